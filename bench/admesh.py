"""STL checks beside admesh: what each finds in the same STL files, and how long each takes.

admesh (Debian's `admesh`, C) is the classic STL checker and repairer. It matches facet edges exactly (`-e`),
then by distance (`-n`), removes unconnected facets, fills holes, and makes the normals agree. amprep never
merges or repairs by distance: its checks identify an edge by its two vertex indices (identical coordinates are one
vertex), and it reports boundary, non-manifold and misoriented edges, shells, volume, degenerate and duplicate
triangles (core/checks.py). Its `analyze` also runs manifold3d, the self-intersection test, regularity and cusp
height.

Inputs: the corpus's STL files; amprep's own STL of NIST CTC-02 at 0.01 mm; that STL with planted defects whose
counts are known (triangles removed and flipped, none sharing a vertex); its quality mesh at 0.01 mm; and the
counter refined twice by Butterfly. Every cell runs in its own child process (wall seconds, peak RSS by wait4).

    python bench/admesh.py                  # writes docs/bench_admesh.md and .csv
    python bench/admesh.py --quick          # the corpus STLs and the planted defects only
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from convert import CORPUS, ROOT, wait_child  # noqa: E402  (stdlib only at import: this process stays small)

sys.path.insert(0, str(ROOT))
CORPUS_STLS = ["featuretype_inch.stl", "voron_hotend_mount_dragon.stl", "voron_vhb_din_mount.stl", "counter_83k.stl",
               "adis16480_metres.stl", "voron_rear_skirt_nonmanifold.stl", "triangle_soup.stl"]
#: defects planted in CTC-02's STL: triangles removed (3 boundary edges each) and flipped (3 misoriented edges each)
REMOVED, FLIPPED = 5, 7


# ----------------------------------------------------------------------------------------- inputs
def _ctc02(tmp: Path, mesher: str) -> Path:
    from amprep.geometry.cad.read import read_cad
    from amprep.geometry.io.stl import write_stl
    from amprep.geometry.meshing.params import MeshParams
    from amprep.geometry.meshing.pipeline import mesh_model

    out = tmp / f"ctc02_{mesher}_0.01.stl"
    mesh = mesh_model(read_cad(CORPUS / "nist_ctc02_ap242.stp"), MeshParams(tolerance=0.01, mesher=mesher)).mesh
    write_stl(mesh, out)
    return out


def planted(src: Path, out: Path, seed: int = 0) -> dict[str, int]:
    """Write src's STL with REMOVED triangles left out and FLIPPED ones reversed, no two of them sharing a vertex (so
    each adds exactly 3 boundary or 3 misoriented edges); the counts a correct checker must find."""
    import numpy as np

    from amprep.geometry.core.mesh import Mesh
    from amprep.geometry.io.stl import read_stl, write_stl

    mesh = read_stl(src)
    tris = np.array(mesh.triangles)
    used = np.zeros(mesh.n_vertices, bool)
    chosen: list[int] = []
    for i in np.random.default_rng(seed).permutation(len(tris)):
        if not used[tris[i]].any():
            chosen.append(int(i))
            used[tris[i]] = True
        if len(chosen) == REMOVED + FLIPPED:
            break
    gone, flip = chosen[:REMOVED], chosen[REMOVED:]
    tris[flip] = tris[flip][:, ::-1]
    write_stl(Mesh.from_arrays(np.asarray(mesh.vertices), np.delete(tris, gone, axis=0)), out)
    return {"boundary_edges": 3 * REMOVED, "misoriented_edges": 3 * FLIPPED}


def _butterfly(tmp: Path) -> Path:
    from amprep.geometry.io.stl import read_stl, write_stl
    from amprep.geometry.refine.butterfly import ButterflyParams, butterfly_refine

    out = tmp / "counter_butterfly_2.stl"
    write_stl(butterfly_refine(read_stl(CORPUS / "counter_83k.stl"), ButterflyParams(levels=2)).mesh, out)
    return out


def make_inputs(tmp: Path, quick: bool) -> None:
    """Print [label, STL, the planted counts or None] of every input as JSON, the generated ones written in tmp (in a
    child process: the parent stays small, so its children's peak RSS is their own, not a fork's copy of it)."""
    rows: list[tuple[str, str, dict[str, int] | None]] = [(n, str(CORPUS / n), None) for n in CORPUS_STLS]
    ctc = _ctc02(tmp, "occt")
    rows.append(("ctc02 amprep 0.01 mm", str(ctc), None))
    rows.append(("ctc02 planted defects", str(tmp / "planted.stl"), planted(ctc, tmp / "planted.stl")))
    if not quick:
        rows.append(("ctc02 amprep quality 0.01 mm", str(_ctc02(tmp, "quality")), None))
        rows.append(("counter butterfly ×2", str(_butterfly(tmp)), None))
    print(json.dumps(rows))


# ----------------------------------------------------------------------------------------- child side
def child(path: str) -> None:
    """Print amprep's checks of one STL (read, check_mesh, the whole analysis), each stage timed, as JSON."""
    from amprep.geometry.core.checks import check_mesh
    from amprep.geometry.io.stl import read_stl
    from amprep.geometry.measure.analysis import analyze_mesh

    t0 = time.perf_counter()
    mesh = read_stl(path)
    t1 = time.perf_counter()
    c = check_mesh(mesh)
    t2 = time.perf_counter()
    a = analyze_mesh(mesh)
    t3 = time.perf_counter()
    print(json.dumps({"read_s": t1 - t0, "check_s": t2 - t1, "analyze_s": t3 - t2, "triangles": c.triangles,
                      "boundary_edges": c.boundary_edges, "nonmanifold_edges": c.nonmanifold_edges,
                      "misoriented_edges": c.misoriented_edges, "shells": c.shells, "volume": c.volume,
                      "degenerate": c.degenerate_triangles, "duplicates": c.duplicate_triangles,
                      "manifold3d": a.mesh_section.to_json().get("manifold3d")}))


