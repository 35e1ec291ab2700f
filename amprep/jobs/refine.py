"""The refine job: choose faces, refine them (SMA, VTA or adaptive), and prove it: per-face numbers before/after, the
mesh checks before/after, and the comparison with uniform re-tessellations of the whole part."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.cad.edge_curves import EdgeCurves
from amprep.geometry.cad.read import CadModel, read_cad
from amprep.geometry.cad.surfaces import Surface, surface_of
from amprep.geometry.core.compiled import compiled
from amprep.geometry.core.edges import edge_incidence
from amprep.geometry.core.mesh import Mesh
from amprep.geometry.core.progress import Progress, ProgressFn
from amprep.geometry.measure.analysis import AnalysisParams, analyze_mesh, face_chordal_errors, faces_section
from amprep.geometry.measure.chordal import worth_compiling
from amprep.geometry.measure.regularity import regularity
from amprep.geometry.measure.report import Issue
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.pipeline import mesh_file
from amprep.geometry.placement.place import PlacedStl, place_user_stl, unmatched_issue
from amprep.geometry.refine.butterfly import ButterflyParams, butterfly_refine
from amprep.geometry.refine.compare import (
    STL_HEADER,
    STL_PER_TRIANGLE,
    RefineParams,
    compare,
    mesh_summary,
    predicted_size,
    refine_faces,
    refine_params_section,
    refined_faces,
    select_faces,
    topology_issues,
)
from amprep.geometry.refine.face_domain import FaceDomains
from amprep.geometry.refine.limit_surface import LimitSurface, remesh_to_edge
from amprep.jobs.common import input_of, is_cad, model_info, provenance, read_mesh, sha256_file


@dataclass(frozen=True, eq=False)
class RefineResult:
    """The refined mesh in the user's frame (`mesh`), the one scored in the CAD's frame (`cad_mesh`), the mesh
    before (in the user's frame, as `mesh`), the report, and per-triangle chordal error of `mesh`."""

    mesh: Mesh
    cad_mesh: Mesh
    before: Mesh
    report: dict[str, Any]
    chordal: np.ndarray
    surfaces: dict[int, Surface] = field(default_factory=dict)
    faces: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))


def refine_file(path: str | Path, stl: str | Path | None = None, mesh_params: MeshParams = MeshParams(tolerance=0.2),
                params: RefineParams = RefineParams(), progress: ProgressFn | None = None) -> RefineResult:
    """Refine a CAD part's tessellation, or (with `stl`) the user's own STL placed on the CAD, and report."""
    params.validate()
    prog = Progress(progress)
    fmt, info = input_of(path)
    if params.method == "butterfly":
        if is_cad(fmt) or stl is not None:
            raise AmprepError(ErrorCode.INVALID_PARAMETER, "butterfly refines an STL alone (no CAD): give the STL as "
                              "the input; for a CAD model use sma, vta or adaptive")
        return refine_stl(path, info, params, prog)
    if not is_cad(fmt):
        raise AmprepError(ErrorCode.INVALID_PARAMETER, f"{params.method.upper()} refines faces of a CAD model: give "
                          "the STEP, IGES, BREP or ACIS (SAT, SAB, DXF) (and the STL with --stl), or use method butterfly for an STL alone")
    placed: PlacedStl | None = None
    if stl is not None:
        prog("reading", 0.0)
        model = read_cad(path, fmt)
        user = read_mesh(stl)
        placed = place_user_stl(model, user, mesh_params, prog.span(0.02, 0.4))
        mesh, surfaces = placed.mesh, placed.surfaces
        info.update(model_info(model), source="user_stl", stl_sha256=sha256_file(stl), stl_triangles=user.n_triangles)
        base_tol = float(mesh_params.tolerance)
    else:
        model, res = mesh_file(path, fmt, mesh_params, prog.span(0.02, 0.3))
        mesh, base_tol = res.mesh, res.tolerance
        surfaces = {i: surface_of(f) for i, f in enumerate(model.faces)}
        info.update(model_info(model), source="tessellation", tolerance=res.tolerance)
    with compiled(worth_compiling(mesh.n_triangles, params.sample_order)):  # decided by the mesh, not by timing
        return _refine_and_report(model, mesh, surfaces, placed, info, base_tol, mesh_params, params, prog)


def levels_within(n_triangles: int, max_triangles: int) -> int:
    """The most levels (1..6) of 1-to-4 splitting whose output n·4^L fits max_triangles (output_too_large if none)."""
    levels = next((L for L in range(6, 0, -1) if n_triangles * 4**L <= max_triangles), 0)
    if not levels:
        raise AmprepError(ErrorCode.OUTPUT_TOO_LARGE, f"one level of butterfly would output {n_triangles * 4:,} "
                          f"triangles, over the limit of {max_triangles:,}")
    return levels


