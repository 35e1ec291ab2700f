"""CAD model → closed mesh within the chord tolerance on every face (the conversion core)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from OCP.Bnd import Bnd_Box
from OCP.BRep import BRep_Tool
from OCP.BRepBndLib import BRepBndLib

from .brepmesh import run_brepmesh
from .cad import CadModel
from .checks import DEGENERATE_REL_AREA
from .chordal import COMPILED_MIN_POINTS, barycentric_grid, kernels_loaded, load_kernels, triangle_chordal_error
from .errors import AmprepError, ErrorCode
from .face_pool import map_faces
from .fallback import discretize_missing_edges, has_pole, mesh_face, split_edge_to_tolerance
from .first_look import first_look, patch_error
from .mesh import FaceInfo, Mesh
from .own_faces import faces_to_mesh_ourselves
from .patch_refine import flat_triangles, flip_flat_triangles, refine_patch
from .progress import Progress, ProgressFn
from .surfaces import Surface, surface_of
from .tessellate import (
    FacePatch,
    MeshParams,
    Topology,
    bulk_triangulation_arrays,
    face_edges,
)
from .weld import orient_stored_shells, weld

ENFORCE_ROUNDS = 4
#: faces are refined until their sampled error is ≤ this × tolerance: the order-6 grid can miss up to ~0.5 %
#: of the true maximum between its points (measured on a sphere against the exact distance), so aim below it
ENFORCE_MARGIN = 0.98
#: a face is re-meshed only when its sampled error exceeds this × tolerance (OCCT's mesh is kept otherwise)
TRIGGER_MARGIN = 0.995
#: a face sampled within (TRIGGER_MARGIN, 1] × tolerance is measured again on the order-24 grid (it contains the
#: order-6 points; its miss is ~(6/24)² × 0.5 % = 0.03 %) and kept when that stays ≤ FINE_MARGIN × tolerance
FINE_ORDER = 24
FINE_MARGIN = 0.999
#: a face of at least LOCAL_MIN_TRIANGLES with at most LOCAL_MAX_BAD of them over the target is refined where they
#: are (patch_refine.py); any other is meshed again whole: a fresh CDT packs the points better than OCCT's layout
#: can be mended (a countersink cone's apex fan: 90 triangles re-meshed, 124 mended), and a small face costs little;
#: so is a face with a pole or apex (a degenerated edge), where points mended into OCCT's fan make tilted triangles
LOCAL_MIN_TRIANGLES = 1000
LOCAL_MAX_BAD = 0.25


@dataclass(frozen=True, eq=False)
class MeshResult:
    """The welded mesh and how it was made: `face_error` (F,) max chordal error per face (nan: no surface),
    `tolerance` the absolute tolerance used, `fallback_faces` ids meshed by fallback.py, and why."""

    mesh: Mesh
    tolerance: float
    face_error: np.ndarray
    fallback_faces: dict[int, str]
    unmeshed_faces: tuple[int, ...]

    @property
    def max_error(self) -> float:
        e = self.face_error[np.isfinite(self.face_error)]
        return float(e.max()) if len(e) else float("nan")


def bbox_diagonal(model: CadModel, meshed: bool = False) -> float:
    """Diagonal of the model's bounding box (mm): the optimal (exact-geometry) box, or with `meshed` the box of
    its triangulations (milliseconds where the optimal box of a free-form part takes seconds)."""
    box = Bnd_Box()
    if meshed:
        BRepBndLib.Add_s(model.shape, box, True)
    else:
        BRepBndLib.AddOptimal_s(model.shape, box, False, False)
    if box.IsVoid():
        return 0.0
    x0, y0, z0, x1, y1, z1 = box.Get()
    return float(np.linalg.norm([x1 - x0, y1 - y0, z1 - z0]))


def absolute_tolerance(model: CadModel, params: MeshParams) -> float:
    """The linear tolerance in mm: `tolerance`, or `relative` × bounding-box diagonal."""
    if params.relative is None:
        return params.tolerance
    diag = bbox_diagonal(model)
    if diag <= 0:
        raise AmprepError(ErrorCode.EMPTY_MODEL, "the model has an empty bounding box")
    return params.relative * diag


def own_faces(model: CadModel, params: MeshParams, tol: float) -> list[int]:
    """Ids of the faces mesh_model meshes itself from the start (own_faces.py), none when not own_large_faces."""
    if not params.own_large_faces or params.force_fallback:
        return []
    return faces_to_mesh_ourselves(model.faces, tol)


def brepmesh_model(model: CadModel, params: MeshParams) -> float:
    """The model's absolute tolerance, after run_brepmesh meshed its shape at it, all but own_faces."""
    tol = absolute_tolerance(model, params)
    run_brepmesh(model.shape, tol, params, [model.faces[i] for i in own_faces(model, params, tol)])
    return tol


