"""Analysis benchmark: exact-surface evaluation against OCCT's own evaluator, and the analysis of a large mesh.

1. Surface points per second, per surface type, of amprep's vectorised evaluators (closed forms, rational
   B-splines from poles/weights/knots) against a Python loop over OCCT's BRepAdaptor_Surface.D0, with the
   largest difference relative to the part's size (target ≥ 5 M points/s on one core, agreement 1e-9).
2. The whole analysis (`analyze_mesh`: checks, chordal error, cusp height by both methods, cylindricity,
   regularity, self-intersections) of NIST CTC-02's tessellations up to ~1 M triangles, each in its own process
   (time of the analysis alone, and the process's peak memory; target < 60 s and < 4 GB for 1 M triangles).

    python bench/analysis.py            # writes docs/bench_analysis.md and .csv
    python bench/analysis.py --quick    # evaluation only, and CTC-02 at 0.1 mm
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
CORPUS = Path(os.environ.get("AMPREP_CORPUS", ROOT.parent / "shared" / "corpus"))
N_OURS = 2_000_000
N_OCCT = 50_000


# ------------------------------------------------------------------------------------------ evaluation
def _faces_by_type() -> dict[str, tuple[str, object]]:
    """One face per surface type: analytic faces from cadquery solids, the largest B-spline face of CTC-02's twin."""
    import cadquery as cq

    from amprep.geometry.cad.read import read_cad
    from amprep.geometry.cad.surfaces import surface_of

    solids = {
        "plane": cq.Workplane().box(30, 20, 10),
        "cylinder": cq.Workplane().cylinder(20, 8),
        "cone": cq.Workplane().add(cq.Solid.makeCone(10, 3, 15)),
        "sphere": cq.Workplane().sphere(12),
        "torus": cq.Workplane().add(cq.Solid.makeTorus(20, 5)),
    }
    out: dict[str, tuple[str, object]] = {}
    for kind, wp in solids.items():
        for f in wp.val().Faces():
            if surface_of(f.wrapped).surface_type == kind:
                out[kind] = (f"cadquery {kind}", f.wrapped)
                break
    model = read_cad(CORPUS / "nist_ctc02_bspline_ap203.stp")
    best, area = None, -1.0
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps

    for f in model.faces:
        if surface_of(f).surface_type != "bspline":
            continue
        g = GProp_GProps()
        BRepGProp.SurfaceProperties_s(f, g)
        if g.Mass() > area:
            best, area = f, g.Mass()
    out["bspline"] = ("CTC-02 twin, largest B-spline face", best)
    return out


def evaluation_rows() -> list[dict]:
    from OCP.BRepAdaptor import BRepAdaptor_Surface
    from OCP.gp import gp_Pnt

    from amprep.geometry.cad.surfaces import surface_of

    rows = []
    rng = np.random.default_rng(1)
    for kind, (label, face) in _faces_by_type().items():
        surf = surface_of(face)
        u1, u2, v1, v2 = surf.bounds
        uv = np.column_stack([rng.uniform(u1, u2, N_OURS), rng.uniform(v1, v2, N_OURS)])
        surf.evaluate(uv[:200_000])  # warm-up (numba compile for B-splines)
        t0 = time.perf_counter()
        ours = surf.evaluate(uv)
        t_ours = time.perf_counter() - t0
        ad = BRepAdaptor_Surface(face, True)
        p = gp_Pnt()
        ref = np.empty((N_OCCT, 3))
        t0 = time.perf_counter()
        for i, (u, v) in enumerate(uv[:N_OCCT]):
            ad.D0(u, v, p)
            ref[i] = p.X(), p.Y(), p.Z()
        t_occt = time.perf_counter() - t0
        scale = float(np.ptp(ref, axis=0).max()) or 1.0
        rel = float(np.abs(ours[:N_OCCT] - ref).max() / scale)
        rows.append(dict(surface=kind, face=label, ours_mps=N_OURS / t_ours / 1e6, occt_mps=N_OCCT / t_occt / 1e6,
                         ratio=(N_OURS / t_ours) / (N_OCCT / t_occt), max_rel_diff=rel))
        r = rows[-1]
        print(f"{kind:9s} ours {r['ours_mps']:7.2f} M/s  OCCT D0 loop {r['occt_mps']:5.3f} M/s  "
              f"×{r['ratio']:7.1f}  max diff / size {rel:.1e}", flush=True)
    return rows


# ------------------------------------------------------------------------------------------ large analysis
def _child(path: str, tol: float, box: bool) -> None:
    from amprep.geometry.cad.read import read_cad
    from amprep.geometry.cad.surfaces import surface_of
    from amprep.geometry.measure.analysis import AnalysisParams, analyze_mesh
    from amprep.geometry.meshing.params import MeshParams
    from amprep.geometry.meshing.pipeline import mesh_model

    model = read_cad(path)
    t0 = time.perf_counter()
    res = mesh_model(model, MeshParams(tolerance=tol))
    t_mesh = time.perf_counter() - t0
    surfaces = {i: surface_of(f) for i, f in enumerate(model.faces)}
    stages: dict[str, float] = {}
    last = [time.perf_counter(), "start"]

    def progress(stage: str, fraction: float) -> None:
        now = time.perf_counter()
        if stage != last[1]:
            stages[last[1]] = stages.get(last[1], 0.0) + now - last[0]
            last[:] = [now, stage]

    t0 = time.perf_counter()
    a = analyze_mesh(res.mesh, AnalysisParams(bounding_box=box), surfaces, len(model.faces), {}, res.tolerance,
                     progress=progress)
    t_an = time.perf_counter() - t0
    stages[last[1]] = stages.get(last[1], 0.0) + time.perf_counter() - last[0]
    hwm = 0
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM"):
            hwm = int(line.split()[1]) * 1024
    print(json.dumps(dict(triangles=res.mesh.n_triangles, mesh_s=t_mesh, analysis_s=t_an, peak_bytes=hwm,
                          watertight=a.report["mesh"]["watertight"], stages=stages)))


