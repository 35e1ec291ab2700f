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
Each distinct face (one shape placed several times by instancing counts per placement) is read from OCCT once
(face_shape: what the count needs of it, whatever the tolerance); the counts at any tolerance are then numpy over
those (TriangleEstimate), so a refusal can search tolerances cheaply. On the corpus
(tests/geometry/test_estimate.py) the default mesher's count is 0.62–1.64 × it from 0.1 to 0.001 mm, which is what a
refusal needs: a part is refused before meshing when it would be over the limit, not part way through.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

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
#: BRepMesh discretises edges at this × the deflection and the angle it is given (BRepMesh_CurveTessellator), so
#: meshing.brepmesh.run_brepmesh gives it the user's angle over this; its range splitters take that angle for faces
OCCT_EDGE_FACTOR = 0.5
#: BRepMesh's MinSize, when the user sets none, is this × the tolerance
OCCT_MIN_SIZE = 0.1


def occt_min_size(tol: float, min_size: float) -> float:
    """The MinSize run_brepmesh gives BRepMesh: the user's `min_size`, else max(OCCT_MIN_SIZE × tol, 1e-7)."""
    return min_size if min_size > 0 else max(OCCT_MIN_SIZE * tol, 1e-7)


#: an edge's curvature in FaceShape.edges for a line (one segment) and for an edge with no curve (none)
LINE, NO_CURVE = -1.0, -2.0
#: FaceShape.kind values
STORED, RULED, SPHERE, CONE, TORUS, FREE = "stored", "ruled", "sphere", "cone", "torus", "free"


@dataclass(frozen=True, eq=False)
class FaceShape:
    """What the estimate needs of one face, whatever the tolerance: `edges` (E, 2) each edge's length and largest
    curvature κ (LINE, NO_CURVE); `kind`; `stored` the triangles a tessellated-only face keeps; an analytic face's
    `radii` (sphere R, cone R at its wider end, torus r and R) and (u,v) `spans` (nan: unbounded); a free-form face's
    `jacobian` (S²,) |S_u × S_v| and `kappa` (S², 2) principal curvatures κ₁ ≥ κ₂ at the centres of the SAMPLES²
    cells of area `cell` of its (u,v) box."""

    edges: np.ndarray
    kind: str
    stored: float = 0.0
    radii: tuple[float, ...] = ()
    spans: tuple[float, float] = (math.nan, math.nan)
    jacobian: np.ndarray | None = None
    kappa: np.ndarray | None = None
    cell: float = 0.0


def edge_shape(edge: TopoDS_Edge) -> tuple[float, float]:
    """(length, κ) of an edge: κ its largest curvature over SAMPLES points (exact for circles), LINE for a line or a
    zero length, NO_CURVE for a null or degenerated edge."""
    if edge.IsNull():
        return 0.0, NO_CURVE
    try:
        curve = BRepAdaptor_Curve(edge)
    except Exception:  # noqa: BLE001 - a degenerated edge has no 3D curve
        return 0.0, NO_CURVE
    kind = curve.GetType()
    length = GCPnts_AbscissaPoint.Length_s(curve)
    if kind == GeomAbs_Line or length <= 0:
        return length, LINE
    if kind == GeomAbs_Circle:
        return length, 1.0 / curve.Circle().Radius()
    props = BRepLProp_CLProps(curve, 2, 1e-9)
    t0, t1 = curve.FirstParameter(), curve.LastParameter()
    kappa = 0.0
    for t in t0 + (np.arange(SAMPLES) + 0.5) / SAMPLES * (t1 - t0):
        props.SetParameter(float(t))
        kappa = max(kappa, props.Curvature() if props.IsTangentDefined() else 0.0)
    return length, kappa


def edge_segments(edges: np.ndarray, tol: float, angular: float) -> np.ndarray:
    """(E,) segments of edges (E, 2) (length L, κ): max(1, L · max(√(κ/8t), κ/θ)); 1 for a line, 0 with no curve."""
    length, kappa = edges[:, 0], np.maximum(edges[:, 1], 0.0)
    curved = np.maximum(1.0, length * np.maximum(np.sqrt(kappa / (8 * tol)), kappa / angular))
    return np.where(edges[:, 1] == NO_CURVE, 0.0, np.where(edges[:, 1] == LINE, 1.0, curved))