def mesh_model(model: CadModel, params: MeshParams = MeshParams(), progress: ProgressFn | None = None,
               meshed_at: float | None = None) -> MeshResult:
    """Tessellate every face; re-mesh from the shared edge discretisation any face OCCT leaves unmeshed or
    broken, and any face whose chordal error exceeds the tolerance (splitting its edges where their own
    sagitta does), until every face is within tolerance; weld by topology. `meshed_at`: the absolute tolerance
    run_brepmesh already meshed the shape at with these params (read_ahead.py), so it is not run again."""
    params.validate()
    prog = Progress(progress)
    prog("meshing", 0.0)
    tol = brepmesh_model(model, params) if meshed_at is None else meshed_at
    prog("meshing", 0.4)
    topo = Topology.of(model.shape)
    n_faces = len(model.faces)
    min_area = DEGENERATE_REL_AREA * bbox_diagonal(model, meshed=True) ** 2  # as checks.degenerate_mask has it
    bulk = bulk_triangulation_arrays(model.faces) if not params.force_fallback else [None] * n_faces
    own = set(own_faces(model, params, tol))
    surfaces: list[Surface | None] = [surface_of(f) if BRep_Tool.Surface_s(f) is not None else None
                                      for f in model.faces]  # none: a tessellated-only face (stored triangles)
    # every face's error will be measured: a large part pays numba's start-up once (B-splines sooner: numpy
    # evaluates them ~5× slower than closed forms)
    points = len(barycentric_grid(params.sample_order))
    tri_count = [len(b[2]) if b is not None else 0 for b in bulk]
    free_form = sum(n for n, sf in zip(tri_count, surfaces, strict=True) if sf is not None and sf.data is not None
                    and sf.surface_type in ("bspline", "bezier"))
    if sum(tri_count) * points >= COMPILED_MIN_POINTS or free_form * points >= COMPILED_MIN_POINTS / 3:
        load_kernels()
    prog("meshing", 0.45)
    skip = {i: "large_curved" for i in own} if not params.force_fallback else dict.fromkeys(range(n_faces), "forced")
    looks = first_look(model.faces, topo, bulk, surfaces, skip, params.sample_order, min_area)
    patches: list[FacePatch | None] = []
    fallback: dict[int, str] = {}
    first_error: dict[int, np.ndarray] = {}
    for i, look in enumerate(looks):
        look.found.record(topo)
        patches.append(look.found.assemble(model.faces[i], bulk[i]) if look.reason is None else None)
        if look.reason is not None:
            fallback[i] = look.reason
        elif look.error is not None:
            first_error[i] = look.error
    prog("meshing", 0.5)
    # edges of faces that keep OCCT's mesh keep OCCT's discretisation; re-mesh the rest from it
    todo = set(fallback)
    errors: list[np.ndarray] = [np.zeros(0)] * n_faces
    unmeshed: list[int] = []
    for round_ in range(ENFORCE_ROUNDS + 1):
        stage = Progress(progress, 0.5 + 0.08 * round_, 0.58 + 0.08 * round_)
        stage("re-meshing faces", 0.0)
        remesh = [i for i in todo if surfaces[i] is not None]
        for i in remesh:  # every edge discretised here, before faces are meshed apart from each other
            discretize_missing_edges(model.faces[i], topo, tol * ENFORCE_MARGIN, params.angular)

        def remesh_face(i: int) -> FacePatch | None:
            old = patches[i]
            seeds = None
            if old is not None and old.uv is not None:
                seeds = old.uv[(old.node_edge < 0) & (old.node_vertex < 0)]
            try:
                return mesh_face(i, model.faces[i], topo, surfaces[i], tol * ENFORCE_MARGIN,  # type: ignore[arg-type]
                                 params.angular, params.sample_order, seeds, min_area)
            except AmprepError:
                return None

        for i, patch in _costliest_first(remesh_face, remesh, patches, errors, tol * ENFORCE_MARGIN).items():
            patches[i] = patch
            if patch is None:
                unmeshed.append(i)
        for i in range(n_faces):
            stage("measuring chordal error", 0.5 + 0.5 * i / n_faces)
            if patches[i] is None or not (round_ == 0 or i in todo):
                continue
            if round_ == 0 and i in first_error:
                errors[i] = first_error[i]
            else:
                errors[i] = patch_error(patches[i], surfaces[i], params.sample_order)
        if not params.enforce_tolerance or round_ == ENFORCE_ROUNDS:
            break
        target = tol * ENFORCE_MARGIN
        over = [i for i in range(n_faces) if patches[i] is not None and len(errors[i])
                and np.nanmax(errors[i], initial=0) > tol * TRIGGER_MARGIN
                and not _within_on_a_finer_grid(patches[i], surfaces[i], errors[i], tol)]
        if not over:
            break
        todo = set()
        for i in over:  # a face's own boundary chords bound its error: split edges whose sagitta exceeds tol
            for edge in face_edges(model.faces[i]):
                ei = topo.edge_index(edge)
                before = topo.edge_params.get(ei)
                if before is None:
                    continue
                after = split_edge_to_tolerance(edge, before, target)
                if len(after) != len(before):
                    topo.edge_params[ei] = after
                    todo |= _faces_of_edge(model, topo, ei)
        mend = []
        for i in over:  # a face whose boundary stands is refined where it fails, the rest of its mesh kept
            if (i in todo or surfaces[i] is None or patches[i].uv is None  # type: ignore[union-attr]
                    or len(errors[i]) < LOCAL_MIN_TRIANGLES or np.mean(errors[i] > target) > LOCAL_MAX_BAD
                    or has_pole(model.faces[i])):
                todo.add(i)
            else:
                mend.append(i)

        def mend_face(i: int, target: float = target) -> FacePatch | None:
            refined = refine_patch(patches[i], errors[i], surfaces[i], target, params.sample_order)  # type: ignore[arg-type]
            if refined is not None:
                refined = flip_flat_triangles(refined, surfaces[i], target, params.sample_order, min_area)  # type: ignore[arg-type]
            return None if refined is None or flat_triangles(refined, min_area).any() else refined

        for i, refined in _costliest_first(mend_face, mend, patches, errors, target).items():
            if refined is None:
                todo.add(i)
            else:
                patches[i], errors[i] = refined, refined.error  # type: ignore[assignment]
        for i in todo.union(over):
            fallback.setdefault(i, "tolerance")
        prog("enforcing tolerance", 0.5 + 0.08 * (round_ + 1))
    infos = tuple(
        FaceInfo(i, surfaces[i].surface_type if surfaces[i] is not None else "none", model.face_solid[i],
                 patches[i].meshed_by if patches[i] is not None else "none")
        for i in range(n_faces)
    )
    prog("welding", 0.95)
    mesh = orient_stored_shells(weld([p for p in patches if p is not None], infos, topo.vertex_roots()))
    face_error = np.array([np.nanmax(e) if len(e) and np.isfinite(e).any() else np.nan for e in errors])
    prog("welding", 1.0)
    return MeshResult(mesh, tol, face_error, fallback, tuple(sorted(set(unmeshed))))


