"""A model made ready for meshing: its absolute tolerance worked out once (`tolerance`, or `relative` × the model's
bounding-box diagonal), the faces we mesh ourselves from the start chosen once, and every other face meshed by
BRepMesh at that tolerance (brepmesh.py)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from OCP.Bnd import Bnd_Box
from OCP.BRepAdaptor import BRepAdaptor_Surface
from OCP.BRepBndLib import BRepBndLib
from OCP.GeomAbs import GeomAbs_Torus
from OCP.TopoDS import TopoDS_Face

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.cad.estimate import TriangleEstimate
from amprep.geometry.cad.instances import Instancing, find_instancing, template_face_of
from amprep.geometry.cad.read import CadModel
from amprep.geometry.cad.surfaces import Surface, tangents
from amprep.geometry.core.limits import MAX_TOLERANCE, MIN_TOLERANCE
from amprep.geometry.meshing.brepmesh import run_brepmesh
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.shared_edges import has_pole
from amprep.geometry.meshing.uv_cdt import inside_loops
from amprep.geometry.meshing.uv_seed import DIFF_STEP, second_form


def bbox_diagonal(model: CadModel, meshed: bool = False) -> float:
    """Diagonal of the model's bounding box (mm): the optimal (exact-geometry) box, or with `meshed` the box of
    its triangulations (milliseconds where the optimal box of a free-form part takes seconds) where that is bounded
    (a face with no triangulation adds its untrimmed surface: OCCT's ±1e100), else the optimal box; 0 when empty or
    unbounded."""
    box = Bnd_Box()
    if meshed:
        BRepBndLib.Add_s(model.shape, box, True)
    if not meshed or _unbounded(box):
        box = Bnd_Box()
        BRepBndLib.AddOptimal_s(model.shape, box, False, False)
    if box.IsVoid() or _unbounded(box):
        return 0.0
    x0, y0, z0, x1, y1, z1 = box.Get()
    return float(np.linalg.norm([x1 - x0, y1 - y0, z1 - z0]))


def _unbounded(box: Bnd_Box) -> bool:
    """True when a non-void box is open or reaches OCCT's infinite (Precision::Infinite, 2e100) in any direction."""
    return not box.IsVoid() and (box.IsOpen() or max(abs(c) for c in box.Get()) >= 1e99)


def absolute_tolerance(model: CadModel, params: MeshParams) -> float:
    """The linear tolerance in mm: `tolerance`, or `relative` × bounding-box diagonal."""
    if params.relative is None:
        return params.tolerance
    diag = bbox_diagonal(model)
    if diag <= 0:
        raise AmprepError(ErrorCode.EMPTY_MODEL, "the model has an empty bounding box")
    tol = params.relative * diag
    if tol < MIN_TOLERANCE:
        raise AmprepError(ErrorCode.INVALID_PARAMETER, f"relative tolerance {params.relative:g} of this part's "
                          f"{diag:.4g} mm diagonal is {tol:.3g} mm, under the finest of {MIN_TOLERANCE:g} mm")
    return tol


@dataclass(frozen=True, eq=False)
class Prepared:
    """A model whose shape BRepMesh meshed at `tolerance` (mm, absolute), all faces but `own` (ids left to our own
    mesher, below); `estimated` the triangles estimate.py expected. With `instancing` (instances.py) only
    its template was meshed, and `own` are template face ids."""

    model: CadModel
    tolerance: float
    own: tuple[int, ...]
    estimated: int = 0
    instancing: Instancing | None = None

    @property
    def meshed(self) -> CadModel:
        """The model BRepMesh meshed: the instancing's template, or the model."""
        return self.instancing.template if self.instancing is not None else self.model


# ---- large faces (default mesher): which faces amprep meshes itself from the start instead of BRepMesh: large torus
# faces. OCCT fills a torus's
# interior with a dense grid, slowly, and more densely than the tolerance needs; Triangle from curvature-sized points
# (uv_seed.py) is faster with fewer triangles, both within tolerance: R20 r5 at 0.001 mm 1.4 s and 173k triangles
# against OCCT's 2.6 s and 222k, a trimmed torus 0.4 s and 95k against 1.8 s and 178k. Measured and left to OCCT:
# cylinders and cones (OCCT meshes them as strips, with no interior points, quickly, from edges at the tolerance:
# brepmesh.py), spheres (a band at 0.001 mm: 108k ours, 75k OCCT's mended), B-splines (a loft at 0.001 mm: 40k
# either way).

#: a face expected to need at least this many triangles is meshed by fallback.mesh_face (below it, OCCT's meshing
#: takes well under 0.1 s and our per-face set-up would cost more than it saves)
OWN_MESH_MIN = 20_000


def expected_triangles(face: TopoDS_Face, tolerance: float) -> float:
    """Triangles a torus face needs at the chord tolerance t: A·κ / (2√3·t), the area A of its (u,v) box over that of
    an equilateral triangle whose sides have sagitta κh²/8 = t at the largest principal curvature κ (0 for other
    surfaces and an unbounded box)."""
    if BRepAdaptor_Surface(face, False).GetType() != GeomAbs_Torus or tolerance <= 0:
        return 0.0  # (u,v) bounds of the face cost 10× the type: only a torus's are computed
    ad = BRepAdaptor_Surface(face, True)
    u1, u2, v1, v2 = ad.FirstUParameter(), ad.LastUParameter(), ad.FirstVParameter(), ad.LastVParameter()
    if not np.isfinite([u1, u2, v1, v2]).all():
        return 0.0
    torus = ad.Torus()
    big, small = torus.MajorRadius(), torus.MinorRadius()
    area = small * abs(u2 - u1) * abs(big * (v2 - v1) + small * (np.sin(v2) - np.sin(v1)))
    kappa = max(1.0 / small, 1.0 / (big - small)) if big > small else 1.0 / small
    return float(area * kappa / (2 * np.sqrt(3) * tolerance))


def faces_to_mesh_ourselves(faces: tuple[TopoDS_Face, ...] | list[TopoDS_Face], tolerance: float) -> list[int]:
    """Ids of the faces with no pole or apex (has_pole) expected to need ≥ OWN_MESH_MIN triangles."""
    return [i for i, f in enumerate(faces)
            if (n := expected_triangles(f, tolerance)) > 0 and n >= OWN_MESH_MIN and not has_pole(f)]


#: the quality mesher's triangles over the B-rep estimate (estimate.py), the fewest seen on the corpus: 0.81 (the lens at
#: 0.34 mm, a few large B-spline faces); the most: 15 (as1 at 0.01 mm). Before its edges exist a model is refused only
#: when even this × the B-rep estimate is over the limit; quality_estimate decides once they do
QUALITY_LEAST_FACTOR = 0.25
#: the quality mesher's triangles over the B-rep estimate, typically (the corpus: 2–6.5 at 0.34 mm, 1.4–15 at
#: 0.01 mm): its first estimate, which decides whether the compiled kernels are loaded before any face is meshed
QUALITY_ESTIMATE_FACTOR = 6


def refuse_too_large(model: CadModel, params: MeshParams, tol: float, inst: Instancing | None = None) -> int:
    """The model's estimated triangle count (estimate.py; with `inst`, its template's faces counted once per
    placement; × QUALITY_ESTIMATE_FACTOR for the quality mesher); output_too_large, before any meshing, when it
    exceeds params.max_triangles (for the quality mesher: when QUALITY_LEAST_FACTOR × the B-rep estimate does),
    naming the finest tolerance whose estimate would fit (fitting_tolerance; × QUALITY_ESTIMATE_FACTOR for the
    quality mesher)."""
    if inst is None:
        estimate = TriangleEstimate(model.faces, params.angular, min_size=params.min_size)
    else:
        estimate = TriangleEstimate(inst.template.faces, params.angular, face_uses(inst), params.min_size)
    n = estimate(tol)
    least = n * QUALITY_LEAST_FACTOR if params.quality else n
    if least > params.max_triangles:
        factor = QUALITY_ESTIMATE_FACTOR if params.quality else 1
        fit = fitting_tolerance(lambda t: estimate(t) * factor, tol, params.max_triangles)
        hint = f" (about {fit:g} mm would fit)" if fit is not None else ""
        raise AmprepError(ErrorCode.OUTPUT_TOO_LARGE, f"at {tol:g} mm this model would mesh to about {least:,.0f} "
                          f"triangles{' at least' if params.quality else ''}, over the limit of "
                          f"{params.max_triangles:,}: use a coarser tolerance{hint} or a higher max_triangles (the "
                          "estimate is made from the B-rep before meshing)")
    return n * QUALITY_ESTIMATE_FACTOR if params.quality else n


#: a refusal's tolerance that would fit is looked for in steps of this × the tolerance asked for, up to MAX_TOLERANCE
FIT_GROWTH = 4.0
#: then the last step's interval is halved this many times in log scale (4^(1/2^8): to 0.5 %)
FIT_HALVINGS = 8


def fitting_tolerance(count: Callable[[float], float], tol: float, limit: int) -> float | None:
    """The finest tolerance over `tol` whose count(t) ≤ limit (count non-increasing in t), to 0.5 % and rounded up
    to two significant digits; None when none up to MAX_TOLERANCE does (a count the tolerance does not set: flat
    faces' boundaries, many faces). At most log_4(MAX_TOLERANCE / tol) + FIT_HALVINGS calls of count."""
    lo, hi = tol, tol * FIT_GROWTH
    while count(hi) > limit:
        if hi >= MAX_TOLERANCE:
            return None
        lo, hi = hi, min(hi * FIT_GROWTH, MAX_TOLERANCE)
    for _ in range(FIT_HALVINGS):
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if count(mid) > limit else (lo, mid)
    step = 10.0 ** (math.floor(math.log10(hi)) - 1)
    fit = math.ceil(hi / step * (1 - 1e-12)) * step
    return float(f"{fit:.2g}")


def face_uses(inst: Instancing) -> np.ndarray:
    """(F,) how many faces of the model each face of the instancing's template stands for."""
    return np.bincount(template_face_of(inst), minlength=len(inst.template.faces))


# ---- the quality mesher's estimate, once its edges are discretised and its lattices planned (enforce._remesh): per
# face, a planned lattice's rows (lattice.expected_triangles, within 0.75–1.34 of the count on the corpus); a plane's
# graded Delaunay triangles, about boundary_layer(n) of its n boundary segments; any other face its boundary layer
# plus near-equilateral triangles sized by curvature over its trimmed area (curvature_fill). On the corpus at 0.34,
# 0.1 and 0.01 mm a part's count is 0.43–1.7 × this estimate (its B-rep estimate × 6: 0.07–4.5).

#: boundary-layer triangles per boundary segment of a face with n of them: 1 + n / BOUNDARY_GROWTH, at most
#: BOUNDARY_MOST (planes on the corpus: 0.9–6.4 per segment, the larger faces the more, as Delaunay grades inward)
BOUNDARY_GROWTH = 20.0
BOUNDARY_MOST = 6.0
#: cell centres per (u,v) direction at which a curved face's curvature and trimmed area are sampled; a surface OCCT
#: evaluates point by point (no numpy evaluator: 13 evaluations a sample) takes FEW_SAMPLES
FILL_SAMPLES = 12
FEW_SAMPLES = 4


def boundary_layer(n: np.ndarray | float) -> np.ndarray | float:
    """Triangles along n boundary segments: n · min(BOUNDARY_MOST, 1 + n / BOUNDARY_GROWTH)."""
    return n * np.minimum(BOUNDARY_MOST, 1 + n / BOUNDARY_GROWTH)


def curvature_fill(surface: Surface, loops: list[np.ndarray], tol: float) -> float:
    """Σ over the FILL_SAMPLES² (FEW_SAMPLES²) cells of the loops' (u,v) box (closed polygons (n, 2)) whose centres are
    inside them:
    the cell's area |S_u × S_v| du dv × 2κ / (3√3 t), the density of equilateral triangles of side s whose sagitta
    at the centroid κs²/6 is the tolerance t, κ the larger principal curvature there (at most 6 / t: s ≥ t)."""
    pts = np.concatenate(loops)
    lo, span = pts.min(axis=0), np.maximum(np.ptp(pts, axis=0), 1e-12)
    k = FILL_SAMPLES if surface.exact_numpy else FEW_SAMPLES
    g = (np.arange(k) + 0.5) / k
    uv = np.stack(np.meshgrid(lo[0] + g * span[0], lo[1] + g * span[1]), -1).reshape(-1, 2)
    uv = uv[inside_loops(uv, loops)]
    if not len(uv):
        return 0.0
    su, sv = tangents(surface, uv)
    ll, mm, nn = second_form(surface, uv, DIFF_STEP * span)
    e, f, g2 = (su * su).sum(axis=1), (su * sv).sum(axis=1), (sv * sv).sum(axis=1)
    w2 = np.maximum(e * g2 - f * f, 1e-300)
    gauss, mean = (ll * nn - mm * mm) / w2, (e * nn - 2 * f * mm + g2 * ll) / (2 * w2)
    kappa = np.abs(mean) + np.sqrt(np.maximum(mean * mean - gauss, 0.0))
    area = np.sqrt(w2) * span[0] * span[1] / k**2
    fill = float(np.sum(area * np.minimum(np.nan_to_num(kappa), 6 / tol)) * 2 / (3 * np.sqrt(3) * tol))
    return fill if np.isfinite(fill) else 0.0


def quality_estimate(surfaces: list[Surface], loops: list[list[dict]], segments: list[int],  # type: ignore[type-arg]
                     lattice: list[float | None], tol: float) -> np.ndarray:
    """(F,) the triangles the quality mesher is expected to make on each face (above): `loops` its boundary_loops
    (none where they do not join: only its boundary layer), `segments` its boundary segments, `lattice` its planned
    lattice's count (None where it has none)."""
    out = np.zeros(len(surfaces))
    for i, (surface, lps, n, rows) in enumerate(zip(surfaces, loops, segments, lattice, strict=True)):
        if rows is not None:
            out[i] = rows
            continue
        out[i] = boundary_layer(float(n))
        if lps and not surface.affine:
            out[i] += curvature_fill(surface, [lp["uv"] for lp in lps], tol)
    return out


def refuse_quality_too_large(expected: np.ndarray, made: int, tol: float, limit: int,
                             brep: Callable[[], Callable[[float], float]] | None = None) -> int:
    """Σ expected (F,) + `made` (triangles already made, kept as they are), rounded up; output_too_large when over
    `limit`, before any face is meshed, naming the finest tolerance that would fit when `brep` gives the B-rep
    estimate (made only then): where brep(t) × this estimate / brep(tol) fits (fitting_tolerance). On the corpus the
    quality mesher's count over the B-rep estimate falls as the tolerance coarsens (as1: 15 at 0.01 mm, 5.5 at
    0.34), so the tolerance named errs coarse."""
    n = int(np.ceil(expected.sum())) + made
    if n > limit:
        fit = None
        if brep is not None:
            estimate = brep()
            at = estimate(tol)
            if at > 0:
                fit = fitting_tolerance(lambda t: estimate(t) * n / at, tol, limit)
        hint = f" (about {fit:g} mm would fit)" if fit is not None else ""
        raise AmprepError(ErrorCode.OUTPUT_TOO_LARGE, f"at {tol:g} mm the quality mesher would make about {n:,} "
                          f"triangles, over the limit of {limit:,}: use a coarser tolerance{hint}, the default mesher "
                          "or a higher max_triangles (the estimate is made from the edges and the faces' curvature "
                          "before any face is meshed)")
    return n


def own_faces(model: CadModel, params: MeshParams, tol: float) -> list[int]:
    """Ids of the faces meshed by us from the start (below), none when not own_large_faces."""
    if not params.own_large_faces or params.all_own:
        return []
    return faces_to_mesh_ourselves(model.faces, tol)


def prepare(model: CadModel, params: MeshParams) -> Prepared:
    """The model's absolute tolerance, its size checked (refuse_too_large) and its own faces, after run_brepmesh
    meshed every other face at that tolerance (only the distinct solids when instances.py finds instancing)."""
    tol = absolute_tolerance(model, params)
    inst = find_instancing(model) if params.mesh_instances_once else None
    estimated = refuse_too_large(model, params, tol, inst)
    meshed = inst.template if inst is not None else model
    own = own_faces(meshed, params, tol)
    if not params.all_own:  # the quality mesher meshes every face itself: BRepMesh's work would be thrown away
        run_brepmesh(meshed.shape, tol, params, [meshed.faces[i] for i in own])
    return Prepared(model, tol, tuple(own), estimated, inst)
