"""The triangle count a model will mesh to, estimated from the B-rep before any meshing, so a job whose output
would be too large is refused (output_too_large) before it is paid for.

Per face, from its boundary, its (u,v) box and its principal curvatures κ₁ ≥ κ₂:
- an edge of length L and curvature κ takes L · max(√(κ / 8t), κ / θ) segments (sagitta κh²/8 = t, turn ≤ θ);
- a plane takes its boundary's segments (a polygon of n points: n − 2 triangles, plus 2 per hole);
- a cylinder or other ruled face is a strip between its boundaries: about their segments;
- a cone, sphere or torus takes the interior nodes BRepMesh's range splitter for it puts on its (u,v) box, two
  triangles each, plus its boundary (arc_step, analytic_nodes);
- any other face Σ FREE_FORM_DENSITY · |S_u × S_v| du dv / (h₁ h₂) over a 5 × 5 sample of its (u,v) box, sides
  h_i = min(√(8t / κ_i), 2θ / κ_i, √A) from the curvatures at each sample, plus its boundary.
Faces of one shape placed several times (instances) are estimated once and counted per placement. On the corpus
(tests/geometry/test_estimate.py) the default mesher's count is 0.62–1.64 × it from 0.1 to 0.001 mm, which is what a
refusal needs: a part is refused before meshing when it would be over the limit, not part way through.
"""

from __future__ import annotations

import math

import numpy as np
from OCP.BRep import BRep_Tool
from OCP.BRepAdaptor import BRepAdaptor_Curve, BRepAdaptor_Surface
from OCP.BRepLProp import BRepLProp_CLProps, BRepLProp_SLProps
from OCP.GCPnts import GCPnts_AbscissaPoint
from OCP.GeomAbs import GeomAbs_Circle, GeomAbs_Cone, GeomAbs_Line, GeomAbs_Sphere, GeomAbs_Torus
from OCP.TopAbs import TopAbs_EDGE
from OCP.TopLoc import TopLoc_Location
from OCP.TopoDS import TopoDS, TopoDS_Edge, TopoDS_Face

from amprep.geometry.cad.read import CadModel
from amprep.geometry.cad.surfaces import is_ruled
from amprep.geometry.cad.topology import explore

#: samples of a free-form edge's or face's curvature, per parameter direction
SAMPLES = 5
#: a free-form face's triangles per h₁h₂ of its area. Right triangles on a grid whose sagitta at the hypotenuse's
#: midpoint, (κ₁s₁² + κ₂s₂²)/8, is the tolerance have sides s_i = h_i/√2 at best: 4 per h₁h₂. BRepMesh leaves
#: doubly curved B-splines over the tolerance, and the enforcement's insertions halve the triangles that are over
#: it: about twice that (the spheres and tori of CTC-02's B-spline twin, re-meshed at 0.01 mm: 1.8–2.0 × the grid)
FREE_FORM_DENSITY = 8.0
#: BRepMesh's angle for every face is this × the angular deflection (meshing.brepmesh.run_brepmesh gives it the
#: edges' angle, twice the user's: OCCT halves it for edges)
OCCT_ANGLE = 2.0
#: and its MinSize, when the user sets none, this × the tolerance
OCCT_MIN_SIZE = 0.1


def edge_segments(edge: TopoDS_Edge, tol: float, angular: float) -> float:
    """Segments an edge takes: L · max(√(κ/8t), κ/θ), κ its largest curvature (exact for lines and circles)."""
    if edge.IsNull():
        return 0.0
    try:
        curve = BRepAdaptor_Curve(edge)
    except Exception:  # noqa: BLE001 - a degenerated edge has no 3D curve
        return 0.0
    kind = curve.GetType()
    length = GCPnts_AbscissaPoint.Length_s(curve)
    if kind == GeomAbs_Line or length <= 0:
        return 1.0
    if kind == GeomAbs_Circle:
        kappa = 1.0 / curve.Circle().Radius()
    else:
        props = BRepLProp_CLProps(curve, 2, 1e-9)
        t0, t1 = curve.FirstParameter(), curve.LastParameter()
        kappa = 0.0
        for t in t0 + (np.arange(SAMPLES) + 0.5) / SAMPLES * (t1 - t0):
            props.SetParameter(float(t))
            kappa = max(kappa, props.Curvature() if props.IsTangentDefined() else 0.0)
    return max(1.0, length * max(math.sqrt(kappa / (8 * tol)), kappa / angular))


def arc_step(radius: float, tol: float, angle: float, min_size: float) -> float:
    """The angular step BRepMesh takes along a circle of `radius` (OCCT's GCPnts_TangentialDeflection::ArcAngularStep):
    2 acos(1 − t/R), at most `angle`, at least min_size / R (≤ π/2)."""
    step = 2 * math.acos(max(1 - tol / radius, 0.0)) if radius > 1e-7 else 0.0
    least = min(min_size / radius, math.pi / 2) if radius > 1e-7 and min_size > 1e-7 else 0.0
    return max(min(step, angle), least)


