"""Write an analysis to a directory: report.json, the scored mesh, per-triangle fields and the plots."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from . import plots
from .analysis import Analysis
from .io_stl import write_stl
from .quality import regularity

#: Per-triangle fields for the viewer: little-endian float32, one value per triangle of mesh.stl, NaN = unknown.
FIELDS = ("chordal_error", "cusp_height")


def write_analysis(a: Analysis, out_dir: Path, with_plots: bool = True) -> list[Path]:
    """Files of an analysis under out_dir; returns their paths (report.json first)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    report = out_dir / "report.json"
    report.write_text(json.dumps(a.report, indent=1, default=float, allow_nan=False))
    paths = [report]
    mesh = out_dir / "mesh.stl"
    write_stl(a.mesh, mesh, header="amprep analysis: the mesh the report scores")
    paths.append(mesh)
    for name, values in zip(FIELDS, (a.chordal, a.cusp_height)):
        p = out_dir / f"{name}.f32"
        p.write_bytes(np.asarray(values, "<f4").tobytes())
        paths.append(p)
    if with_plots:
        if a.box is not None:
            paths.append(plots.cusp_per_slice(a.box, a.report["cusp_height"]["approximate"]["mean"],
                                              out_dir / "cusp_per_slice.png"))
        if a.report["faces"]:
            paths.append(plots.chordal_per_face(a.report["faces"], a.report["input"].get("tolerance"),
                                                out_dir / "chordal_per_face.png"))
        paths.append(plots.regularity_histograms(regularity(a.mesh.corners), out_dir / "regularity.png"))
    return paths
