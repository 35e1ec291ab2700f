"""The files of a job's result written to a directory: report.json, the scored or refined mesh, per-triangle fields
and the plots."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from amprep.geometry.core.mesh import Mesh
from amprep.geometry.io import plots
from amprep.geometry.io.stl import write_stl
from amprep.geometry.io.write import write_mesh
from amprep.geometry.measure.analysis import Analysis
from amprep.geometry.measure.regularity import regularity
from amprep.jobs.refine import RefineResult

#: Per-triangle fields for the viewer: little-endian float32, one value per triangle of mesh.stl, NaN = unknown.
FIELDS = ("chordal_error", "cusp_height")
#: The CAD face of each triangle for the viewer: little-endian int32 per triangle (-1: none), written with a CAD model.
FACE_IDS = "face_id.i32"


def _face_ids(mesh: Mesh, out_dir: Path) -> list[Path]:
    """face_id.i32 of a mesh that has CAD faces; nothing for a mesh read from an STL alone."""
    if not len(mesh.face_ids) or int(mesh.face_ids.max()) < 0:
        return []
    p = out_dir / FACE_IDS
    p.write_bytes(np.asarray(mesh.face_ids, "<i4").tobytes())
    return [p]


def write_analysis(a: Analysis, out_dir: Path, with_plots: bool = True) -> list[Path]:
    """Files of an analysis under out_dir; returns their paths (report.json first)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    report = out_dir / "report.json"
    report.write_text(json.dumps(a.report, indent=1, default=float, allow_nan=False), encoding="utf-8")
    paths = [report]
    mesh = out_dir / "mesh.stl"
    write_stl(a.mesh, mesh, header="amprep analysis: the mesh the report scores")
    paths.append(mesh)
    for name, values in zip(FIELDS, (a.chordal, a.cusp_height)):
        p = out_dir / f"{name}.f32"
        p.write_bytes(np.asarray(values, "<f4").tobytes())
        paths.append(p)
    paths += _face_ids(a.mesh, out_dir)
    if with_plots:
        if a.box is not None:
            paths.append(plots.cusp_per_slice(a.box, a.cusp["approximate"]["mean"],
                                              out_dir / "cusp_per_slice.png"))
        if a.faces:
            paths.append(plots.chordal_per_face(a.faces, a.input.get("tolerance"),
                                                out_dir / "chordal_per_face.png"))
        paths.append(plots.regularity_histograms(regularity(a.mesh.corners), out_dir / "regularity.png"))
    return paths


def write_refinement(r: RefineResult, out_dir: Path, name: str = "refined.stl", ascii: bool = False,
                     with_plots: bool = True) -> list[Path]:
    """The refined mesh (STL or 3MF by `name`, in the user's frame), report.json, chordal_error.f32 and face_id.i32
    of the refined mesh, before.stl (the mesh it refined, in the same frame) and error_vs_size.png; returns their
    paths (the mesh first)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    mesh_path = write_refined_mesh(r, out_dir / name, ascii)
    report = out_dir / "report.json"
    report.write_text(json.dumps(r.report, indent=1, default=float, allow_nan=False), encoding="utf-8")
    field = out_dir / "chordal_error.f32"
    field.write_bytes(np.asarray(r.chordal, "<f4").tobytes())
    before = out_dir / "before.stl"
    write_stl(r.before, before, header="amprep refine: the mesh before refinement")
    paths = [mesh_path, report, field, before, *_face_ids(r.mesh, out_dir)]
    if with_plots and r.report.get("comparison"):
        paths.append(plots.error_vs_size(r.report["comparison"], out_dir / "error_vs_size.png"))
    return paths


def write_refined_mesh(r: RefineResult, out: Path, ascii: bool = False) -> Path:
    """The refined mesh as binary/ASCII STL or 3MF by the extension; header/metadata name the method and versions."""
    p = r.report.get("provenance", {})
    header = f"amprep {p.get('amprep')} occt {p.get('occt')} refine {r.report['method']} {r.report['params']['ratios']}"
    write_mesh(r.mesh, out, header, r.report["input"].get("sha256", ""), ascii)
    return out