def face_shape(face: TopoDS_Face) -> FaceShape:
    """A face read once for the estimate (FaceShape)."""
    edges = np.array([edge_shape(e) for e in explore(face, TopAbs_EDGE, TopoDS.Edge_s)], float).reshape(-1, 2)
    if BRep_Tool.Surface_s(face) is None:
        stored = BRep_Tool.Triangulation_s(face, TopLoc_Location())
        return FaceShape(edges, STORED, float(stored.NbTriangles()) if stored is not None else 0.0)
    surface = BRepAdaptor_Surface(face, True)
    kind = surface.GetType()
    u0, u1, v0, v1 = (surface.FirstUParameter(), surface.LastUParameter(), surface.FirstVParameter(),
                      surface.LastVParameter())
    bounded = bool(np.isfinite([u0, u1, v0, v1]).all())
    spans = (abs(u1 - u0), abs(v1 - v0)) if bounded else (math.nan, math.nan)
    if kind == GeomAbs_Sphere:
        return FaceShape(edges, SPHERE, radii=(surface.Sphere().Radius(),), spans=spans)
    if kind == GeomAbs_Cone:
        cone = surface.Cone()
        wide = max(abs(cone.RefRadius() + v * math.sin(cone.SemiAngle())) for v in (v0, v1)) if bounded else 0.0
        return FaceShape(edges, CONE, radii=(wide,), spans=spans)
    if kind == GeomAbs_Torus:
        return FaceShape(edges, TORUS, radii=(surface.Torus().MinorRadius(), surface.Torus().MajorRadius()),
                         spans=spans)
    if is_ruled(face) or not bounded:
        return FaceShape(edges, RULED)
    props = BRepLProp_SLProps(surface, 2, 1e-9)
    at = (np.arange(SAMPLES) + 0.5) / SAMPLES
    jacobian, kappa = np.zeros(SAMPLES**2), np.zeros((SAMPLES**2, 2))
    for n, (u, v) in enumerate((u, v) for u in u0 + at * (u1 - u0) for v in v0 + at * (v1 - v0)):
        props.SetParameters(float(u), float(v))
        jacobian[n] = props.D1U().Crossed(props.D1V()).Magnitude()
        if props.IsCurvatureDefined():
            a, b = abs(props.MaxCurvature()), abs(props.MinCurvature())
            kappa[n] = max(a, b), min(a, b)
    return FaceShape(edges, FREE, jacobian=jacobian, kappa=kappa, cell=spans[0] * spans[1] / SAMPLES**2)


def arc_step(radius: float, tol: float, angle: float, min_size: float) -> float:
    """The angular step BRepMesh takes along a circle of `radius` (OCCT's GCPnts_TangentialDeflection::ArcAngularStep):
    2 acos(1 − t/R), at most `angle`, at least min_size / R (≤ π/2)."""
    step = 2 * math.acos(max(1 - tol / radius, 0.0)) if radius > 1e-7 else 0.0
    least = min(min_size / radius, math.pi / 2) if radius > 1e-7 and min_size > 1e-7 else 0.0
    return max(min(step, angle), least)


def analytic_nodes(shape: FaceShape, tol: float, angle: float, min_size: float) -> float:
    """The interior nodes BRepMesh's range splitter puts on a cone, sphere or torus face's (u,v) box (0 for an unbounded
    box): a sphere rows of 0.7 × arc_step(R) both ways; a cone columns of the arc step at its wider end, rows about as
    long over ln(length / that step); a torus rows of the tube's step, columns of the ring's step narrowed by both
    (BRepMesh_{Sphere,Cone,Torus}RangeSplitter)."""
    span_u, span_v = shape.spans
    if not (math.isfinite(span_u) and math.isfinite(span_v)):
        return 0.0
    if shape.kind == SPHERE:
        step = 0.7 * arc_step(shape.radii[0], tol, angle, min_size)
        return float(int(span_v / step) * (int(span_u / step) + 1)) if step > 0 else 0.0
    if shape.kind == CONE:
        radius = shape.radii[0]
        du = arc_step(radius, tol, angle, min_size)
        scale = du * radius
        if scale <= 0 or span_v <= 0:
            return 0.0
        ratio = max(1.0, math.log(span_v / scale))
        return float(int(span_u / du) * max(int(span_v / scale / ratio) + int(ratio) - 1, 0))
    small, big = shape.radii
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