def large_rows(cases: list[tuple[str, float, bool]]) -> list[dict]:
    rows = []
    for name, tol, box in cases:
        out = subprocess.run([sys.executable, __file__, "--child", str(CORPUS / name), str(tol), str(int(box))],
                             capture_output=True, text=True, cwd=ROOT)
        if out.returncode != 0:
            print(out.stderr[-2000:], file=sys.stderr)
            continue
        r = json.loads(out.stdout.strip().splitlines()[-1])
        r.update(part=name, tolerance=tol, box=box)
        rows.append(r)
        slow = ", ".join(f"{k} {v:.1f}" for k, v in sorted(r["stages"].items(), key=lambda kv: -kv[1])[:4])
        print(f"{name} @ {tol} box={box}: {r['triangles']:,} triangles, analysis {r['analysis_s']:.1f} s "
              f"(meshing {r['mesh_s']:.1f} s), peak {r['peak_bytes'] / 2**30:.2f} GB  [{slow}]", flush=True)
    return rows


def write(ev: list[dict], large: list[dict]) -> None:
    docs = ROOT / "docs"
    with open(docs / "bench_analysis.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["table", "case", "value1", "value2", "value3", "value4"])
        for r in ev:
            w.writerow(["evaluation", r["surface"], f"{r['ours_mps']:.3f}", f"{r['occt_mps']:.4f}", f"{r['ratio']:.1f}",
                        f"{r['max_rel_diff']:.2e}"])
        for r in large:
            w.writerow(["analysis", f"{r['part']}@{r['tolerance']}/box={r['box']}", r["triangles"],
                        f"{r['analysis_s']:.2f}", f"{r['mesh_s']:.2f}", r["peak_bytes"]])
    lines = ["# Analysis benchmark", "", "Generated by `python bench/analysis.py` on the 2-core VM, one process per "
             "measurement.", "", "## Exact-surface evaluation (one core)", "",
             f"amprep evaluates {N_OURS:,} random (u,v) in the face's bounds in one call; OCCT's "
             f"`BRepAdaptor_Surface.D0` is called in a Python loop on the first {N_OCCT:,} of them (the way a Python "
             "service would reach OCCT's evaluator). Difference: the largest distance between the two points, divided "
             "by the size of the evaluated patch.", "",
             "| surface | face | amprep (M points/s) | OCCT D0 loop (M points/s) | ratio | max difference / size |",
             "|---|---|---:|---:|---:|---:|"]
    for r in ev:
        lines.append(f"| {r['surface']} | {r['face']} | {r['ours_mps']:.2f} | {r['occt_mps']:.3f} | {r['ratio']:.0f}× "
                     f"| {r['max_rel_diff']:.1e} |")
    lines += ["", "## Analysis of large meshes", "",
              "`analyze_mesh` on amprep's tessellation of the corpus's NIST CTC-02 (meshing not included in the "
              "analysis time; peak memory is the whole process, meshing included). Stages: the four slowest.", "",
              "| part | tolerance (mm) | box method | triangles | analysis (s) | meshing (s) | peak memory (GB) | slowest stages (s) |",
              "|---|---:|---|---:|---:|---:|---:|---|"]
    for r in large:
        slow = ", ".join(f"{k} {v:.1f}" for k, v in sorted(r["stages"].items(), key=lambda kv: -kv[1])[:4])
        lines.append(f"| {r['part']} | {r['tolerance']} | {'yes' if r['box'] else 'no'} | {r['triangles']:,} | "
                     f"{r['analysis_s']:.1f} | {r['mesh_s']:.1f} | {r['peak_bytes'] / 2**30:.2f} | {slow} |")
    (docs / "bench_analysis.md").write_text("\n".join(lines) + "\n")
    print("wrote docs/bench_analysis.md")


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        _child(sys.argv[2], float(sys.argv[3]), bool(int(sys.argv[4])))
        return
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    ev = evaluation_rows()
    if args.quick:
        cases = [("nist_ctc02_ap242.stp", 0.1, True)]
    else:
        cases = [("nist_ctc02_ap242.stp", 0.1, True), ("nist_ctc02_ap242.stp", 0.01, True),
                 ("nist_ctc02_bspline_ap203.stp", 0.01, True), ("nist_ctc02_bspline_ap203.stp", 0.005, False),
                 ("nist_ctc02_bspline_ap203.stp", 0.005, True)]
    write(ev, large_rows(cases))


if __name__ == "__main__":
    main()
