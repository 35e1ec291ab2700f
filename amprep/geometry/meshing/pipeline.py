"""CAD → closed mesh within the chord tolerance on every face: the one meshing entry point of every job.

mesh_file reads a file and meshes it (the read and OCCT's first meshing in a forked child, read_ahead.py);
mesh_model meshes a model already read. Both work out the tolerance once (prepare.py), read and check OCCT's mesh of
every face (occt_check.py), enforce the tolerance on every face (enforce.py) and weld the faces by topology (weld.py).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from OCP.BRep import BRep_Tool

from amprep.geometry.cad.instances import Instancing, expand_mesh, template_face_of
from amprep.geometry.cad.read import CadModel
from amprep.geometry.cad.surfaces import Surface, surface_of
from amprep.geometry.cad.topology import Topology, mirrors
from amprep.geometry.core.checks import DEGENERATE_REL_AREA
from amprep.geometry.core.compiled import compiled
from amprep.geometry.core.mesh import FaceInfo, Mesh
from amprep.geometry.core.progress import Progress, ProgressFn
from amprep.geometry.measure.chordal import free_form_work, load_kernels, worth_compiling
from amprep.geometry.meshing.enforce import FaceStates, enforce_tolerance
from amprep.geometry.meshing.occt_check import first_look
from amprep.geometry.meshing.occt_read import FacePatch, bulk_triangulation_arrays
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.prepare import Prepared, bbox_diagonal, face_uses, prepare
from amprep.geometry.meshing.read_ahead import read_and_prepare_ahead
from amprep.geometry.meshing.weld import (
    agree_face_orientations,
    orient_stored_shells,
    pinch_double_sheets,
    split_caps,
    weld,
)


@dataclass(frozen=True, eq=False)
class MeshResult:
    """The welded mesh and how it was made: `face_error` (F,) max chordal error per face (nan: no surface),
    `tolerance` the absolute tolerance used, `fallback_faces` ids meshed by our own mesher, and why,
    `estimated_triangles` the count expected before meshing (estimate.py's from the B-rep; the quality mesher's
    from its edges and the faces' curvature, prepare.quality_estimate), `brep_gap` the largest distance of a shared
    edge or vertex point of the output from a face it bounds (mm; weld.seat_boundaries): what the B-rep's faces miss their
    shared edges by, counted in face_error; `seat_move` the farthest a face's boundary node was moved to join its
    neighbours' (mm): where two faces' pcurves put their edge apart along their surfaces, the gap is nil and this is
    how far apart."""

    mesh: Mesh
    tolerance: float
    face_error: np.ndarray
    fallback_faces: dict[int, str]
    unmeshed_faces: tuple[int, ...]
    estimated_triangles: int = 0
    brep_gap: float = 0.0
    seat_move: float = 0.0

    @property
    def max_error(self) -> float:
        e = self.face_error[np.isfinite(self.face_error)]
        return float(e.max()) if len(e) else float("nan")

    @property
    def within_tolerance(self) -> bool | None:
        """max_error ≤ tolerance (to 1e-9 of it); None when no face has a surface to measure against."""
        e = self.max_error
        return bool(e <= self.tolerance * (1 + 1e-9)) if e == e else None


def mesh_file(path: str | Path, fmt: str, params: MeshParams = MeshParams(),
              progress: ProgressFn | None = None) -> tuple[CadModel, MeshResult]:
    """(model, its mesh) of a CAD file: read and prepared in a forked child while this process loads the compiled
    kernels (read_ahead.py), then meshed as mesh_model does."""
    params.validate()
    if progress:
        progress("reading", 0.0)
    prepared = read_and_prepare_ahead(path, fmt, params, progress)
    return prepared.model, mesh_prepared(prepared, params, progress)


def mesh_model(model: CadModel, params: MeshParams = MeshParams(), progress: ProgressFn | None = None) -> MeshResult:
    """Tessellate every face; re-mesh from the shared edge discretisation any face OCCT leaves unmeshed or
    broken, and any face whose chordal error exceeds the tolerance (splitting its edges where their own
    sagitta does), until every face is within tolerance; weld by topology."""
    params.validate()
    Progress(progress)("meshing", 0.0)
    return mesh_prepared(prepare(model, params), params, progress)


def mesh_prepared(prepared: Prepared, params: MeshParams, progress: ProgressFn | None) -> MeshResult:
    """mesh_model's work after prepare(): OCCT's face meshes read and checked, the tolerance enforced, the welding;
    with instancing, on the distinct solids, then placed (instances.py)."""
    inst = prepared.instancing
    if inst is None:
        return _mesh_whole(prepared, params, progress)
    part = _mesh_whole(replace(prepared, model=inst.template, instancing=None), params, progress, face_uses(inst))
    return _placed(part, inst, prepared.model)


def _placed(part: MeshResult, inst: Instancing, model: CadModel) -> MeshResult:
    """The MeshResult of the whole model from its template's (instances.py)."""
    tf = template_face_of(inst)
    infos = tuple(FaceInfo(f, part.mesh.faces[t].surface_type, model.face_solid[f], part.mesh.faces[t].meshed_by)
                  for f, t in enumerate(tf.tolist()))
    fallback = {f: part.fallback_faces[t] for f in np.flatnonzero(np.isin(tf, list(part.fallback_faces))).tolist()
                for t in (int(tf[f]),)}
    unmeshed = tuple(np.flatnonzero(np.isin(tf, list(part.unmeshed_faces))).tolist())
    return MeshResult(expand_mesh(inst, part.mesh, infos), part.tolerance, part.face_error[tf], fallback, unmeshed,
                      part.estimated_triangles, part.brep_gap, part.seat_move)


def _mesh_whole(prepared: Prepared, params: MeshParams, progress: ProgressFn | None,
                uses: np.ndarray | None = None) -> MeshResult:
    prog = Progress(progress)
    prog("meshing", 0.4)
    model, tol = prepared.model, prepared.tolerance
    topo = Topology.of(model.shape)
    n_faces = len(model.faces)
    min_area = DEGENERATE_REL_AREA * bbox_diagonal(model, meshed=True) ** 2  # as checks.degenerate_mask has it
    surfaces: list[Surface | None] = [surface_of(f) if BRep_Tool.Surface_s(f) is not None else None
                                      for f in model.faces]  # none: a tessellated-only face (stored triangles)
    bulk = bulk_triangulation_arrays(model.faces) if not params.all_own else _stored(model, surfaces)
    use = (_compiled_for(bulk, surfaces, params.check_order, prepared.estimated) if not params.all_own
           else worth_compiling(prepared.estimated, params.check_order))  # no first mesh: the part's estimate decides
    if use:
        load_kernels()
    with compiled(use):  # one evaluator for the whole part, whatever is loaded (core/compiled.py)
        prog("meshing", 0.45)
        skip = ({i: "large_curved" for i in prepared.own} if not params.all_own
                else dict.fromkeys((i for i in range(n_faces) if surfaces[i] is not None),
                                   "quality" if params.quality else "forced"))
        looks = first_look(model.faces, topo, bulk, surfaces, skip, params.check_order, min_area)
        patches: list[FacePatch | None] = []
        fallback: dict[int, str] = {}
        first_error: dict[int, np.ndarray] = {}
        for i, look in enumerate(looks):
            if not look.found.record(topo) and look.reason is None:
                look.reason = "edge_mismatch"
            patches.append(look.found.assemble(model.faces[i], bulk[i]) if look.reason is None else None)
            if look.reason is not None:
                fallback[i] = look.reason
            elif look.error is not None:
                first_error[i] = look.error
        prog("meshing", 0.5)
        faces = FaceStates(model, topo, surfaces, params, tol, min_area, patches, fallback, uses=uses)
        enforce_tolerance(faces, first_error, progress)
    infos = tuple(
        FaceInfo(i, surfaces[i].surface_type if surfaces[i] is not None else "none", model.face_solid[i],
                 patches[i].meshed_by if patches[i] is not None else "none")
        for i in range(n_faces)
    )
    prog("welding", 0.95)
    welded = weld([p for p in patches if p is not None], infos, topo.vertex_roots())
    welded = agree_face_orientations(welded, np.array([not mirrors(f) for f in model.faces], bool))
    mesh = pinch_double_sheets(split_caps(orient_stored_shells(welded)))
    face_error = np.array([np.nanmax(e) if len(e) and np.isfinite(e).any() else np.nan for e in faces.errors])
    prog("welding", 1.0)
    return MeshResult(mesh, tol, face_error, faces.fallback, tuple(sorted(set(faces.unmeshed))),
                      faces.estimated or prepared.estimated, max(faces.gaps.face.values(), default=0.0),
                      faces.gaps.moved)


def _stored(model: CadModel, surfaces: list[Surface | None]) -> list:  # type: ignore[type-arg]
    """bulk_triangulation_arrays of the faces with no surface (a tessellated-only face keeps the triangles it stores,
    whichever mesher runs), None for every other face."""
    stored = [i for i, s in enumerate(surfaces) if s is None]
    bulk: list = [None] * len(surfaces)  # type: ignore[type-arg]
    for i, arrays in zip(stored, bulk_triangulation_arrays([model.faces[i] for i in stored]), strict=True):
        bulk[i] = arrays
    return bulk


def _compiled_for(bulk: list, surfaces: list[Surface | None], order: int, estimated: int) -> bool:  # type: ignore[type-arg]
    """True when every face's measure runs the compiled kernels (chordal.worth_compiling of the larger of OCCT's
    first mesh and the part's estimate, its free-form work as in the first mesh): decided by the part alone. The
    first mesh alone undercounts a part whose faces it leaves over the tolerance (the DTMB hull at 0.01 mm: 13,128
    triangles, 132,394 once refined, 2.4x the time on numpy)."""
    tri_count = [len(b[2]) if b is not None else 0 for b in bulk]
    total = sum(tri_count)
    free_form = free_form_work(tri_count, surfaces)
    if estimated > total:
        free_form, total = free_form * estimated / max(total, 1), estimated
    return worth_compiling(total, order, free_form)