def analytic_nodes(surface: BRepAdaptor_Surface, tol: float, angle: float, min_size: float) -> float | None:
    """The interior nodes BRepMesh's range splitter puts on a cone, sphere or torus face's (u,v) box (None for other
    surfaces, 0 for an unbounded box): a sphere rows of 0.7 × arc_step(R) both ways; a cone columns of the arc step at
    its wider end, rows about as long over ln(length / that step); a torus rows of the tube's step, columns of the
    ring's step narrowed by both (BRepMesh_{Sphere,Cone,Torus}RangeSplitter)."""
    kind = surface.GetType()
    if kind not in (GeomAbs_Cone, GeomAbs_Sphere, GeomAbs_Torus):
        return None
    u0, u1, v0, v1 = (surface.FirstUParameter(), surface.LastUParameter(), surface.FirstVParameter(),
                      surface.LastVParameter())
    if not np.isfinite([u0, u1, v0, v1]).all():
        return 0.0
    span_u, span_v = abs(u1 - u0), abs(v1 - v0)
    if kind == GeomAbs_Sphere:
        step = 0.7 * arc_step(surface.Sphere().Radius(), tol, angle, min_size)
        return float(int(span_v / step) * (int(span_u / step) + 1)) if step > 0 else 0.0
    if kind == GeomAbs_Cone:
        cone = surface.Cone()
        radius = max(abs(cone.RefRadius() + v * math.sin(cone.SemiAngle())) for v in (v0, v1))
        du = arc_step(radius, tol, angle, min_size)
        scale = du * radius
        if scale <= 0 or span_v <= 0:
            return 0.0
        ratio = max(1.0, math.log(span_v / scale))
        return float(int(span_u / du) * max(int(span_v / scale / ratio) + int(ratio) - 1, 0))
    torus = surface.Torus()
    small, big = torus.MinorRadius(), torus.MajorRadius()
    tube = arc_step(small, tol, angle, min_size)
    ring = arc_step(big + small, tol, angle, min_size)
    if tube <= 0 or ring <= 0:
        return 0.0
    rows = max(int(span_v / tube), 2)
    ring *= min(tube, ring) / math.hypot(ring, tube)
    cols = max(int(span_u / ring), 2)
    if small > 0 and span_v > 0:
        cols = max(cols, int(rows * span_u * big / (span_v * small) / 5.0))
    return float(cols * rows)


def free_form_interior(surface: BRepAdaptor_Surface, tol: float, angular: float) -> float:
    """Σ FREE_FORM_DENSITY · |S_u × S_v| du dv / (h₁ h₂) over SAMPLES² cell centres of the face's (u,v) box (a pole
    or degenerate corner is never sampled), h_i = min(√(8t/κ_i), 2θ/κ_i, √A) from the principal curvatures there, A
    the box's area on the surface; 0 for an unbounded box. The box overstates a trimmed face's area by what the
    trimming removes (an estimate may be high)."""
    props = BRepLProp_SLProps(surface, 2, 1e-9)
    u0, u1, v0, v1 = (surface.FirstUParameter(), surface.LastUParameter(), surface.FirstVParameter(),
                      surface.LastVParameter())
    if not np.isfinite([u0, u1, v0, v1]).all():
        return 0.0
    at = (np.arange(SAMPLES) + 0.5) / SAMPLES
    cell = abs(u1 - u0) * abs(v1 - v0) / SAMPLES**2
    jacobian, kappa = np.zeros(SAMPLES**2), np.zeros((SAMPLES**2, 2))
    for n, (u, v) in enumerate((u, v) for u in u0 + at * (u1 - u0) for v in v0 + at * (v1 - v0)):
        props.SetParameters(float(u), float(v))
        jacobian[n] = props.D1U().Crossed(props.D1V()).Magnitude()
        if props.IsCurvatureDefined():
            a, b = abs(props.MaxCurvature()), abs(props.MinCurvature())
            kappa[n] = max(a, b), min(a, b)
    side = math.sqrt(jacobian.sum() * cell)
    if not side > 0:
        return 0.0
    curved = kappa > 0
    k = np.where(curved, kappa, 1.0)
    h = np.where(curved, np.minimum(np.minimum(np.sqrt(8 * tol / k), 2 * angular / k), side), side)
    total = float(np.sum(FREE_FORM_DENSITY * jacobian * cell / (h[:, 0] * h[:, 1])))
    return total if math.isfinite(total) else 0.0


def face_triangles(face: TopoDS_Face, tol: float, angular: float, min_size: float = 0.0) -> float:
    """The triangles one face is expected to take at chord tolerance `tol` (mm), edge angle `angular` (rad) and
    BRepMesh's `min_size` (0: its default for the tolerance); a tessellated-only face (no surface) keeps the triangles
    it stores."""
    if BRep_Tool.Surface_s(face) is None:
        stored = BRep_Tool.Triangulation_s(face, TopLoc_Location())
        return float(stored.NbTriangles()) if stored is not None else 0.0
    boundary = sum(edge_segments(e, tol, angular) for e in explore(face, TopAbs_EDGE, TopoDS.Edge_s))
    surface = BRepAdaptor_Surface(face, True)
    nodes = analytic_nodes(surface, tol, OCCT_ANGLE * angular, min_size if min_size > 0 else OCCT_MIN_SIZE * tol)
    if nodes is not None:
        return max(2 * nodes + boundary, 1.0)
    if is_ruled(face):
        return max(boundary, 1.0)
    return max(free_form_interior(surface, tol, angular) + boundary, 1.0)


def estimate_triangles(model: CadModel, tol: float, angular: float, uses: np.ndarray | None = None,
                       min_size: float = 0.0) -> int:
    """The model's expected triangle count: face_triangles summed, each distinct face (one TShape, placed several
    times by instancing) estimated once; `uses` (F,) how many times each face counts (default once)."""
    known: dict[int, list[tuple[TopoDS_Face, float]]] = {}
    total = 0.0
    for i, face in enumerate(model.faces):
        bare = TopoDS.Face_s(face.Located(TopLoc_Location()))
        same = known.setdefault(hash(bare), [])
        n = next((n for f, n in same if f.IsEqual(bare)), None)
        if n is None:
            n = face_triangles(bare, tol, angular, min_size)
            same.append((bare, n))
        total += n * (1 if uses is None else int(uses[i]))
    return int(math.ceil(total))
