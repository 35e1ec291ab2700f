"""Where the tolerance is kept: every face's chordal error measured, and any face over the tolerance re-meshed or
refined where it fails (its edges split where their own sagitta exceeds it), for up to ENFORCE_ROUNDS rounds.

Faces OCCT left unmeshed or broken are meshed here from the shared edge discretisation (face_mesher.py); a face
over the tolerance whose boundary stands is mended locally (local_refine.py), any other meshed again whole.
"""

from __future__ import annotations

from collections.abc import Callable
from contextlib import nullcontext
from dataclasses import dataclass, field, replace

import numpy as np

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.cad.estimate import TriangleEstimate
from amprep.geometry.cad.read import CadModel
from amprep.geometry.cad.surfaces import Surface
from amprep.geometry.cad.topology import Topology, face_edges, faces_of_edge
from amprep.geometry.core.compiled import compiled
from amprep.geometry.core.progress import Progress, ProgressFn, budgeted, checkpoint, grew_over
from amprep.geometry.measure.chordal import (
    free_form_work,
    kernels_loaded,
    load_kernels,
    triangle_chordal_error,
    worth_compiling,
)
from amprep.geometry.meshing.face_mesher import bare_ruled_seam, boundary_loops, mesh_face, ruled_patch
from amprep.geometry.meshing.lattice import Field, mesh_lattice, plan_lattices
from amprep.geometry.meshing.local_refine import flat_triangles, flip_flat_triangles, refine_patch
from amprep.geometry.meshing.occt_check import patch_error
from amprep.geometry.meshing.occt_read import FacePatch
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.prepare import quality_estimate, refuse_quality_too_large
from amprep.geometry.meshing.shared_edges import (
    ANALYTIC,
    LINES_STAY_LINES,
    ROOM,
    bare_straight_edges,
    collapse_short_edges,
    discretize_missing_edges,
    edge_length,
    grade_edges,
    has_pole,
    split_edge_to_tolerance,
    stagger_strips,
)
from amprep.geometry.meshing.uv_cdt import MIN_SPACING, crossing_segments
from amprep.geometry.meshing.weld import BrepGaps, seat_boundaries
from amprep.geometry.parallel.face_pool import SharedCount, map_faces

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
#: are (local_refine.py); any other is meshed again whole: a fresh CDT packs the points better than OCCT's layout
#: can be mended (a countersink cone's apex fan: 90 triangles re-meshed, 124 mended), and a small face costs little;
#: so is a face with a pole or apex (a degenerated edge), where points mended into OCCT's fan make tilted triangles
LOCAL_MIN_TRIANGLES = 1000
LOCAL_MAX_BAD = 0.25
#: re-meshing a face costs about this many triangles' time (face_pool's unit) whatever its size
REMESH_PER_FACE = 100
#: a closed edge (one vertex at both ends) gets at least this many segments, so a face it bounds alone has area:
#: BRepMesh collapses a circle under its minimum size onto its vertex (KiCad's DSUB-15: a pin's 0.05 mm end disc at
#: 0.1 mm, left with no triangles and reported unmeshed)
CLOSED_EDGE_SEGMENTS = 3
#: an edge the B-rep's gap g leaves off a tight face's surface (weld.seat_boundaries) is split to the target less g, to
#: no less than this × the target: a gap near the tolerance is reported, not chased into ever smaller triangles. The
#: face itself is meshed to the target: its triangles' error holds the gap already (their corners are off the surface),
#: so a face target less g counted it twice and chased triangles at the boundary chords no insertion could mend (CTC-02's
#: cones: 3,182 slivers of regularity under 0.005 each in a band 8 µm wide along the chord)
GAP_FLOOR = 0.25
#: rounds in which a face whose discretised boundary crosses itself has the crossing segments split (_uncross)
UNCROSS_ROUNDS = 6