#: re-meshing a face costs about this many triangles' time (face_pool's unit) whatever its size
REMESH_PER_FACE = 100


def _costliest_first(fn: Callable[[int], FacePatch | None], faces: list[int], patches: list[FacePatch | None],
                     errors: list[np.ndarray], target: float) -> dict[int, FacePatch | None]:
    """{i: fn(i)} for the faces, through face_pool.map_faces, costliest first by _remesh_cost. In parallel only once
    the compiled kernels run every chordal measure (numpy's floats differ in the last bits, and which faces a process
    would measure in numpy depends on timing): the result stays deterministic."""
    cost = {i: _remesh_cost(patches[i], errors[i], target) for i in faces}
    order = sorted(faces, key=lambda i: (-cost[i], i))
    return map_faces(fn, order, ready=kernels_loaded, cost=[cost[i] for i in order])


def _remesh_cost(patch: FacePatch | None, error: np.ndarray, target: float) -> float:
    """Time to re-mesh a face in triangles' worth: REMESH_PER_FACE plus the triangles its new mesh is expected to have,
    Σ max(1, ε_T / target) over its old triangles (ε ∝ h², so a triangle ε/target over the target needs about that
    many in its place), or its old triangle count when not measured."""
    if patch is None:
        return REMESH_PER_FACE
    if len(error) != len(patch.tris) or not len(error):
        return REMESH_PER_FACE + float(len(patch.tris))
    return REMESH_PER_FACE + float(np.maximum(np.nan_to_num(error / target, nan=1.0), 1.0).sum())


def _within_on_a_finer_grid(patch: FacePatch | None, surface: Surface | None, error: np.ndarray, tol: float) -> bool:
    """A close call (sampled max in (TRIGGER_MARGIN·tol, tol]): the triangles over TRIGGER_MARGIN·tol measured again
    on the order-FINE_ORDER grid, whose miss is (6/24)² of the order-6 grid's; True (and `error` updated) when they
    are all ≤ FINE_MARGIN·tol, so the face keeps its mesh instead of being re-meshed for a sampling doubt."""
    if patch is None or surface is None or patch.uv is None or not np.nanmax(error, initial=0) <= tol:
        return False
    band = np.flatnonzero(error > tol * TRIGGER_MARGIN)
    t = patch.tris[band]
    fine = triangle_chordal_error(patch.nodes[t], patch.uv[t], surface, FINE_ORDER, affine=surface.affine)
    if fine.max(initial=0) > tol * FINE_MARGIN:
        return False
    error[band] = np.maximum(error[band], fine)
    return True


def _faces_of_edge(model: CadModel, topo: Topology, edge_index: int) -> set[int]:
    """Ids of the faces bounded by a B-rep edge (cached edge → faces map on the topology)."""
    cache = getattr(topo, "_edge_faces", None)
    if cache is None:
        cache = {}
        for i, f in enumerate(model.faces):
            for e in face_edges(f):
                cache.setdefault(topo.edge_index(e), set()).add(i)
        topo._edge_faces = cache  # type: ignore[attr-defined]
    return cache.get(edge_index, set())