def _butterfly(mesh: Mesh, params: RefineParams, prog: Progress) -> tuple[Mesh, dict[str, Any]]:
    """The refined mesh and the report's `butterfly` section: `levels` of splitting (0: as many as max_triangles
    allows), or with max_edge a re-mesh to that edge length on the limit surface."""
    bp = ButterflyParams(1, params.feature_angle)
    if params.max_edge is not None:
        surface = LimitSurface.of(mesh, bp, progress=prog.span(0.05, 0.3))
        remeshed = remesh_to_edge(surface, params.max_edge, params.max_triangles, prog.span(0.3, 0.5))
        out, off = remeshed.mesh, remeshed.moved  # off: the new nodes' offsets from the input's facets
        inc = edge_incidence(out.triangles)
        longest = float(np.linalg.norm(out.vertices[inc.edges[:, 0]] - out.vertices[inc.edges[:, 1]], axis=1).max())
        section = surface.refinement.to_json() | {
            "levels": None, "max_edge": params.max_edge, "limit_depth": surface.depth, "triangles_out": out.n_triangles,
            "longest_edge": longest, "per_level": [],
            "moved": {"max": float(off.max(initial=0.0)), "mean": float(off.mean()) if len(off) else 0.0}}
        return out, section
    levels = params.levels or levels_within(mesh.n_triangles, params.max_triangles)
    size = mesh.n_triangles * 4**levels
    if size > params.max_triangles:
        raise AmprepError(ErrorCode.OUTPUT_TOO_LARGE, f"{levels} level(s) of butterfly would output {size:,} "
                          f"triangles, over the limit of {params.max_triangles:,}: fewer levels")
    result = butterfly_refine(mesh, replace(bp, levels=levels), prog.span(0.05, 0.5))
    return result.mesh, result.to_json()


def refine_stl(path: str | Path, info: dict[str, Any], params: RefineParams, prog: Progress) -> RefineResult:
    """An STL refined alone by the modified Butterfly scheme (butterfly.py, limit_surface.py), with the analysis of
    the result and what the refinement did (`butterfly` section: node classes, triangles by region, how far new
    nodes moved, or the re-mesh's edge length)."""
    prog("reading", 0.0)
    mesh = read_mesh(path)
    info.update(source="stl", triangles=mesh.n_triangles)
    refined, section = _butterfly(mesh, params, prog)
    ap = AnalysisParams(params.layer, params.build_dir, params.sample_order, bounding_box=False)
    with compiled(worth_compiling(refined.n_triangles, params.sample_order)):
        analysis = analyze_mesh(refined, ap, None, 0, info, None, prog.span(0.5, 0.95))
    mesh_before = mesh_summary(mesh)
    analysis.issues += topology_issues(mesh_before, analysis.mesh_section)
    analysis.params = refine_params_section(params, None) | {"levels": section["levels"], "max_edge": params.max_edge,
                                                             "feature_angle": params.feature_angle}
    report = analysis.report
    report.update(method="butterfly", mesh_before=mesh_before.to_json(), refined_faces=[], comparison=None,
                  butterfly=section, provenance=provenance(None))
    prog("done", 1.0)
    return RefineResult(refined, refined, mesh, report, analysis.chordal)


def _refine_and_report(model: CadModel, mesh: Mesh, surfaces: dict[int, Surface], placed: PlacedStl | None,
                       info: dict[str, Any], base_tol: float, mesh_params: MeshParams, params: RefineParams,
                       prog: Progress) -> RefineResult:
    """refine_file's work once the mesh to refine and its faces' surfaces are known."""
    n_faces = len(model.faces)
    ap = AnalysisParams(params.layer, params.build_dir, params.sample_order, bounding_box=False)
    before = faces_section(mesh, face_chordal_errors(mesh, surfaces, params.sample_order), surfaces, ap,
                           regularity(mesh.corners), n_faces)
    chosen = select_faces(before, params, n_faces)
    faces = np.array(sorted(chosen), dtype=np.int64)
    size = predicted_size(params.method, mesh, faces, params.iterations)
    if size > params.max_triangles:
        raise AmprepError(ErrorCode.OUTPUT_TOO_LARGE, f"{params.method.upper()} would output {size:,} triangles, over "
                          f"the limit of {params.max_triangles:,}: choose fewer faces, fewer iterations or a coarser input")
    curves = EdgeCurves(model) if placed is None else None  # a user's STL has no B-rep edges behind its vertices
    worst = max((before[f].chordal_error.max if before[f].chordal_error else 0.0 for f in faces), default=0.0)
    target = params.target if params.target is not None else (0.1 * worst if worst > 0 else 1.0)
    prog("refining", 0.45)
    ref = refine_faces(params.method, mesh, faces, surfaces, params, params.iterations, curves, target,
                       FaceDomains(model, target))
    out = ref.mesh
    prog("scoring", 0.55)
    analysis = analyze_mesh(out, ap, surfaces, n_faces, info, None, prog.span(0.55, 0.6))
    mesh_before = mesh_summary(mesh)
    analysis.mesh_section = analysis.mesh_section.with_extra(file_size=STL_HEADER + STL_PER_TRIANGLE * out.n_triangles)
    analysis.issues += topology_issues(mesh_before, analysis.mesh_section)
    if placed is not None and placed.unmatched:
        analysis.issues.append(unmatched_issue(placed))
    if not len(faces):
        analysis.issues.append(Issue("nothing_to_refine", "info", 0,
                                     "no face exceeds the thresholds: the mesh is returned unchanged"))
    comparison = None
    if params.compare:
        prog("comparing with uniform tessellations", 0.6)
        comparison = compare(model, mesh, out, faces, surfaces, params, mesh_params, base_tol, curves, target)
    analysis.params = refine_params_section(params, target)
    report = analysis.report
    report.update(method=params.method, mesh_before=mesh_before.to_json(),
                  refined_faces=refined_faces(faces, before, analysis.faces, chosen, ref), comparison=comparison,
                  provenance=provenance(mesh_params))
    user_frame, user_before = out, mesh
    if placed is not None:
        report["alignment"] = placed.alignment()
        R, t = np.asarray(placed.fit.rotation), np.asarray(placed.fit.translation)
        user_frame = replace(out, vertices=(out.vertices - t) @ R)  # x_user = Rᵀ (x_cad − t)
        user_before = replace(mesh, vertices=(mesh.vertices - t) @ R)
    prog("done", 1.0)
    return RefineResult(user_frame, out, user_before, report, analysis.chordal, surfaces, faces)