@dataclass
class FaceStates:
    """Every face of a model while its tolerance is enforced: patches (F,) (None: unmeshed), errors (F,) arrays of
    per-triangle chordal error, why faces were meshed by us (`fallback`), and the faces no mesher could mesh."""

    model: CadModel
    topo: Topology
    surfaces: list[Surface | None]
    params: MeshParams
    tol: float
    min_area: float
    patches: list[FacePatch | None]
    fallback: dict[int, str]
    errors: list[np.ndarray] = field(init=False)
    unmeshed: list[int] = field(default_factory=list)
    lattice: dict[int, Field] = field(default_factory=dict)  # faces whose rows lattice.plan_lattices set
    uses: np.ndarray = field(default=None)  # type: ignore[assignment]  # (F,) faces of the model each stands for
    estimated: int = 0  # the quality mesher's estimate, once made (_estimate)
    compiled: bool = False  # its faces meshed with the compiled kernels, as that estimate decided (_estimate)
    expected: dict[int, float] = field(default_factory=dict)  # that estimate per face, meshed once (_estimate)
    gaps: BrepGaps = field(default_factory=BrepGaps)  # the B-rep's gaps at the faces' boundaries (weld.seat_boundaries)
    was_over: set[int] = field(default_factory=set)  # faces over the tolerance in some round so far
    tight: set[int] = field(default_factory=set)  # faces over in two rounds: edges split to less_gap from then on
    plain: set[int] = field(default_factory=set)  # the quality mesher's faces over in three: the default's mesher then

    def __post_init__(self) -> None:
        self.errors = [np.zeros(0)] * len(self.patches)
        if self.uses is None:
            self.uses = np.ones(len(self.patches), np.int64)


def enforce_tolerance(f: FaceStates, first_error: dict[int, np.ndarray], progress: ProgressFn | None) -> None:
    """Mesh the faces OCCT left to us, measure every face (first_error: errors already measured by occt_check), then
    re-mesh or mend the faces over the tolerance until none is or ENFORCE_ROUNDS have run; `f` is updated."""
    prog = Progress(progress)
    todo = set(f.fallback)  # edges of faces that keep OCCT's mesh keep OCCT's discretisation; the rest from it
    for i in _open_collapsed_loops(f, todo) - todo:
        f.fallback[i] = "closed_edge"
        todo.add(i)
    over: list[int] = []
    for round_ in range(ENFORCE_ROUNDS + 1):
        stage = Progress(progress, 0.5 + 0.08 * round_, 0.58 + 0.08 * round_)
        stage("re-meshing faces", 0.0)
        _remesh(f, todo)
        uncrossed = _uncross(f)
        todo |= uncrossed
        for i in uncrossed:  # OCCT's mesh of these was measured by occt_check: they are ours now
            first_error.pop(i, None)
        moved = seat_boundaries(f.patches, f.surfaces, f.topo.vertex_roots(), f.tol, f.gaps)
        _measure(f, round_, todo, first_error, stage)
        _measure_moved(f, moved)
        if not f.params.enforce_tolerance or round_ == ENFORCE_ROUNDS:
            break
        over = [i for i in range(len(f.patches)) if f.patches[i] is not None and len(f.errors[i])
                and np.nanmax(f.errors[i], initial=0) > f.tol * TRIGGER_MARGIN
                and not _within_on_a_finer_grid(f.patches[i], f.surfaces[i], f.errors[i], f.tol)]
        if not over:
            break
        if f.params.quality:  # over three times, once with edges to less_gap: the quality mesher cannot, the plain one
            _to_plain(f, f.tight.intersection(over))
        # over twice (not only running: a face within once re-meshed can be over again when its neighbours' boundary
        # nodes move, and so on in turn): the B-rep's gap is reckoned with from now
        f.tight.update(f.was_over.intersection(over))
        f.was_over.update(over)
        todo = _split_edges(f, over)
        _mend(f, over, todo)
        for i in todo.union(over):
            f.fallback.setdefault(i, "tolerance")
        prog("enforcing tolerance", 0.5 + 0.08 * (round_ + 1))


