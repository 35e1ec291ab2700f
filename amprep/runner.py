"""Run one job of a kind on files in a directory: the single entry the Celery tasks (and tests) call.

Params arrive as a dict validated by the API's per-kind model (defaults filled in); the runner maps them onto
the geometry library's dataclasses, writes artifacts into `out_dir` and returns a JSON-ready result.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from .geometry.errors import AmprepError, ErrorCode
from .geometry.progress import ProgressFn

MESH_KEYS = ("tolerance", "relative", "angular", "min_size", "algorithm", "occt_edges", "own_large_faces")


def mesh_params(params: dict[str, Any]):  # type: ignore[no-untyped-def]
    """MeshParams from a job's params (keys as the CLI's long options in snake_case)."""
    from .geometry.tessellate import MeshParams

    kw = {k: params[k] for k in MESH_KEYS if params.get(k) is not None}
    return MeshParams(**kw)


def run_convert(src: Path, stl: Path | None, params: dict[str, Any], out_dir: Path, progress: ProgressFn | None) -> tuple[dict, list[Path]]:
    """convert: `part.stl` (binary, or ASCII) or `part.3mf`, and `summary.json`."""
    from .geometry.convert import convert, write_result

    result = convert(src, mesh_params(params), progress)
    out = out_dir / ("part.3mf" if params.get("format") == "3mf" else "part.stl")
    if progress:
        progress("writing", 1.0)
    written = write_result(result, out, ascii=bool(params.get("ascii")))
    summary = result.summary()
    summary["output"] = {k: v for k, v in written.items() if k != "path"} | {"name": out.name}
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=2, default=float))
    return summary, [out, out_dir / "summary.json"]


def run_analyze(src: Path, stl: Path | None, params: dict[str, Any], out_dir: Path,
                progress: ProgressFn | None) -> tuple[dict, list[Path]]:
    """analyze: report.json, mesh.stl, per-triangle fields (chordal_error.f32, cusp_height.f32) and PNG plots."""
    from .geometry.analysis import AnalysisParams, analyze_file
    from .geometry.report_files import write_analysis

    ap = AnalysisParams(layer=params.get("layer", 0.2), build_dir=tuple(params.get("build_dir", (0.0, 0.0, 1.0))),
                        sample_order=params.get("sample_order", 6), cloud_density=params.get("cloud_density"),
                        bounding_box=params.get("bounding_box", True))
    a = analyze_file(src, stl, mesh_params(params), ap, progress)
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
               progress: ProgressFn | None) -> tuple[dict, list[Path]]:
    """refine: `refined.stl` (or .3mf; in the STL's own frame when one was given), report.json,
    chordal_error.f32 and error_vs_size.png."""
    from .geometry.refine import RefineParams, refine_file
    from .geometry.report_files import write_refinement

    rp = RefineParams(method=params.get("method", "sma"),
                      faces=tuple(params["faces"]) if params.get("faces") is not None else None,
                      max_chordal=params.get("max_chordal"), max_cusp=params.get("max_cusp"),
                      max_cylindricity=params.get("max_cylindricity"), layer=params.get("layer", 0.2),
                      build_dir=tuple(params.get("build_dir", (0.0, 0.0, 1.0))),
                      ratios=params.get("ratios", "3:4:3,3:4:3"), iterations=params.get("iterations", 1),
                      target=params.get("target"),
                      compare=params.get("compare", True), max_triangles=params.get("max_triangles", 10_000_000))
    mp = mesh_params({"tolerance": 0.2} | params)
    r = refine_file(src, stl, mp, rp, progress)
    if progress:
        progress("writing", 1.0)
    name = "refined.3mf" if params.get("format") == "3mf" else "refined.stl"
    paths = write_refinement(r, out_dir, name, ascii=bool(params.get("ascii")))
    rep = r.report
    summary = {"method": rep["method"], "mesh_before": {k: rep["mesh_before"][k] for k in ("triangles", "watertight")},
               "mesh": {k: rep["mesh"][k] for k in ("triangles", "watertight", "boundary_edges", "nonmanifold_edges")},
               "refined_faces": [{k: f[k] for k in ("id", "surface_type", "triangles_before", "triangles_after",
                                                   "chordal_error_before", "chordal_error_after")}
                                 for f in rep["refined_faces"]],
               "issues": rep["issues"], "provenance": rep["provenance"]}
    return summary, paths


RUNNERS = {"convert": run_convert, "analyze": run_analyze, "refine": run_refine}


def run(kind: str, src: Path, params: dict[str, Any], out_dir: Path,
        progress: ProgressFn | None = None, stl: Path | None = None) -> tuple[dict[str, Any], list[Path]]:
    """Run job `kind` on `src`; (result summary, artifact paths under out_dir)."""
    if kind not in RUNNERS:
        raise AmprepError(ErrorCode.INVALID_PARAMETER, f"unknown job kind '{kind}'")
    out_dir.mkdir(parents=True, exist_ok=True)
    return RUNNERS[kind](src, stl, params, out_dir, progress)
