"""The source paper's Tables 1 and 2 on the corpus: triangles per surface type and the regularity of the
tessellation (four-bin counts and the mean of the angle, area and edge measures) at ε = 0.34 mm, for amprep's
tessellation and for OCCT's BRepMesh alone, next to the paper's rows (Pro/E, SolidWorks, its method).

    python bench/regularity.py                 # writes docs/regularity_table2.md and .csv
    python bench/regularity.py --tolerance 0.1 --name regularity_0.1
    python bench/regularity.py --gmsh          # adds gmsh sized to the chord tolerance (bench/gmsh_chord.py)
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
CORPUS = Path(os.environ.get("AMPREP_CORPUS", ROOT.parent / "shared" / "corpus"))

import numpy as np  # noqa: E402

from amprep.geometry.cad.read import read_cad  # noqa: E402
from amprep.geometry.core.formats import CAD_FORMATS, sniff_path  # noqa: E402
from amprep.geometry.measure.regularity import MEASURES, regularity, summarize  # noqa: E402
from amprep.geometry.meshing.params import MeshParams  # noqa: E402
from amprep.geometry.meshing.pipeline import mesh_model  # noqa: E402

# Paper 000 (../shared/seeds/), Table 2 at ε = 0.34 mm: bins [0, 0.005) [0.005, 0.4) [0.4, 0.8) [0.8, 1] and the mean.
PAPER_TABLE2 = {
    "Pro/E": {"angle": ([39, 1034, 845, 524], 0.457549), "area": ([14, 997, 843, 588], 0.477277),
              "edge": ([132, 1609, 610, 91], 0.284350)},
    "SolidWorks": {"angle": ([63, 749, 1138, 438], 0.499124), "area": ([30, 790, 1034, 534], 0.510262),
                   "edge": ([129, 1487, 757, 15], 0.298160)},
    "paper's method": {"angle": ([10, 634, 1380, 427], 0.510036), "area": ([0, 650, 1353, 448], 0.514934),
                       "edge": ([38, 1869, 538, 6], 0.300517)},
}
# Paper 000, Table 1 at ε = 0.34 mm: triangles per surface type.
PAPER_TABLE1 = {
    "Pro/E": {"plane": 494, "cone": 778, "sphere": 57, "torus": 672, "bspline": 441},
    "SolidWorks": {"plane": 437, "cone": 717, "sphere": 30, "torus": 745, "bspline": 459},
    "paper's method": {"plane": 516, "cone": 781, "sphere": 48, "torus": 876, "bspline": 230},
}
TYPES = ("plane", "cylinder", "cone", "sphere", "torus", "bspline", "other")


def corpus_parts() -> list[Path]:
    """Every CAD file of the corpus with exact surfaces (the tessellated-only AP242 has none)."""
    out = []
    for p in sorted(CORPUS.iterdir()):
        if p.is_file() and p.suffix.lower() != ".md" and sniff_path(p) in CAD_FORMATS and "tessellated" not in p.name:
            out.append(p)
    return out


def row(mesh) -> dict:
    """Triangles per surface type and the regularity summary of one mesh."""
    s = summarize(regularity(mesh.corners))
    types = dict.fromkeys(TYPES, 0)
    kinds = [f.surface_type for f in mesh.faces]
    for fid, n in zip(*np.unique(mesh.face_ids[mesh.face_ids >= 0], return_counts=True)):
        t = kinds[fid] if kinds[fid] in types else "other"
        types[t] += int(n)
    return {"triangles": mesh.n_triangles, "types": types,
            **{k: (s.bins[k], s.mean[k]) for k in MEASURES}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tolerance", type=float, default=0.34)
    ap.add_argument("--name", default="regularity_table2")
    ap.add_argument("--gmsh", action="store_true", help="add gmsh's Frontal-Delaunay, sized to the chord tolerance")
    ap.add_argument("--gmsh-timeout", type=float, default=900.0, help="seconds gmsh may take on one part")
    ap.add_argument("--only", default="", help="comma-separated substrings of the parts' names")
    args = ap.parse_args()
    rows: list[tuple[str, str, dict]] = []
    failed: list[str] = []  # parts gmsh failed on or took too long with
    only = [s for s in args.only.split(",") if s]
    for path in corpus_parts():
        if only and not any(s in path.name for s in only):
            continue
        model = read_cad(path)
        for label, params in (("amprep", MeshParams(tolerance=args.tolerance)),
                              ("amprep quality", MeshParams(tolerance=args.tolerance, mesher="quality")),
                              ("OCCT BRepMesh", MeshParams(tolerance=args.tolerance, enforce_tolerance=False))):
            t0 = time.perf_counter()
            res = mesh_model(model, params)
            r = row(res.mesh)
            r["seconds"] = time.perf_counter() - t0
            r["max_error"] = res.max_error
            r["over"] = 0 if label != "OCCT BRepMesh" and res.within_tolerance else None
            rows.append((path.name, label, r))
            _print(path.name, label, r)
            faces = res.mesh.faces
        if args.gmsh:
            from gmsh_chord import mesh_gmsh

            g = mesh_gmsh(path, args.tolerance, model, faces, args.gmsh_timeout)
            if g is None:
                print(f"{path.name:38s} {GMSH}: failed or over {args.gmsh_timeout:g} s", flush=True)
                failed.append(path.name)
                continue
            r = row(g["mesh"])
            r.update(seconds=g["seconds"], max_error=g["max_error"], over=g["over"], unmeasured=g["unmeasured"])
            rows.append((path.name, GMSH, r))
            _print(path.name, GMSH, r)
    write(rows, args.tolerance, args.name, failed, args.gmsh_timeout)


GMSH = "gmsh (chord-sized)"


def _print(part: str, label: str, r: dict) -> None:
    print(f"{part:38s} {label:18s} {r['triangles']:7d} " + " ".join(f"{k} {r[k][1]:.4f}" for k in MEASURES),
          flush=True)


def write(rows: list[tuple[str, str, dict]], tol: float, name: str, failed: Sequence[str] = (),
          timeout: float = 0.0) -> None:
    docs = ROOT / "docs"
    with open(docs / f"{name}.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["part", "mesher", "triangles", *[f"{k}_{x}" for k in MEASURES for x in ("b0", "b1", "b2", "b3", "mean")],
                    *TYPES])
        for part, label, r in rows:
            w.writerow([part, label, r["triangles"], *[v for k in MEASURES for v in (*r[k][0], f"{r[k][1]:.6f}")],
                        *[r["types"][t] for t in TYPES]])
    lines = [f"# Regularity of the tessellation at ε = {tol} mm (the source paper's Tables 1 and 2)", "",
             f"Generated by `python bench/regularity.py{'' if tol == 0.34 else f' --tolerance {tol} --name {name}'}"
             f"{' --gmsh' if failed or any(label == GMSH for _, label, _ in rows) else ''}`. "
             "Measures of paper 000 (1 = equilateral): angle, area, edge; the paper's bins [0, 0.005) [0.005, 0.4) "
             "[0.4, 0.8) [0.8, 1]. amprep: the default mesher (OCCT BRepMesh, welded by topology, re-meshed where "
             "the chord tolerance is exceeded); amprep quality: `--mesher quality` (every face by our mesher, seed "
             "000's approach: planes by constrained Delaunay to a 30° minimum angle, curved faces from a (u,v) grid "
             "cut near square on the surface, large analytic faces bounded by iso-lines as closed-form rows, "
             "boundary segments graded to the faces' width); OCCT BRepMesh: the "
             "default without the tolerance enforcement; gmsh (chord-sized), with `--gmsh`: gmsh's Frontal-Delaunay "
             "with its size from the larger principal curvature, √(8 · 0.95 ε / κ), the rule the quality mesher's "
             "cells follow (bench/gmsh_chord.py), its chordal error measured by amprep's measure on the B-rep's "
             "faces; its seconds include a Python size callback, so they are no measure of gmsh's speed. "
             "`× amprep`: triangles over the default mesher's. The "
             "paper's rows are for its own test part (not in the corpus), so compare the shape of the distributions "
             "and the means, not the counts.", "",
             "## Table 2: regularity", "",
             "| part | mesher | triangles | × amprep | angle bins | angle mean | area bins | area mean | edge bins | "
             "edge mean |",
             "|---|---|---:|---:|---|---:|---|---:|---|---:|"]
    base = {part: r["triangles"] for part, label, r in rows if label == "amprep"}
    for label, t in PAPER_TABLE2.items():
        n = sum(t["angle"][0])
        lines.append(f"| paper 000 test part | {label} | {n} | | "
                     + " | ".join(f"{'/'.join(map(str, t[k][0]))} | {t[k][1]:.4f}" for k in MEASURES) + " |")
    for part, label, r in rows:
        ratio = f"{r['triangles'] / base[part]:.2f}" if base.get(part) else ""
        lines.append(f"| {part} | {label} | {r['triangles']} | {ratio} | "
                     + " | ".join(f"{'/'.join(map(str, r[k][0]))} | {r[k][1]:.4f}" for k in MEASURES) + " |")
    lines += ["", "## Table 1: triangles per surface type", "",
              "| part | mesher | " + " | ".join(TYPES) + " | total |", "|---|---|" + "---:|" * (len(TYPES) + 1)]
    for label, t in PAPER_TABLE1.items():
        lines.append(f"| paper 000 test part | {label} | " + " | ".join(str(t.get(k, "–")) for k in TYPES)
                     + f" | {sum(t.values())} |")
    for part, label, r in rows:
        lines.append(f"| {part} | {label} | " + " | ".join(str(r["types"][k]) for k in TYPES) + f" | {r['triangles']} |")
    lines += ["", "## Chord error and time", "",
              "`over tol`: triangles whose chordal error exceeds ε (– where not counted: OCCT's mesh is not measured "
              "per triangle); gmsh's faces that its (u,v) could not be matched to are left out of its error "
              "(`unmeasured`).", "",
              "| part | mesher | max chordal error (mm) | over tol | seconds |", "|---|---|---:|---:|---:|"]
    for part, label, r in rows:
        over = "–" if r.get("over") is None else str(r["over"])
        if r.get("unmeasured"):
            over += f" ({r['unmeasured']} faces unmeasured)"
        lines.append(f"| {part} | {label} | {r['max_error']:.4g} | {over} | {r['seconds']:.2f} |")
    lines += [f"| {part} | {GMSH} | failed or over {timeout:g} s | | |" for part in failed]
    (docs / f"{name}.md").write_text("\n".join(lines) + "\n")
    print(f"wrote docs/{name}.md")


if __name__ == "__main__":
    main()