# ----------------------------------------------------------------------------------------- parent side
def timed(cmd: list[str], timeout: float) -> tuple[str, float, float]:
    """(stdout, wall seconds, peak RSS MB) of a child process."""
    with tempfile.TemporaryFile("w+") as sink:
        proc = subprocess.Popen(cmd, stdout=sink, stderr=subprocess.DEVNULL, text=True,
                                env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})
        ended = wait_child(proc, timeout, poll=0.01)
        if ended is None:
            return "", float("nan"), float("nan")
        _, usage, wall = ended
        sink.seek(0)
        return sink.read(), wall, usage.ru_maxrss / 1024  # type: ignore[attr-defined]


_STAT = {"facets": r"Number of facets\s*:\s*(\d+)", "one": r"1 disconnected edge\s*:\s*(\d+)",
         "two": r"2 disconnected edges\s*:\s*(\d+)", "three": r"3 disconnected edges\s*:\s*(\d+)",
         "parts": r"Number of parts\s*:\s*(\d+)", "volume": r"Volume\s*:\s*(-?[\d.]+)",
         "degenerate": r"Degenerate facets\s*:\s*(\d+)", "edges_fixed": r"Edges fixed\s*:\s*(\d+)",
         "removed": r"Facets removed\s*:\s*(\d+)", "added": r"Facets added\s*:\s*(\d+)",
         "reversed": r"Facets reversed\s*:\s*(\d+)", "backwards": r"Backwards edges\s*:\s*(\d+)"}


def admesh_stats(text: str) -> dict[str, float]:
    """admesh's results block: the first (original) column of each statistic it prints."""
    out = {}
    for key, pattern in _STAT.items():
        m = re.search(pattern, text)
        if m:
            out[key] = float(m.group(1))
    if {"one", "two", "three"} <= out.keys():
        out["disconnected_edges"] = out["one"] + 2 * out["two"] + 3 * out["three"]
    return out


def run(label: str, path: Path, expect: dict[str, int] | None, timeout: float) -> dict:
    """One input: admesh -e -d (exact matching and normal directions: the checks alone), admesh with no option (all its
    checks and repairs, written to /dev/null), and amprep's child."""
    exe = shutil.which("admesh")
    row: dict = {"input": label, "planted": json.dumps(expect) if expect else ""}
    if exe:
        text, row["admesh_check_s"], row["admesh_check_mb"] = timed([exe, "-e", "-d", str(path)], timeout)
        row |= {f"admesh_{k}": v for k, v in admesh_stats(text).items()}
        text, row["admesh_repair_s"], row["admesh_repair_mb"] = timed([exe, str(path), "-b", os.devnull], timeout)
        repair = admesh_stats(text)
        row |= {f"admesh_repair_{k}": repair.get(k, 0) for k in ("edges_fixed", "removed", "added", "reversed")}
    text, row["amprep_s"], row["amprep_mb"] = timed([sys.executable, __file__, "--child", str(path)], timeout)
    try:
        row |= {f"amprep_{k}": v for k, v in json.loads(text.strip().splitlines()[-1]).items()}
    except (ValueError, IndexError):
        row["amprep_error"] = "failed"
    return row


def _f(v: object, fmt: str = "{:,.0f}") -> str:
    return "–" if v is None or (isinstance(v, float) and not math.isfinite(v)) else fmt.format(v)


