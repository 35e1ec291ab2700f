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

MESH_KEYS = ("tolerance", "relative", "angular", "min_size", "algorithm")


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


def run_analyze(src: Path, stl: Path | None, params: dict[str, Any], out_dir: Path, progress: ProgressFn | None) -> tuple[dict, list[Path]]:
    """analyze: `report.json` with the input, the mesh checks and the issues found."""
    from .geometry.convert import convert
    from .geometry.report import SCHEMA, mesh_issues, mesh_section

    # With a user's STL the mesh scored is that STL (its checks); scoring it against the CAD is issue #5.
    result = convert(stl if stl is not None else src, mesh_params(params), progress)
    unmeshed = len(result.meshing.unmeshed_faces) if result.meshing else 0
    report = {
        "schema": SCHEMA,
        "input": result.input,
        "mesh": mesh_section(result.mesh, result.checks, result.manifold3d),
        "issues": mesh_issues(result.checks, result.manifold3d, unmeshed),
        "provenance": result.provenance,
        "notes": result.notes,
    }
    path = out_dir / "report.json"
    path.write_text(json.dumps(report, indent=2, default=float))
    return {"mesh": report["mesh"], "issues": report["issues"]}, [path]


def run_refine(src: Path, stl: Path | None, params: dict[str, Any], out_dir: Path, progress: ProgressFn | None) -> tuple[dict, list[Path]]:
    raise AmprepError(ErrorCode.NOT_IMPLEMENTED, "refine is not available in this release (issue #6)")


RUNNERS = {"convert": run_convert, "analyze": run_analyze, "refine": run_refine}


def run(kind: str, src: Path, params: dict[str, Any], out_dir: Path,
        progress: ProgressFn | None = None, stl: Path | None = None) -> tuple[dict[str, Any], list[Path]]:
    """Run job `kind` on `src`; (result summary, artifact paths under out_dir)."""
    if kind not in RUNNERS:
        raise AmprepError(ErrorCode.INVALID_PARAMETER, f"unknown job kind '{kind}'")
    out_dir.mkdir(parents=True, exist_ok=True)
    return RUNNERS[kind](src, stl, params, out_dir, progress)
