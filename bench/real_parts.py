"""Real parts outside the corpus: every STEP, IGES and BREP a Debian package ships (FreeCAD's by default: an IDF
part library of electronic packages in STEP and IGES, and the B-rep of every FreeCAD document among its CAM and
FEM test files), converted by amprep and by the bare OCCT pipeline (Delabella), one child process per cell
(bench/convert.py's run_one). A sweep for robustness, not speed: does the part come out, closed where its B-rep
is, within the tolerance; and the triangles and seconds beside OCCT's.

    python bench/real_parts.py                          # freecad-common at 0.1 and 0.01 mm
    python bench/real_parts.py --package freecad-common --tolerances 0.1,0.01,0.001
    python bench/real_parts.py --tools amprep,amprep-quality,occt-delabella --name bench_real_parts_quality
    python bench/real_parts.py --package kicad-packages3d --sample 120 --tools amprep,amprep-quality,occt-delabella \
        --name bench_real_parts_kicad                  # 120 of KiCad's 3D models of electronic parts
    python bench/real_parts.py --built --tools amprep,amprep-quality,occt-delabella --name bench_built_parts
                                                       # solids built here (built_parts.py), each written four ways
    python bench/real_parts.py ... --rerun amprep-quality   # after a change to one mesher: the other tools' cells
                                                       # are kept from docs/NAME.csv, only this one's are run again

Downloads the package with `apt-get download` (no install) and writes docs/bench_real_parts.md and .csv.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import json
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from built_parts import PARTS, write_built_parts  # noqa: E402
from convert import ROOT, run_one  # noqa: E402

CAD_SUFFIXES = (".step", ".stp", ".iges", ".igs", ".brep", ".brp")


def package_parts(package: str, into: Path) -> list[Path]:
    """The CAD files of a Debian package, each once (by content): its STEP/IGES/BREP files and the .brp B-reps
    inside its FreeCAD documents (.FCStd, zip archives)."""
    subprocess.run(["apt-get", "download", package], cwd=into, check=True, capture_output=True)
    deb = next(into.glob(f"{package}_*.deb"))
    tree = into / "tree"
    subprocess.run(["dpkg-deb", "-x", str(deb), str(tree)], check=True)
    found: dict[str, Path] = {}

    def keep(data: bytes, path: Path) -> None:
        digest = hashlib.sha256(data).hexdigest()
        if digest not in found:
            path.parent.mkdir(parents=True, exist_ok=True)
            if not path.exists():
                path.write_bytes(data)
            found[digest] = path

    for p in sorted(tree.rglob("*")):
        if p.suffix.lower() in CAD_SUFFIXES and p.is_file():
            keep(p.read_bytes(), p)
        elif p.suffix.lower() == ".fcstd" and zipfile.is_zipfile(p):
            with zipfile.ZipFile(p) as z:
                for name in sorted(z.namelist()):
                    if name.lower().endswith(".brp"):
                        keep(z.read(name), into / "fcstd" / p.stem / name)
    return list(found.values())


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--package", default="freecad-common")
    ap.add_argument("--tolerances", default="0.1,0.01")
    ap.add_argument("--timeout", type=float, default=300)
    ap.add_argument("--name", default="bench_real_parts")
    ap.add_argument("--tools", default="amprep,occt-delabella", help="amprep, amprep-quality, occt-delabella (the "
                    "reference every other tool is set beside)")
    ap.add_argument("--from-log", help="write the tables from the JSON lines a run printed (e.g. one stopped early)")
    ap.add_argument("--built", action="store_true", help="the solids of built_parts.py, not a package's files")
    ap.add_argument("--sample", type=int, default=0, help="only this many parts, evenly spaced over the package's "
                    "sorted list (a package of thousands, as kicad-packages3d)")
    ap.add_argument("--rerun", help="run only these of --tools; the others' cells are kept from docs/NAME.csv (a "
                    "change that left their output byte-identical); a cell missing there is run")
    ap.add_argument("--parts", help="with --rerun: a file of part labels (one a line) whose cells of the --rerun tools "
                    "are run; every other part's are kept too (a change that altered only these parts' output)")
    args = ap.parse_args()
    if args.from_log:
        rows = [json.loads(line) for line in Path(args.from_log).read_text().splitlines() if line.startswith("{")]
        write_tables(rows, args, len({r["part"] for r in rows}), complete=False)
        return
    with tempfile.TemporaryDirectory(prefix="amprep-real-") as name:  # the unpacked package: KiCad's is 5.7 GB
        tmp = Path(name)
        parts = write_built_parts(tmp / "built") if args.built else package_parts(args.package, tmp)
        if 0 < args.sample < len(parts):
            parts = [parts[i] for i in np.linspace(0, len(parts) - 1, args.sample).round().astype(int)]
        only = _listed_parts(args)
        kept = _kept_rows(ROOT / "docs" / f"{args.name}.csv", set(args.rerun.split(",")), only) if args.rerun else {}
        rows = []
        for part in parts:
            label = str(part.relative_to(tmp)).replace("tree/usr/share/", "")
            for tol in (float(t) for t in args.tolerances.split(",")):
                for tool in args.tools.split(","):
                    row = kept.get((label, tol, tool))
                    if row is None:
                        row = {"part": label, "tolerance": tol, "tool": tool, **run_one(tool, part, tol, args.timeout)}
                        print(json.dumps(row), flush=True)
                    rows.append(row)
    write_tables(rows, args, len(parts))


def _listed_parts(args: argparse.Namespace) -> set[str] | None:
    """The part labels of the --parts file (one a line), or None without one."""
    return set(Path(args.parts).read_text().splitlines()) - {""} if args.parts else None


def _rerun_note(args: argparse.Namespace) -> str:
    """What the header says of a --rerun: which cells were run again."""
    if not args.rerun:
        return ""
    if not args.parts:
        return f" (then `--rerun {args.rerun}`: the other tools’ cells kept from the run before)"
    n = len(_listed_parts(args) or ())
    return (f" (then `--rerun {args.rerun} --parts`: those tools’ cells of the {n} parts whose output a change altered "
            "run again, every other cell kept from the run before)")


_FLOATS = ("tolerance", "seconds", "deviation_ratio", "angle_regularity", "peak_rss_mb")
_INTS = ("triangles", "boundary", "nonmanifold", "degenerate")


def _kept_rows(path: Path, rerun: set[str], only: set[str] | None = None) -> dict[tuple[str, float, str], dict]:
    """{(part, tolerance, tool): row} of an earlier run's CSV for every tool not in `rerun` (for those, of every
    part not in `only`, when given), each row as run_one's JSON had it (empty fields dropped, numbers and `closed`
    typed)."""
    kept = {}
    with open(path, newline="") as fh:
        for r in csv.DictReader(fh):
            if r["tool"] in rerun and (only is None or r["part"] in only):
                continue
            row = {k: v for k, v in r.items() if v != ""}
            row.update({k: float(row[k]) for k in _FLOATS if k in row})
            row.update({k: int(row[k]) for k in _INTS if k in row})
            if "closed" in row:
                row["closed"] = row["closed"] == "True"
            kept[(row["part"], row["tolerance"], row["tool"])] = row
    return kept


def _summary(rows: list[dict], tool: str) -> dict:
    """Counts over one tool's cells: converted, closed, within tolerance (max dev / tol ≤ 1), errors, and the median
    of the written STLs' mean angle regularity."""
    mine = [r for r in rows if r["tool"] == tool]
    done = [r for r in mine if "seconds" in r]
    angle = sorted(r["angle_regularity"] for r in done if r.get("angle_regularity") is not None)
    return {"cells": len(mine), "converted": len(done), "closed": sum(bool(r.get("closed")) for r in done),
            "within": sum((r.get("deviation_ratio") or 0) <= 1 for r in done),
            "angle": f"{angle[len(angle) // 2]:.2f}" if angle else "",
            "errors": sorted({r.get("error", "") for r in mine if "seconds" not in r})}


