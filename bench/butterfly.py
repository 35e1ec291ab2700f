"""STL-only refinement benchmark (refine/butterfly.py): speed of one level in output triangles per second on the
83k-triangle counter and on a ~1.3 M-triangle STL, and on corpus CAD parts tessellated at 0.5 mm and written to STL,
the mean distance of the curved faces' points to the exact CAD (OCCT's BRepExtrema) before and after one and two
levels and a re-mesh to an edge length on the limit surface — next to SMA and adaptive refinement of the same STL
with its CAD (which they measure against), in one run.

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
from amprep.geometry.refine.compare import RefineParams  # noqa: E402
from amprep.geometry.refine.limit_surface import LimitSurface, remesh_to_edge  # noqa: E402
from amprep.jobs.refine import refine_file  # noqa: E402

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


def _mean_distance(model, mesh: Mesh, stl: Mesh, curved: np.ndarray, n: int = 300) -> float:
    """Mean distance to the CAD part (OCCT's BRepExtrema to the whole shape) of n sampled centroids of the output's
    triangles that lie over curved faces: over the input triangle nearest to it (nearest_on_mesh), with `curved`
    (m0,) of the input — so every method's output is measured the same way,
    with face ids or without."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeVertex
    from OCP.BRepExtrema import BRepExtrema_DistShapeShape
    from OCP.gp import gp_Pnt

    from amprep.geometry.refine.limit_surface import nearest_on_mesh

    rng = np.random.default_rng(2)
    some = rng.choice(mesh.n_triangles, min(20 * n, mesh.n_triangles), replace=False)  # located, then filtered
    centroids = mesh.corners[some].mean(axis=1)
    over_curved = np.flatnonzero(curved[nearest_on_mesh(centroids, stl)[1]])
    pick = over_curved[:n]
    return float(np.mean([BRepExtrema_DistShapeShape(BRepBuilderAPI_MakeVertex(gp_Pnt(*map(float, centroids[j])))
                                                     .Vertex(), model.shape).Value() for j in pick]))


def accuracy(name: str, tmp: Path) -> dict[str, object]:
    """A corpus part at 0.5 mm to STL; that STL refined alone (1 and 2 Butterfly levels, a re-mesh to 1/100 of the
    part's diagonal on the limit surface) and, with the CAD, by SMA and adaptive: (distance, triangles, closed,
    self-intersections) per method."""
    model = read_cad(CORPUS / name)
    res = mesh_model(model, MeshParams(tolerance=0.5))
    kinds = np.array([f.surface_type for f in res.mesh.faces])
    curved = kinds[res.mesh.face_ids] != "plane"
    path = tmp / "part.stl"
    write_stl(res.mesh, path)
    stl = read_stl(path)
    diag = float(np.linalg.norm(np.ptp(stl.vertices, axis=0)))
    outs = {"before": stl}
    for levels in (1, 2):
        outs[f"{levels} level{'s' if levels > 1 else ''}"] = butterfly_refine(stl, ButterflyParams(levels=levels)).mesh
    outs["max edge"] = remesh_to_edge(LimitSurface.of(stl), diag / 100, 20_000_000).mesh
    for method in ("sma", "adaptive"):
        r = refine_file(CORPUS / name, path, MeshParams(tolerance=0.5), RefineParams(method=method, compare=False))
        outs[method] = r.cad_mesh  # as refined on the CAD (the user-frame copy also carries the placement's error)
    row: dict[str, object] = {"part": name, "triangles": stl.n_triangles, "max_edge": diag / 100}
    for key, out in outs.items():
        row[key] = (_mean_distance(model, out, stl, curved), out.n_triangles, check_mesh(out).closed,
                    self_intersections(out)[0])
    return row


COLUMNS = ("before", "1 level", "2 levels", "max edge", "sma", "adaptive")


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
    lines += ["", "## Corpus parts at 0.5 mm: the STL refined alone, and by SMA and adaptive with its CAD", "",
              "Mean distance (mm) to the CAD part (OCCT's BRepExtrema) of 300 centroids of each output's triangles, "
              "drawn at random among those over curved faces (whose nearest input triangle is on a curved face), "
              "and the output's triangles. Butterfly (1 and 2 levels, and \"max edge\": re-meshed on "
              "the limit surface until no edge exceeds 1/100 of the part's diagonal) sees the STL alone; SMA and "
              "adaptive (every curved face, default settings) refine the same STL placed on its CAD and measure "
              "against it. ✓ closed with no self-intersection.", "",
              "| part | " + " | ".join(COLUMNS) + " |", "|---|" + "---|" * len(COLUMNS)]
    with tempfile.TemporaryDirectory() as tmp:
        for name in PARTS:
            r = accuracy(name, Path(tmp))
            cells = []
            for key in COLUMNS:
                d, n, closed, si = r[key]  # type: ignore[misc]
                ok = "✓" if closed and si == 0 else f"closed {closed}, {si} crossing pairs"
                cells.append(f"{d:.4f} ({n:,}) {ok}")
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
            print(lines[-1], flush=True)
    text = "\n".join(lines) + "\n"
    print(text)
    if args.write:
        (ROOT / "docs" / "bench_butterfly.md").write_text(text)


if __name__ == "__main__":
    main()
