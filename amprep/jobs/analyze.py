"""The analyze job: the error report of a CAD part's tessellation, of an STL alone, or of an STL against its CAD."""

from __future__ import annotations

from pathlib import Path

from amprep.geometry.cad.read import read_cad
from amprep.geometry.cad.surfaces import surface_of
from amprep.geometry.core.progress import Progress, ProgressFn
from amprep.geometry.measure.analysis import Analysis, AnalysisParams, analyze_mesh
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.pipeline import mesh_file
from amprep.geometry.placement.place import place_user_stl, unmatched_issue
from amprep.jobs.common import STL_INFO, input_of, is_cad, model_info, provenance, read_mesh, sha256_file


def analyze_file(path: str | Path, stl: str | Path | None = None, mesh_params: MeshParams = MeshParams(),
                 params: AnalysisParams = AnalysisParams(), progress: ProgressFn | None = None) -> Analysis:
    """Analyze CAD alone (tessellated as convert does), an STL alone, or an STL made elsewhere against its CAD (placed
    on it first, scored in the CAD's frame)."""
    prog = Progress(progress)
    fmt, info = input_of(path)
    if not is_cad(fmt):
        info.update(STL_INFO, source="stl")
        a = analyze_mesh(read_mesh(path), params, None, 0, info, None, prog.span(0.0, 1.0))
        a.extra["provenance"] = provenance()
        return a
    if stl is not None:
        prog("reading", 0.0)
        model = read_cad(path, fmt)
        user = read_mesh(stl)
        placed = place_user_stl(model, user, mesh_params, prog.span(0.05, 0.5))
        info.update(model_info(model), source="user_stl", stl_sha256=sha256_file(stl), stl_triangles=user.n_triangles)
        a = analyze_mesh(placed.mesh, params, placed.surfaces, len(model.faces), info, None, prog.span(0.5, 1.0))
        a.extra["alignment"] = placed.alignment()
        if placed.unmatched:
            a.issues.append(unmatched_issue(placed))
    else:
        model, result = mesh_file(path, fmt, mesh_params, prog.span(0.0, 0.5))
        info.update(model_info(model), source="tessellation", tolerance=result.tolerance)
        surfaces = {i: surface_of(f) for i, f in enumerate(model.faces)}
        a = analyze_mesh(result.mesh, params, surfaces, len(model.faces), info, result.tolerance, prog.span(0.5, 1.0))
    a.extra["provenance"] = provenance(mesh_params)
    return a
