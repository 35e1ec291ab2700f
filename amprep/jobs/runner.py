"""Run one job of a kind on files in a directory: the single entry the Celery tasks (and tests) call.

Params are the kind's values (jobs.params.check fills defaults and enforces bounds, once more here since a job record
may have been written by another version); each fills the geometry library's parameter dataclasses by field name.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from amprep.geometry.core.progress import ProgressFn
from amprep.jobs.params import build, check

Runner = Callable[[Path, Path | None, dict[str, Any], Path, ProgressFn | None], tuple[dict[str, Any], list[Path]]]


def run_convert(src: Path, stl: Path | None, params: dict[str, Any], out_dir: Path,
                progress: ProgressFn | None) -> tuple[dict[str, Any], list[Path]]:
    """convert: `part.stl` (binary, or ASCII) or `part.3mf`, and `summary.json`."""
    from amprep.geometry.meshing.params import MeshParams
    from amprep.jobs.convert import convert, write_result

    result = convert(src, build(MeshParams, params), progress)
    out = out_dir / f"part.{params['format']}"
    if progress:
        progress("writing", 1.0)
    written = write_result(result, out, ascii=params["ascii"])
    summary = result.summary()
    summary["output"] = {k: v for k, v in written.items() if k != "path"} | {"name": out.name}
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=2, default=float), encoding="utf-8")
    return summary, [out, out_dir / "summary.json"]


def run_analyze(src: Path, stl: Path | None, params: dict[str, Any], out_dir: Path,
                progress: ProgressFn | None) -> tuple[dict[str, Any], list[Path]]:
    """analyze: report.json, mesh.stl, per-triangle fields (chordal_error.f32, cusp_height.f32) and PNG plots."""
    from amprep.geometry.measure.analysis import AnalysisParams
    from amprep.geometry.meshing.params import MeshParams
    from amprep.jobs.analyze import analyze_file
    from amprep.jobs.artifacts import write_analysis

    a = analyze_file(src, stl, build(MeshParams, params), build(AnalysisParams, params), progress)
    if progress:
        progress("writing", 1.0)
    paths = write_analysis(a, out_dir)
    r = a.report
    summary = {"mesh": {k: r["mesh"][k] for k in ("triangles", "vertices", "watertight", "boundary_edges",
                                                  "nonmanifold_edges", "shells", "volume", "area")},
               "chordal_error": r["chordal_error"], "cusp_height": {k: r["cusp_height"][k] for k in ("layer", "approximate")},
               "issues": r["issues"], "provenance": r.get("provenance", {})}
    return summary, paths


def run_refine(src: Path, stl: Path | None, params: dict[str, Any], out_dir: Path,
               progress: ProgressFn | None) -> tuple[dict[str, Any], list[Path]]:
    """refine: `refined.stl` (or .3mf; in the STL's own frame when one was given), report.json,
    chordal_error.f32 and error_vs_size.png."""
    from amprep.geometry.meshing.params import MeshParams
    from amprep.geometry.refine.compare import RefineParams
    from amprep.jobs.artifacts import write_refinement
    from amprep.jobs.refine import refine_file

    r = refine_file(src, stl, build(MeshParams, params), build(RefineParams, params), progress)
    if progress:
        progress("writing", 1.0)
    paths = write_refinement(r, out_dir, f"refined.{params['format']}", ascii=params["ascii"])
    rep = r.report
    summary = {"method": rep["method"], "mesh_before": {k: rep["mesh_before"][k] for k in ("triangles", "watertight")},
               "mesh": {k: rep["mesh"][k] for k in ("triangles", "watertight", "boundary_edges", "nonmanifold_edges")},
               "refined_faces": [{k: f[k] for k in ("id", "surface_type", "triangles_before", "triangles_after",
                                                   "chordal_error_before", "chordal_error_after")}
                                 for f in rep["refined_faces"]],
               "issues": rep["issues"], "provenance": rep["provenance"]}
    if rep.get("butterfly") is not None:  # node classes, triangles by region, moves: a few numbers per level
        summary["butterfly"] = rep["butterfly"]
    return summary, paths


RUNNERS: dict[str, Runner] = {"convert": run_convert, "analyze": run_analyze, "refine": run_refine}


def run(kind: str, src: Path, params: dict[str, Any], out_dir: Path,
        progress: ProgressFn | None = None, stl: Path | None = None) -> tuple[dict[str, Any], list[Path]]:
    """Run job `kind` on `src` with its params (service-only keys allowed, ignored here); (result summary, artifact
    paths under out_dir)."""
    values = check(kind, params, service=True)
    out_dir.mkdir(parents=True, exist_ok=True)
    return RUNNERS[kind](src, stl, values, out_dir, progress)