REFERENCE = "occt-delabella"


def write_tables(rows: list[dict], args: argparse.Namespace, n_parts: int, complete: bool = True) -> None:
    docs = ROOT / "docs"
    fields = ["part", "tolerance", "tool", "seconds", "triangles", "closed", "boundary", "nonmanifold", "degenerate",
              "deviation_ratio", "angle_regularity", "peak_rss_mb", "error"]
    with open(docs / f"{args.name}.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=fields, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    tools = list(dict.fromkeys(r["tool"] for r in rows))
    cells: dict[tuple[str, float], dict[str, dict]] = {}
    for r in rows:
        cells.setdefault((r["part"], r["tolerance"]), {})[r["tool"]] = r
    source = (f"--built --tolerances {args.tolerances}" if args.built
              else f"--package {args.package} --tolerances {args.tolerances}")
    what = (f"the {len(PARTS)} solids bench/built_parts.py builds with cadquery (threads swept on a helix, engraved "
            "text, twisted and lofted B-splines, a torus thinner than a coarse tolerance, holes smaller than it, a "
            "crescent pinched to a point, a parametric surface), each written as BREP, STEP, IGES solids and IGES "
            "trimmed surfaces" if args.built else
            f"{'an evenly spaced sample of the STEP, IGES and BREP files' if args.sample else 'every STEP, IGES and BREP file'}"
            " the Debian package ships and the B-rep of each FreeCAD document in it, each once by content")
    lines = [f"# {'Solids built here' if args.built else f'Real parts outside the corpus: {args.package}'}", "",
             f"Made by `python bench/real_parts.py {source}"
             f"{'' if args.tools == 'amprep,occt-delabella' else f' --tools {args.tools} --name {args.name}'}"
             f"{f' --sample {args.sample}' if args.sample else ''}`"
             f"{_rerun_note(args)}"
             f": {what} "
             f"({n_parts} {'files' if args.built else 'parts'}{'' if complete else ', those a run stopped early had reached, from its log'}), "
             "converted end to end in a child process per cell by amprep (`amprep-quality`: `--mesher quality`) and by "
             "the bare OCCT pipeline (its reader, BRepMesh Delabella, StlAPI_Writer). `closed`: every edge of the "
             "written STL shared by two triangles, consistently oriented; `within`: worst sampled chordal error ≤ the "
             "tolerance; `angle`: the written STL's mean angle regularity (α_min / 60°), its median over the cells.",
             "", "| tool | cells | converted | closed | within tolerance | median angle regularity | errors |",
             "|---|---|---|---|---|---|---|"]
    for tool in tools:
        s = _summary(rows, tool)
        lines.append(f"| {tool} | {s['cells']} | {s['converted']} | {s['closed']} | {s['within']} | {s['angle']} | "
                     f"{', '.join(e for e in s['errors'] if e) or '—'} |")
    for tool in (t for t in tools if t != REFERENCE):
        both = [(k, c) for k, c in cells.items() if all("seconds" in c.get(t, {}) for t in (tool, REFERENCE))]
        closed_only = sum(bool(c[tool]["closed"]) and not c[REFERENCE]["closed"] for _, c in both)
        ratio = sorted(c[tool]["triangles"] / c[REFERENCE]["triangles"] for _, c in both if c[REFERENCE]["triangles"])
        if ratio:
            lines += ["", f"`{tool}`: cells closed by it and open from OCCT: {closed_only} of {len(both)}. Triangles "
                      f"{tool} / OCCT: median {ratio[len(ratio) // 2]:.2f}, range {ratio[0]:.2f}–{ratio[-1]:.2f}."]
        open_for_us = [(k, c) for k, c in both if not c[tool]["closed"]]
        if open_for_us:
            lines += ["", f"Open from `{tool}` (`amprep convert` says why in its notes: surfaces that stay open once "
                      "sewn, or faces it could not mesh; non-manifold edges where solids of an assembly touch, or "
                      "where the B-rep's own edge bounds more than two faces):", ""]
            lines += [f"- {k[0]} at {k[1]:g} mm: {c[tool]['boundary']} boundary, {c[tool]['nonmanifold']} non-manifold "
                      f"edges (OCCT: {c[REFERENCE]['boundary']} boundary, {c[REFERENCE]['nonmanifold']} non-manifold)"
                      for k, c in open_for_us]
    lines += ["", "| part | tol mm | tool | s | triangles | closed | boundary | non-manifold | degenerate | "
              "max dev / tol | angle |", "|" + "---|" * 11]
    for r in rows:
        if "seconds" not in r:
            lines.append(f"| {r['part']} | {r['tolerance']:g} | {r['tool']} | {r.get('error', '')} |||||||")
            continue
        dev, angle = r.get("deviation_ratio"), r.get("angle_regularity")
        lines.append(f"| {r['part']} | {r['tolerance']:g} | {r['tool']} | {r['seconds']:.2f} | {r['triangles']:,} | "
                     f"{'yes' if r['closed'] else 'no'} | {r['boundary']} | {r['nonmanifold']} | {r['degenerate']} | "
                     f"{'' if dev is None else format(dev, '.2f')} | {'' if angle is None else format(angle, '.2f')} |")
    (docs / f"{args.name}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines[:14]))


if __name__ == "__main__":
    main()