def table(rows: list[dict]) -> str:
    """The two markdown tables: what each tool finds, and the seconds and memory."""
    out = ["| input | triangles | open edges: admesh / amprep | non-manifold edges (amprep) | misoriented: admesh "
           "backwards edges / facets reversed; amprep edges | parts / shells | volume mm³: admesh / amprep | "
           "degenerate: admesh / amprep | duplicates (amprep) | manifold3d | planted |",
           "|---|---:|---|---:|---|---|---|---|---:|---|---|"]
    for r in rows:
        out.append(
            f"| {r['input']} | {_f(r.get('amprep_triangles'))} | {_f(r.get('admesh_disconnected_edges'))} / "
            f"{_f(r.get('amprep_boundary_edges'))} | {_f(r.get('amprep_nonmanifold_edges'))} | "
            f"{_f(r.get('admesh_backwards'))} / {_f(r.get('admesh_reversed'))}; {_f(r.get('amprep_misoriented_edges'))} | "
            f"{_f(r.get('admesh_parts'))} / {_f(r.get('amprep_shells'))} | {_f(r.get('admesh_volume'), '{:,.6g}')} / "
            f"{_f(r.get('amprep_volume'), '{:,.6g}')} | {_f(r.get('admesh_degenerate'))} / {_f(r.get('amprep_degenerate'))} | "
            f"{_f(r.get('amprep_duplicates'))} | {r.get('amprep_manifold3d', '–')} | {r['planted'] or ''} |")
    out += ["", "| input | triangles | admesh -e -d s | admesh repair s | amprep read s | amprep checks s | "
            "amprep analyze s | amprep process s | checks ×admesh -e -d | peak MB: admesh / amprep |",
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---|"]
    for r in rows:
        ours = (r.get("amprep_read_s") or math.nan) + (r.get("amprep_check_s") or math.nan)
        ratio = ours / r["admesh_check_s"] if r.get("admesh_check_s") else math.nan
        out.append(
            f"| {r['input']} | {_f(r.get('amprep_triangles'))} | {_f(r.get('admesh_check_s'), '{:.3f}')} | "
            f"{_f(r.get('admesh_repair_s'), '{:.3f}')} | {_f(r.get('amprep_read_s'), '{:.3f}')} | "
            f"{_f(r.get('amprep_check_s'), '{:.3f}')} | {_f(r.get('amprep_analyze_s'), '{:.2f}')} | "
            f"{_f(r.get('amprep_s'), '{:.2f}')} | {_f(ratio, '{:.2f}')} | {_f(r.get('admesh_check_mb'))} / "
            f"{_f(r.get('amprep_mb'))} |")
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--child")
    ap.add_argument("--make")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--timeout", type=float, default=600)
    ap.add_argument("--name", default="bench_admesh")
    args = ap.parse_args()
    if args.child:
        child(args.child)
        return
    if args.make:
        make_inputs(Path(args.make), args.quick)
        return
    if not shutil.which("admesh"):
        print("admesh is not installed (Debian: apt-get install admesh): amprep's columns only", file=sys.stderr)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        made = subprocess.run([sys.executable, __file__, "--make", tmp] + ["--quick"] * args.quick, check=True,
                              capture_output=True, text=True).stdout
        for label, path, expect in json.loads(made.strip().splitlines()[-1]):
            rows.append(run(label, Path(path), expect, args.timeout))
            print(json.dumps(rows[-1]), flush=True)
    text = table(rows)
    print(text)
    docs = ROOT / "docs"
    keys = sorted({k for r in rows for k in r})
    with open(docs / f"{args.name}.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)
    write_md(docs / f"{args.name}.md", text, args.quick)


HEADER = """# STL checks beside admesh

Made by `python bench/admesh.py{quick}` (bench/admesh.py says how). Each cell in its own process: `admesh -e -d`
matches facet edges exactly and makes the normals agree (its checks without the nearby merge and hole filling);
`admesh` with no option runs every check and repair (written to /dev/null); amprep's child reads the STL
(`read_stl`: identical coordinates are one vertex), runs `check_mesh` (edge incidence by index, shells, volume,
degenerate and duplicate triangles) and then the whole `analyze_mesh` report (manifold3d, self-intersections,
defect locations, regularity, cusp height by both methods). `open edges`: admesh's disconnected facet edges
(1 × facets with one + 2 × with two + 3 × with three), amprep's boundary edges. `checks ×admesh -e -d`: amprep's
read + checks over admesh's whole process. admesh's peak RSS has a floor of ~15 MB, the forked bench process before
it runs admesh. Its volume is summed in float32.
"""


def write_md(path: Path, text: str, quick: bool) -> None:
    path.write_text(HEADER.format(quick=" --quick" if quick else "") + "\n" + text + "\n")


if __name__ == "__main__":
    main()
