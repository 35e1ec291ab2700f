"""Hash what the CLI writes for the corpus (STL bytes, report JSON without provenance) to show that a change left
every output bit for bit the same: `--write FILE` records the hashes, `--check FILE` compares and lists the
differences. Runs the CLI in subprocesses, so it works across any internal reorganisation."""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import re
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

CORPUS = Path(os.environ.get("AMPREP_CORPUS", Path(__file__).resolve().parents[2] / "shared" / "corpus"))
CAD = ["as1_assembly_ap214.stp", "bspline_45_faces.iges", "cq_cube_cylinder_colors.step", "dtmb5415_bow_hull.iges",
       "featuretype_inch_ap214.step", "nist_ctc02_ap242.stp", "nist_ctc02_bspline_ap203.stp",
       "nist_ftc08_tessellated_ap242.stp", "occt_top_invalid.brep", "sunglasses_lens_inch.igs",
       "voron_hotend_mount_dragon.step", "voron_vhb_din_mount.step"]
FINE = ["as1_assembly_ap214.stp", "cq_cube_cylinder_colors.step", "featuretype_inch_ap214.step",
        "voron_hotend_mount_dragon.step", "voron_vhb_din_mount.step", "nist_ctc02_ap242.stp"]
STL = ["voron_vhb_din_mount.stl", "triangle_soup.stl"]

# (label, CLI arguments after `amprep`, output names whose bytes are hashed); {i} input, {o} output dir
CASES: list[tuple[str, list[str], list[str]]] = (
    [(f"convert {f} 0.1", ["convert", "{i}" + f, "-o", "{o}part.stl", "--tolerance", "0.1"], ["part.stl"]) for f in CAD]
    + [(f"convert {f} 0.01", ["convert", "{i}" + f, "-o", "{o}part.stl", "--tolerance", "0.01"], ["part.stl"])
       for f in FINE]
    + [("convert as1 3mf", ["convert", "{i}as1_assembly_ap214.stp", "-o", "{o}part.3mf"], ["part.3mf"]),
       ("convert din ascii", ["convert", "{i}voron_vhb_din_mount.step", "-o", "{o}part.stl", "--ascii"], ["part.stl"])]
    + [(f"convert {f}", ["convert", "{i}" + f, "-o", "{o}part.stl"], ["part.stl"]) for f in STL]
    + [(f"analyze {f}", ["analyze", "{i}" + f, "--report", "{o}report.json"], ["report.json"])
       for f in ["voron_vhb_din_mount.step", "featuretype_inch_ap214.step", "voron_vhb_din_mount.stl"]]
    + [("analyze din with its stl", ["analyze", "{i}voron_vhb_din_mount.step", "--stl", "{i}voron_vhb_din_mount.stl",
                                     "--report", "{o}report.json"], ["report.json"])]
    + [(f"refine din {m}", ["refine", "{i}voron_vhb_din_mount.step", "-o", "{o}refined.stl", "--method", m,
                            "--report", "{o}report.json"], ["refined.stl", "report.json"])
       for m in ("sma", "vta", "adaptive")]
    + [("refine din stl", ["refine", "{i}voron_vhb_din_mount.step", "--stl", "{i}voron_vhb_din_mount.stl", "-o",
                           "{o}refined.stl", "--report", "{o}report.json", "--no-compare"], ["refined.stl", "report.json"])]
)


def _digest(path: Path) -> str:
    if path.suffix == ".json":
        data = json.loads(path.read_text())
        data.pop("provenance", None)
        return hashlib.sha256(json.dumps(data, sort_keys=True, default=str).encode()).hexdigest()
    if path.suffix == ".3mf":  # a zip: its entries' contents without the UUIDs, not the archive's timestamps
        h = hashlib.sha256()
        with zipfile.ZipFile(path) as z:
            for name in sorted(z.namelist()):
                h.update(name.encode() + re.sub(rb'UUID="[^"]*"', b"", z.read(name)))
        return h.hexdigest()
    return hashlib.sha256(path.read_bytes()).hexdigest()


#: load the compiled chordal kernels before the CLI runs: every measure then uses them, whatever the timing
PRELOAD = """import sys
try:
    from amprep.geometry.measure.chordal import load_kernels
except ImportError:
    from amprep.geometry.chordal import load_kernels
load_kernels()
from amprep.cli import main
sys.exit(main(sys.argv[1:]))
"""


def run_all(only: str | None, compiled: bool = False) -> dict[str, list[str]]:
    out: dict[str, list[str]] = {}
    for label, args, names in CASES:
        if only and only not in label:
            continue
        with tempfile.TemporaryDirectory() as d:
            argv = [a.replace("{i}", f"{CORPUS}/").replace("{o}", f"{d}/") for a in args]
            cmd = [sys.executable, "-c", PRELOAD, *argv, "--quiet"] if compiled else [sys.executable, "-m", "amprep", *argv, "--quiet"]
            p = subprocess.run(cmd, capture_output=True, text=True)
            out[label] = ([_digest(Path(d) / n) for n in names] if p.returncode == 0
                          else [f"exit {p.returncode}: {p.stderr.strip()[-200:]}"])
        print(f"{label}: {out[label][0][:16]}", flush=True)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    g = ap.add_mutually_exclusive_group(required=True)
    g.add_argument("--write", type=Path)
    g.add_argument("--check", type=Path)
    ap.add_argument("--only", help="run the cases whose label contains this")
    ap.add_argument("--compiled", action="store_true", help="load the compiled kernels first (no timing-dependent "
                    "choice between numpy's and numba's evaluation)")
    args = ap.parse_args()
    got = run_all(args.only, args.compiled)
    if args.write:
        args.write.write_text(json.dumps(got, indent=1))
        return 0
    want = json.loads(args.check.read_text())
    diff = [k for k in got if want.get(k) != got[k]]
    for k in diff:
        print(f"DIFFERS: {k}: {want.get(k)} -> {got[k]}")
    print(f"{len(got) - len(diff)} same, {len(diff)} different")
    return 1 if diff else 0


if __name__ == "__main__":
    sys.exit(main())
