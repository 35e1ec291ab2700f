"""STL-only refinement benchmark (refine/butterfly.py): speed of one level in output triangles per second on the
83k-triangle counter and on a ~1.3 M-triangle STL, and on corpus CAD parts tessellated at 0.5 mm and written to STL,
the mean distance of the curved faces' points to the exact CAD (OCCT's BRepExtrema) before and after one and two
levels, in one run.

    python bench/butterfly.py [--write]     # --write: docs/bench_butterfly.md
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
CORPUS = Path(os.environ.get("AMPREP_CORPUS", ROOT.parent / "shared" / "corpus"))

from amprep.geometry.cad.read import read_cad  # noqa: E402
from amprep.geometry.core.checks import check_mesh  # noqa: E402
from amprep.geometry.core.mesh import Mesh  # noqa: E402
from amprep.geometry.io.stl import read_stl, write_stl  # noqa: E402
from amprep.geometry.measure.defects import self_intersections  # noqa: E402
from amprep.geometry.meshing.params import MeshParams  # noqa: E402
from amprep.geometry.meshing.pipeline import mesh_model  # noqa: E402
from amprep.geometry.refine.butterfly import ButterflyParams, butterfly_refine  # noqa: E402

PARTS = ["voron_vhb_din_mount.step", "voron_hotend_mount_dragon.step", "featuretype_inch_ap214.step",
         "cq_cube_cylinder_colors.step", "nist_ctc02_ap242.stp"]


def speed(mesh: Mesh, repeat: int = 3) -> tuple[int, float]:
    """(output triangles, best seconds of `repeat` runs of one level)."""
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = butterfly_refine(mesh, ButterflyParams(levels=1)).mesh
        best = min(best, time.perf_counter() - t0)
    return out.n_triangles, best


def _mean_distance(model, mesh: Mesh, face_of: np.ndarray, curved: np.ndarray, m0: int, n: int = 300) -> float:
    """Mean distance to its CAD face of n sampled centroids of triangles whose input triangle (index mod m0) was on a
    curved face (`face_of`, `curved`: (m0,) of the input)."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeVertex
    from OCP.BRepExtrema import BRepExtrema_DistShapeShape
    from OCP.gp import gp_Pnt

    tris = np.flatnonzero(curved[np.arange(mesh.n_triangles) % m0])
    pick = np.random.default_rng(2).choice(tris, min(n, len(tris)), replace=False)
    d = []
    for j in pick:
        face = model.faces[int(face_of[j % m0])]
        p = mesh.corners[j].mean(axis=0)
        ext = BRepExtrema_DistShapeShape(BRepBuilderAPI_MakeVertex(gp_Pnt(*map(float, p))).Vertex(), face)
        d.append(ext.Value())
    return float(np.mean(d))


def accuracy(name: str, tmp: Path) -> dict[str, object]:
    """A corpus part at 0.5 mm to STL, refined alone 1 and 2 levels: mean distance of curved faces to the CAD."""
    model = read_cad(CORPUS / name)
    res = mesh_model(model, MeshParams(tolerance=0.5))
    kinds = np.array([f.surface_type for f in res.mesh.faces])
    curved = kinds[res.mesh.face_ids] != "plane"
    face_of = res.mesh.face_ids.astype(np.int64)
    path = tmp / "part.stl"
    write_stl(res.mesh, path)
    stl = read_stl(path)
    row: dict[str, object] = {"part": name, "triangles": stl.n_triangles,
                              "before": _mean_distance(model, stl, face_of, curved, stl.n_triangles)}
    for levels in (1, 2):
        out = butterfly_refine(stl, ButterflyParams(levels=levels)).mesh
        row[f"after_{levels}"] = _mean_distance(model, out, face_of, curved, stl.n_triangles)
        row[f"closed_{levels}"] = check_mesh(out).closed
        row[f"self_int_{levels}"] = self_intersections(out)[0]
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--write", action="store_true")
    args = ap.parse_args()
    counter = read_stl(CORPUS / "counter_83k.stl")
    big = butterfly_refine(counter, ButterflyParams(levels=2)).mesh  # a 1.3 M-triangle input
    lines = ["# STL-only refinement (Butterfly): speed and accuracy", "",
             "`python bench/butterfly.py --write`, on this 2-core machine, in one run.", "",
             "## One level, output triangles per second (best of 3)", "",
             "| input | triangles in | out | seconds | M triangles/s |", "|---|---|---|---|---|"]
    for label, mesh in (("counter_83k.stl", counter), ("counter_83k refined twice (an STL of 1.3 M)", big)):
        out, sec = speed(mesh)
        lines.append(f"| {label} | {mesh.n_triangles:,} | {out:,} | {sec:.3f} | {out / sec / 1e6:.2f} |")
    lines += ["", "## Corpus parts at 0.5 mm, refined from the STL alone", "",
              "Mean distance (mm) of points on triangles of curved CAD faces to their face, by OCCT's BRepExtrema "
              "(300 sampled triangle centroids).", "",
              "| part | STL triangles | before | 1 level | 2 levels | closed | self-intersections |",
              "|---|---|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory() as tmp:
        for name in PARTS:
            r = accuracy(name, Path(tmp))
            lines.append(f"| {name} | {r['triangles']:,} | {r['before']:.4f} | {r['after_1']:.4f} | "
                         f"{r['after_2']:.4f} | {r['closed_1']}/{r['closed_2']} | {r['self_int_1']}/{r['self_int_2']} |")
            print(lines[-1], flush=True)
    text = "\n".join(lines) + "\n"
    print(text)
    if args.write:
        (ROOT / "docs" / "bench_butterfly.md").write_text(text)


if __name__ == "__main__":
    main()