def free_form_interior(jacobian: np.ndarray, kappa: np.ndarray, cell: np.ndarray, tol: float,
                       angular: float) -> np.ndarray:
    """(F,) Σ FREE_FORM_DENSITY · |S_u × S_v| du dv / (h₁ h₂) over each free-form face's samples (jacobian (F, S²),
    kappa (F, S², 2), cell (F,)), h_i = min(√(8t/κ_i), 2θ/κ_i, √A) from the principal curvatures there, A the box's
    area on the surface (0 where it has none). The box overstates a trimmed face's area by what the trimming removes
    (an estimate may be high)."""
    area = jacobian.sum(axis=1) * cell
    side = np.sqrt(area)[:, None, None]
    curved = kappa > 0
    k = np.where(curved, kappa, 1.0)
    h = np.where(curved, np.minimum(np.minimum(np.sqrt(8 * tol / k), 2 * angular / k), side), side)
    with np.errstate(divide="ignore", invalid="ignore"):
        total = (FREE_FORM_DENSITY * jacobian * cell[:, None] / (h[..., 0] * h[..., 1])).sum(axis=1)
    return np.where((area > 0) & np.isfinite(total), total, 0.0)


class TriangleEstimate:
    """The triangles `faces` are expected to take, each distinct face (one TShape) read once (face_shape) and counted
    `weights` (F,) times: calling it with a tolerance (mm) gives the count; `angular` the edge angle (rad) and
    `min_size` BRepMesh's (0: its default for the tolerance). Per face: a plane or ruled face its boundary's segments,
    a cone, sphere or torus 2 × analytic_nodes + its boundary, a free-form face free_form_interior + its boundary
    (at least 1 each), a tessellated-only face the triangles it stores."""

    def __init__(self, faces: list[TopoDS_Face] | tuple[TopoDS_Face, ...], angular: float,
                 weights: np.ndarray | None = None, min_size: float = 0.0) -> None:
        self.angular, self.min_size = angular, min_size
        known: dict[int, list[tuple[TopoDS_Face, int]]] = {}
        shapes: list[FaceShape] = []
        weight: list[float] = []
        for i, face in enumerate(faces):
            bare = TopoDS.Face_s(face.Located(TopLoc_Location()))
            same = known.setdefault(hash(bare), [])
            at = next((k for f, k in same if f.IsEqual(bare)), None)
            if at is None:
                at = len(shapes)
                same.append((bare, at))
                shapes.append(face_shape(bare))
                weight.append(0.0)
            weight[at] += 1 if weights is None else int(weights[i])
        self.shapes, self.weights = shapes, np.array(weight)
        self.edges = np.concatenate([s.edges for s in shapes]) if shapes else np.zeros((0, 2))
        self.edge_face = np.repeat(np.arange(len(shapes)), [len(s.edges) for s in shapes])
        self.free = np.array([i for i, s in enumerate(shapes) if s.kind == FREE], np.int64)
        self.analytic = [i for i, s in enumerate(shapes) if s.kind in (SPHERE, CONE, TORUS)]
        self.stored = np.array([s.kind == STORED for s in shapes], bool)
        self.kept = np.array([s.stored for s in shapes], float)
        self.jacobian = np.array([shapes[i].jacobian for i in self.free]).reshape(-1, SAMPLES**2)
        self.kappa = np.array([shapes[i].kappa for i in self.free]).reshape(-1, SAMPLES**2, 2)
        self.cell = np.array([shapes[i].cell for i in self.free], float)

    def counts(self, tol: float) -> np.ndarray:
        """(D,) the triangles each distinct face is expected to take at `tol`."""
        n = len(self.shapes)
        boundary = np.bincount(self.edge_face, edge_segments(self.edges, tol, self.angular), minlength=n)
        interior = np.zeros(n)
        interior[self.free] = free_form_interior(self.jacobian, self.kappa, self.cell, tol, self.angular)
        angle, min_size = self.angular / OCCT_EDGE_FACTOR, occt_min_size(tol, self.min_size)
        for i in self.analytic:
            interior[i] = 2 * analytic_nodes(self.shapes[i], tol, angle, min_size)
        return np.where(self.stored, self.kept, np.maximum(interior + boundary, 1.0))

    def __call__(self, tol: float) -> int:
        """The expected count at `tol`: Σ counts × weights, rounded up."""
        return int(math.ceil(float(self.counts(tol) @ self.weights))) if self.shapes else 0


def face_triangles(face: TopoDS_Face, tol: float, angular: float, min_size: float = 0.0) -> float:
    """The triangles one face is expected to take at chord tolerance `tol` (mm), edge angle `angular` (rad) and
    BRepMesh's `min_size` (0: its default for the tolerance)."""
    return float(TriangleEstimate([face], angular, min_size=min_size).counts(tol)[0])


def estimate_triangles(model: CadModel, tol: float, angular: float, uses: np.ndarray | None = None,
                       min_size: float = 0.0) -> int:
    """The model's expected triangle count (TriangleEstimate): each distinct face (one TShape, placed several times by
    instancing) estimated once; `uses` (F,) how many times each face counts (default once)."""
    return TriangleEstimate(model.faces, angular, uses, min_size)(tol)
