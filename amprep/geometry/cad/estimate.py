"""The triangle count a model will mesh to, estimated from the B-rep before any meshing, so a job whose output
would be too large is refused (output_too_large) before it is paid for.

Per face, from its area A (sampled), its boundary and its principal curvatures κ₁ ≥ κ₂ (closed forms for the analytic
surfaces, a 5 × 5 sample of the others):
- an edge of length L and curvature κ takes L · max(√(κ / 8t), κ / θ) segments (sagitta κh²/8 = t, turn ≤ θ);
- a plane takes its boundary's segments (a polygon of n points: n − 2 triangles, plus 2 per hole);
- a ruled face (cylinder, cone, extrusion) is a strip between its boundaries: about their segments;
- any other face 4A / (√3 h₁ h₂) triangles of sides h_i = min(√(8t / κ_i), 2θ / κ_i, √A), plus its boundary.
Faces of one shape placed several times (instances) are estimated once and counted per placement. Measured on
the corpus (tests/geometry/test_estimate.py) it lands within a small factor of the count the mesher gives, which
is all a refusal needs.
"""

from __future__ import annotations

import math

import numpy as np
from OCP.BRep import BRep_Tool
from OCP.BRepAdaptor import BRepAdaptor_Curve, BRepAdaptor_Surface
from OCP.BRepLProp import BRepLProp_CLProps, BRepLProp_SLProps
from OCP.GCPnts import GCPnts_AbscissaPoint
from OCP.GeomAbs import GeomAbs_Circle, GeomAbs_Line, GeomAbs_Sphere, GeomAbs_Torus
from OCP.TopAbs import TopAbs_EDGE
from OCP.TopLoc import TopLoc_Location
from OCP.TopoDS import TopoDS, TopoDS_Edge, TopoDS_Face

from amprep.geometry.cad.read import CadModel
from amprep.geometry.cad.surfaces import is_ruled
from amprep.geometry.cad.topology import explore

#: samples of a free-form edge's or face's curvature, per parameter direction
SAMPLES = 5


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


def _sampled(surface: BRepAdaptor_Surface) -> tuple[float, float, float]:
    """(κ₁, κ₂, A): the largest principal curvatures over the face and its area ≈ mean |S_u × S_v| × its (u,v)
    box, from SAMPLES² cell centres (a pole or degenerate corner is never sampled); closed-form curvature for a sphere
    and a torus. The box overstates a trimmed face's area by what the trimming removes (an estimate may be high)."""
    props = BRepLProp_SLProps(surface, 2, 1e-9)
    u0, u1, v0, v1 = (surface.FirstUParameter(), surface.LastUParameter(), surface.FirstVParameter(),
                      surface.LastVParameter())
    if not np.isfinite([u0, u1, v0, v1]).all():
        return 0.0, 0.0, 0.0
    at = (np.arange(SAMPLES) + 0.5) / SAMPLES
    k1 = k2 = jacobian = 0.0
    for u in u0 + at * (u1 - u0):
        for v in v0 + at * (v1 - v0):
            props.SetParameters(float(u), float(v))
            jacobian += props.D1U().Crossed(props.D1V()).Magnitude()
            if props.IsCurvatureDefined():
                a, b = abs(props.MaxCurvature()), abs(props.MinCurvature())
                k1, k2 = max(k1, a, b), max(k2, min(a, b))
    area = jacobian / SAMPLES**2 * abs(u1 - u0) * abs(v1 - v0)
    kind = surface.GetType()
    if kind == GeomAbs_Sphere:
        k1 = k2 = 1.0 / surface.Sphere().Radius()
    elif kind == GeomAbs_Torus:
        big, small = surface.Torus().MajorRadius(), surface.Torus().MinorRadius()
        k1, k2 = 1.0 / small, (1.0 / (big - small) if big > small else 1.0 / small)
    return k1, k2, area


def face_triangles(face: TopoDS_Face, tol: float, angular: float) -> float:
    """The triangles one face is expected to take at chord tolerance `tol` (mm) and edge angle `angular` (rad); a
    tessellated-only face (no surface) keeps the triangles it stores."""
    if BRep_Tool.Surface_s(face) is None:
        stored = BRep_Tool.Triangulation_s(face, TopLoc_Location())
        return float(stored.NbTriangles()) if stored is not None else 0.0
    boundary = sum(edge_segments(e, tol, angular) for e in explore(face, TopAbs_EDGE, TopoDS.Edge_s))
    if is_ruled(face):
        return max(boundary, 1.0)
    k1, k2, area = _sampled(BRepAdaptor_Surface(face, True))
    side = math.sqrt(area)

    def h(k: float) -> float:
        return min(math.sqrt(8 * tol / k), 2 * angular / k, side) if k > 0 else side

    h1, h2 = h(k1), h(k2)
    interior = 4 * area / (math.sqrt(3) * h1 * h2) if h1 > 0 and h2 > 0 else 0.0
    return max(interior + boundary, 1.0)


def estimate_triangles(model: CadModel, tol: float, angular: float, uses: np.ndarray | None = None) -> int:
    """The model's expected triangle count: face_triangles summed, each distinct face (one TShape, placed several
    times by instancing) estimated once; `uses` (F,) how many times each face counts (default once)."""
    known: dict[int, list[tuple[TopoDS_Face, float]]] = {}
    total = 0.0
    for i, face in enumerate(model.faces):
        bare = TopoDS.Face_s(face.Located(TopLoc_Location()))
        same = known.setdefault(hash(bare), [])
        n = next((n for f, n in same if f.IsEqual(bare)), None)
        if n is None:
            n = face_triangles(bare, tol, angular)
            same.append((bare, n))
        total += n * (1 if uses is None else int(uses[i]))
    return int(math.ceil(total))