def _remesh(f: FaceStates, todo: set[int]) -> None:
    """Mesh the faces of `todo` with a surface again from the shared edge discretisation (seeded with the interior
    points of their old mesh); every edge is discretised first, before faces are meshed apart from each other."""
    target = f.tol * ENFORCE_MARGIN
    remesh = sorted(i for i in todo if f.surfaces[i] is not None)  # the lattices plan in face order
    # the quality mesher's free-form faces first: their edges' chords at ROOM × the target leave their triangles
    # room to stand on them (shared_edges.bend_sizes); an edge keeps the discretisation its first face gave it
    free = {i for i in remesh if f.params.quality and f.surfaces[i].surface_type not in ANALYTIC}  # type: ignore[union-attr]
    for i in sorted(remesh, key=lambda i: i not in free):
        discretize_missing_edges(f.model.faces[i], f.topo, target * (ROOM if i in free else 1.0), f.params.angular)
        if not f.params.all_own:
            bare_ruled_seam(f.model.faces[i], f.surfaces[i], f.topo)  # type: ignore[arg-type]
    if f.params.quality:
        loops, planned = _plan_quality(f, remesh, target)
    redone = set(remesh)
    kept = sum(len(p.tris) * int(f.uses[i]) for i, p in enumerate(f.patches) if p is not None and i not in redone)
    if f.params.quality and not f.estimated:
        f.compiled = _estimate(f, remesh, loops, planned, kept)

    limit = f.params.max_triangles
    made = SharedCount(kept)

    def remesh_face(i: int) -> FacePatch | None:
        checkpoint()  # a cancel is seen face by face
        with budgeted((limit - made.value) // int(f.uses[i]), limit):  # one face stops once it alone would be over
            patch = mesh_one(i)
        # the estimate before meshing is an estimate: the limit is kept as the faces come, in every process at once
        if patch is not None and made.add(len(patch.tris) * int(f.uses[i])) > limit:
            raise grew_over(limit)
        return patch

    def mesh_one(i: int) -> FacePatch | None:
        old = f.patches[i]
        seeds = None
        if old is not None and old.uv is not None and not (i in f.plain and old.meshed_by in ("quality", "lattice")):
            seeds = old.uv[(old.node_edge < 0) & (old.node_vertex < 0)]  # not the points the quality mesh met again
        try:
            face, made = f.model.faces[i], None
            if i in f.lattice and i not in f.plain:
                made = mesh_lattice(i, face, boundary_loops(face, f.topo, target, f.params.angular), f.surfaces[i],  # type: ignore[arg-type]
                                    f.lattice[i], target, f.params.check_order)
            elif not f.params.all_own:  # the fewest triangles: a ruled face's strip or fan where it keeps the target
                made = ruled_patch(i, face, boundary_loops(face, f.topo, target, f.params.angular), f.surfaces[i],  # type: ignore[arg-type]
                                   target, f.params.check_order)
            if made is not None:
                return made
            return mesh_face(i, face, f.topo, f.surfaces[i], target,  # type: ignore[arg-type]
                             f.params.angular, f.params.check_order, seeds, f.min_area,
                             quality=f.params.quality and i not in f.plain)
        except AmprepError as exc:
            if exc.code != ErrorCode.MESHING_FAILED:  # a cancel seen at a checkpoint stops the job, not the face
                raise
            return None

    if f.compiled:
        load_kernels()  # before the face pool forks: its processes inherit them
    with compiled(True) if f.compiled else nullcontext():
        meshed = _costliest_first(remesh_face, remesh, f.patches, f.errors, target, f.expected)
    for i, patch in meshed.items():
        f.patches[i] = patch
    f.unmeshed = sorted({i for i in f.unmeshed if f.patches[i] is None} | {i for i, p in meshed.items() if p is None})


def _to_plain(f: FaceStates, faces: set[int]) -> None:
    """The quality mesher's faces over the tolerance in three rounds (its refinement stopped short and each
    round met the same mesh again) meshed from then on as the default mesher meshes its own faces (from the boundary,
    refined alone), and listed in `fallback` as `quality_refinement`."""
    for i in sorted(faces - f.plain):
        f.plain.add(i)
        f.fallback[i] = "quality_refinement"


def _uncross(f: FaceStates) -> set[int]:
    """Mesh again the faces left unmeshed because their discretised boundary crosses itself in (u,v) (two edges that
    meet at a small angle, each a chord off its curve, cross there): the crossing segments split at their middle
    parameter, every face of a split edge meshed again, up to UNCROSS_ROUNDS times and while the crossings get fewer
    (edges that touch cross however fine); returns the faces meshed again."""
    redone: set[int] = set()
    before = np.inf
    for _ in range(UNCROSS_ROUNDS):
        split: set[int] = set()
        crossings = 0
        for i in f.unmeshed:
            if f.surfaces[i] is not None:
                edges, count = _split_crossings(f, i)
                split |= edges
                crossings += count
        if not split or crossings >= before:
            break
        before = crossings
        faces = set().union(*(faces_of_edge(f.model.faces, f.topo, e) for e in split))
        for i in faces:
            f.fallback.setdefault(i, "boundary_crossing")
        _remesh(f, faces)
        redone |= faces
    return redone


def _split_crossings(f: FaceStates, i: int) -> tuple[set[int], int]:
    """The edges of face i split at the middle parameter of the longer (in (u,v)) of each pair of their segments that
    cross (uv_cdt.crossing_segments: near a vertex where two edges meet at a small angle, the longer chord leaves at
    the larger angle; halving both would keep the crossing); returns those edges and the number of crossing pairs."""
    try:
        loops = boundary_loops(f.model.faces[i], f.topo, f.tol * ENFORCE_MARGIN, f.params.angular)
    except AmprepError:
        return set(), 0
    if not loops:
        return set(), 0
    uv = [lp["uv"] for lp in loops]
    pairs = crossing_segments(uv)
    length = np.linalg.norm(np.concatenate([np.roll(q, -1, axis=0) - q for q in uv]), axis=1)
    longer = np.where(length[pairs[:, 0]] >= length[pairs[:, 1]], pairs[:, 0], pairs[:, 1])
    edges = np.concatenate([lp["segment"] for lp in loops])[longer]
    spans = np.concatenate([lp["span"] for lp in loops])[longer]
    keep = spans[:, 0] != spans[:, 1]
    split: set[int] = set()
    for e in np.unique(edges[keep]).tolist():
        mids = np.unique(spans[keep & (edges == e)].mean(axis=1))
        f.topo.edge_params[e] = np.unique(np.concatenate([f.topo.edge_params[e], mids]))
        split.add(e)
    return split, len(pairs)


def less_gap(target: float, gap: float) -> float:
    """The target an edge is split to where the B-rep's gap (mm) leaves it off a face's surface:
    max(target − gap, GAP_FLOOR × target)."""
    return max(target - gap, GAP_FLOOR * target)


def _plan_quality(f: FaceStates, remesh: list[int], target: float) -> tuple[list[list[dict]], list[Field | None]]:  # type: ignore[type-arg]
    """The quality mesher's edges for the faces of `remesh`: short ones collapsed, the rest graded to the faces'
    widths, lattices planned (their side edges at their rows); (their boundary loops, their lattices). An edge this
    would change that bounds a face not in `remesh` (a later round's few faces, beside faces whose mesh stands on the
    old points) keeps its points: a face of `remesh` on such an edge is not a lattice then (its rows may need them)."""
    before = dict(f.topo.edge_params)
    faces = [f.model.faces[i] for i in remesh]
    collapse_short_edges(faces, f.topo, MIN_SPACING * f.tol)
    bare_straight_edges(faces, f.topo, lambda ei: _faces_all(f, ei, LINES_STAY_LINES))
    grade_edges(faces, [f.surfaces[i] for i in remesh], f.topo, f.tol, target, f.params.min_size)  # type: ignore[misc]
    stagger_strips(faces, [f.surfaces[i] for i in remesh], f.topo, lambda ei: _faces_all(f, ei, ("plane",)))  # type: ignore[misc]
    loops = [_loops_to_plan(face, f.topo, target, f.params.angular) for face in faces]
    planned = plan_lattices(faces, [f.surfaces[i] for i in remesh], loops, f.topo,  # type: ignore[misc]
                            target, f.params.angular, f.params.max_triangles)
    inside = set(remesh)
    kept = {e for e, p in f.topo.edge_params.items() if e in before and p is not before[e]
            and any(i not in inside and f.patches[i] is not None for i in faces_of_edge(f.model.faces, f.topo, e))}
    for e in kept:
        f.topo.edge_params[e] = before[e]
    for k, i in enumerate(remesh):
        if kept and any(f.topo.edge_index(e) in kept for e in face_edges(faces[k])):
            planned[k] = None
            loops[k] = _loops_to_plan(faces[k], f.topo, target, f.params.angular)
            f.lattice.pop(i, None)
    f.lattice.update((i, p) for i, p in zip(remesh, planned, strict=True) if p is not None)
    return loops, planned


def _faces_all(f: FaceStates, edge_index: int, kinds: tuple[str, ...]) -> bool:
    """True when every face the edge bounds (in `remesh` or not) has a surface of one of `kinds`: LINES_STAY_LINES,
    those that keep lines straight in their (u,v); ("plane",), those no lattice's rows stand on."""
    return all(f.surfaces[i] is not None and f.surfaces[i].surface_type in kinds  # type: ignore[union-attr]
               for i in faces_of_edge(f.model.faces, f.topo, edge_index))


def _estimate(f: FaceStates, remesh: list[int], loops: list[list[dict]], planned: list[Field | None],  # type: ignore[type-arg]
              kept: int) -> bool:
    """f.estimated: the quality mesher's estimate (prepare.quality_estimate) of the faces of `remesh` with their
    boundary_loops `loops` and planned lattices, each × its uses, and the `kept` triangles other faces already have;
    output_too_large when over the limit. Returns chordal.worth_compiling of that estimate (its B-spline and Bézier
    work apart): whether the faces are meshed with the compiled kernels, decided by the part alone before any is."""
    segments = [sum(max(len(f.topo.edge_params.get(f.topo.edge_index(e), ())) - 1, 0) for e in face_edges(f.model.faces[i]))
                for i in remesh]
    rows = [p.expected if p is not None else None for p in planned]
    expected = quality_estimate([f.surfaces[i] for i in remesh], loops, segments, rows, f.tol)  # type: ignore[misc]
    f.expected = {i: REMESH_PER_FACE + float(n) for i, n in zip(remesh, expected, strict=True)}
    placed = expected * f.uses[remesh]
    f.estimated = refuse_quality_too_large(placed, kept, f.tol, f.params.max_triangles, lambda: TriangleEstimate(
        f.model.faces, f.params.angular, f.uses, f.params.min_size))
    free_form = free_form_work(placed, [f.surfaces[i] for i in remesh])
    return worth_compiling(f.estimated, f.params.check_order, free_form)


def _open_collapsed_loops(f: FaceStates, faces: set[int]) -> set[int]:
    """Cut every closed edge of `faces` (both ends one vertex, not degenerated, longer than CLOSED_EDGE_SEGMENTS ×
    MIN_SPACING × tolerance) discretised in fewer than CLOSED_EDGE_SEGMENTS segments into that many equal parameter
    steps; returns the faces of every edge cut, all of which must be meshed from the new discretisation."""
    cut: set[int] = set()
    for i in sorted(faces):
        for edge in face_edges(f.model.faces[i]):
            ei, v1, _, v2, _, degenerate = f.topo.edge_facts(edge)
            params = f.topo.edge_params.get(ei)
            if degenerate or v1 != v2 or params is None or len(params) > CLOSED_EDGE_SEGMENTS:
                continue
            new = np.linspace(params[0], params[-1], CLOSED_EDGE_SEGMENTS + 1)
            if edge_length(edge, new) > CLOSED_EDGE_SEGMENTS * MIN_SPACING * f.tol:
                f.topo.edge_params[ei] = new
                cut |= faces_of_edge(f.model.faces, f.topo, ei)
    return cut


def _loops_to_plan(face, topo: Topology, target: float, angular: float) -> list[dict]:  # type: ignore[no-untyped-def,type-arg]
    """boundary_loops, or none where a wire does not join up (no lattice is planned; meshing the face says why)."""
    try:
        return boundary_loops(face, topo, target, angular)
    except AmprepError:
        return []


def _measure(f: FaceStates, round_: int, todo: set[int], first_error: dict[int, np.ndarray], stage: Progress) -> None:
    """The chordal error of every face in the first round (first_error where occt_check measured it), of the faces
    of `todo` after."""
    n = len(f.patches)
    for i in range(n):
        stage("measuring chordal error", 0.5 + 0.5 * i / n)
        if f.patches[i] is None or not (round_ == 0 or i in todo):
            continue
        if round_ == 0 and i in first_error:
            f.errors[i] = first_error[i]
        else:
            f.errors[i] = patch_error(f.patches[i], f.surfaces[i], f.params.check_order)


def _measure_moved(f: FaceStates, moved: dict[int, np.ndarray]) -> None:
    """The chordal error of the triangles touching a node seat_boundaries moved ({face: (k,) bool}) measured again
    (the rest of a face's errors, measured before the move or by its mesher, stand: their corners did not move)."""
    for i, m in moved.items():
        p, surf = f.patches[i], f.surfaces[i]
        if p is None or surf is None or p.uv is None or p.meshed_by == "stored" or len(f.errors[i]) != len(p.tris):
            continue
        t = np.flatnonzero(m[p.tris].any(axis=1))
        errors = f.errors[i].copy()
        errors[t] = triangle_chordal_error(p.nodes[p.tris[t]], p.uv[p.tris[t]], surf, f.params.check_order,
                                           affine=surf.affine)
        f.errors[i] = errors
        f.patches[i] = replace(p, error=errors) if p.error is not None else p


def _split_edges(f: FaceStates, over: list[int]) -> set[int]:
    """Split the edges of the faces over the tolerance whose own sagitta exceeds the target (a face's boundary chords
    bound its error), less the B-rep's gap along an edge a triangle over the target touches where the face is tight
    (over in two rounds: the gap, not the sagitta, kept it over; less_gap): the larger of the edge's gap and the
    face's (which holds its vertices': a chord from a vertex off the face stands off it by the vertex's gap at that
    end); the faces of every split edge, to be meshed again."""
    target = f.tol * ENFORCE_MARGIN
    todo: set[int] = set()
    for i in over:
        p = f.patches[i]
        touched: set[int] = set()
        if p is not None and len(f.errors[i]) == len(p.tris):
            edges = p.node_edge[p.tris[f.errors[i] > target]]
            touched = set(np.unique(edges[edges >= 0]).tolist())
        for edge in face_edges(f.model.faces[i]):
            ei = f.topo.edge_index(edge)
            before = f.topo.edge_params.get(ei)
            if before is None:
                continue
            # the face's gap, where more than the edge's own: a B-rep vertex's counts at the edges it ends
            gap = max(f.gaps.edge.get(ei, 0.0), f.gaps.face.get(i, 0.0)) if ei in touched and i in f.tight else 0.0
            after = split_edge_to_tolerance(edge, before, less_gap(target, gap))
            if len(after) != len(before):
                f.topo.edge_params[ei] = after
                todo |= faces_of_edge(f.model.faces, f.topo, ei)
    return todo


def _mend(f: FaceStates, over: list[int], todo: set[int]) -> None:
    """Refine the faces over the tolerance whose boundary stands where they fail, the rest of their mesh kept
    (large faces with few bad triangles and no pole); add every other face, and any whose mending fails, leaves it
    worse (a region re-triangulated in a (u,v) space the face was not meshed in can span it) or adds flat triangles,
    to `todo`."""
    target = f.tol * ENFORCE_MARGIN
    mend = []
    for i in over:
        if (i in todo or f.surfaces[i] is None or f.patches[i].uv is None  # type: ignore[union-attr]
                or len(f.errors[i]) < LOCAL_MIN_TRIANGLES or np.mean(f.errors[i] > target) > LOCAL_MAX_BAD
                or has_pole(f.model.faces[i])):
            todo.add(i)
        else:
            mend.append(i)

    def mend_face(i: int) -> FacePatch | None:
        order = f.params.check_order
        refined = refine_patch(f.patches[i], f.errors[i], f.surfaces[i], target, order)  # type: ignore[arg-type]
        if refined is not None:
            refined = flip_flat_triangles(refined, f.surfaces[i], target, order, f.min_area)  # type: ignore[arg-type]
        if refined is None or np.nanmax(refined.error, initial=0) > np.nanmax(f.errors[i], initial=0):  # type: ignore[arg-type]
            return None
        # flat triangles it made; a face may hold some already (a horn torus's axis: a line of (u,v) at one point)
        return None if flat_triangles(refined, f.min_area).sum() > flat_triangles(f.patches[i], f.min_area).sum() \
            else refined

    for i, refined in _costliest_first(mend_face, mend, f.patches, f.errors, target).items():
        if refined is None:
            todo.add(i)
        else:
            f.patches[i], f.errors[i] = refined, refined.error  # type: ignore[assignment]


def _costliest_first(fn: Callable[[int], FacePatch | None], faces: list[int], patches: list[FacePatch | None],
                     errors: list[np.ndarray], target: float,
                     expected: dict[int, float] | None = None) -> dict[int, FacePatch | None]:
    """{i: fn(i)} for the faces, through face_pool.map_faces, costliest first by `expected` (face_pool's unit: the
    quality mesher's estimate) where given, else by _remesh_cost; in parallel once the compiled kernels are loaded
    (which evaluator measures is the part's choice, core/compiled.py, so the result is the same either way)."""
    known = expected or {}
    cost = {i: known[i] if i in known else _remesh_cost(patches[i], errors[i], target) for i in faces}
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
