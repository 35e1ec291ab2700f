"""Conversion benchmark: amprep vs the bare OCCT pipeline (both mesh algorithms), cascadio and gmsh.

Every measurement runs in its own child process (its own peak RSS, VmHWM), end to end, file in → STL out.
Prints a table and writes docs/bench_convert.md and docs/bench_convert.csv.

    python bench/convert.py                   # test parts at 0.1/0.01/0.001, corpus at 0.1/0.01 (+0.001 if small)
    python bench/convert.py --quick           # 0.1 and 0.01 on the test parts and the small corpus parts
    python bench/convert.py --acis --tools amprep,amprep-quality --name bench_convert_acis   # the ACIS corpus, amprep only
    python bench/convert.py --tools amprep,amprep-quality,occt-delabella,occt-watson --only torus_R20,sphere_r12 \
        --tolerances 0.01,0.001 --name bench_convert_quality     # the quality mesher beside the default and OCCT
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CORPUS = Path(os.environ.get("AMPREP_CORPUS", ROOT.parent / "shared" / "corpus"))
TOOLS = ["amprep", "occt-delabella", "occt-watson", "cascadio", "gmsh"]
SMALL_DIAG = 120.0  # mm: parts this small also run at 0.001 mm


# ----------------------------------------------------------------------------------------- child side
def _occt_read(path: str):
    """The bare OCCT read: the format's reader with its default shape healing, lengths in mm (no amprep code)."""
    from OCP.BinTools import BinTools
    from OCP.BRep import BRep_Builder
    from OCP.BRepTools import BRepTools
    from OCP.IGESControl import IGESControl_Reader
    from OCP.Interface import Interface_Static
    from OCP.STEPControl import STEPControl_Reader
    from OCP.TopoDS import TopoDS_Shape

    head = Path(path).read_bytes()[:80].lstrip()
    if head.startswith(b"Open CASCADE Topology"):
        shape = TopoDS_Shape()
        BinTools.Read_s(shape, path)
        return shape
    if head.startswith((b"DBRep_DrawableShape", b"CASCADE Topology")):
        shape = TopoDS_Shape()
        BRepTools.Read_s(shape, path, BRep_Builder())
        return shape
    Interface_Static.SetCVal_s("xstep.cascade.unit", "MM")
    reader = STEPControl_Reader() if head.startswith(b"ISO-10303-21") else IGESControl_Reader()
    reader.ReadFile(path)
    reader.TransferRoots()
    return reader.OneShape()


def _mesh_checks(stl: str) -> dict:
    from amprep.geometry.core.checks import check_mesh
    from amprep.geometry.io.stl import read_stl
    from amprep.geometry.measure.regularity import regularity

    mesh = read_stl(stl)
    c = check_mesh(mesh)
    angle = regularity(mesh.corners)["angle"] if mesh.n_triangles else None
    return dict(triangles=c.triangles, boundary=c.boundary_edges, nonmanifold=c.nonmanifold_edges,
                degenerate=c.degenerate_triangles, closed=c.closed,
                angle_regularity=None if angle is None else float(angle.mean()))


def _occt_deviation(shape, tol: float) -> float:
    """Worst chordal error / tolerance of OCCT's own per-face triangulations (as StlAPI_Writer exports them)."""
    import numpy as np
    from OCP.BRep import BRep_Tool
    from OCP.TopAbs import TopAbs_REVERSED
    from OCP.TopLoc import TopLoc_Location

    from amprep.geometry.cad.read import model_from_shape
    from amprep.geometry.cad.surfaces import surface_of
    from amprep.geometry.cad.topology import apply_trsf, trsf_matrix
    from amprep.geometry.measure.chordal import triangle_chordal_error
    from amprep.geometry.meshing.occt_read import triangulation_arrays

    worst = 0.0
    for face in model_from_shape(shape).faces:
        loc = TopLoc_Location()
        tri = BRep_Tool.Triangulation_s(face, loc)
        if tri is None or BRep_Tool.Surface_s(face) is None:
            continue
        nodes, uv, tris = triangulation_arrays(tri)
        if uv is None or len(tris) == 0:
            continue
        if face.Orientation() == TopAbs_REVERSED:
            tris = tris[:, [0, 2, 1]]
        nodes = apply_trsf(trsf_matrix(loc), nodes)
        err = triangle_chordal_error(nodes[tris], uv[tris], surface_of(face).evaluate)
        worst = max(worst, float(np.max(err, initial=0)))
    return worst / tol


def child(tool: str, path: str, tol: float, out: str) -> dict:
    res: dict = {}
    if tool in ("amprep", "amprep-quality"):
        from amprep.geometry.cad.read import read_cad
        from amprep.geometry.measure.chordal import warm_kernels
        from amprep.geometry.meshing.params import MeshParams
        from amprep.geometry.meshing.pipeline import mesh_model
        from amprep.jobs.convert import convert, write_result

        warm_kernels()  # loaded and dispatched once, as in a worker that has run a job, before the clock
        params = MeshParams(tolerance=tol, mesher="quality" if tool == "amprep-quality" else "occt")
        t = time.perf_counter()
        r = convert(path, params)
        write_result(r, out)
        res["seconds"] = time.perf_counter() - t
        res["deviation_ratio"] = r.meshing.max_error / tol if r.meshing else None
        if r.meshing:  # the read and the meshing alone, once more in this process, to set beside OCCT's
            t = time.perf_counter()
            model = read_cad(path)
            t_mesh = time.perf_counter()
            mesh_model(model, params)
            res["read_seconds"], res["mesh_seconds"] = t_mesh - t, time.perf_counter() - t_mesh
    elif tool.startswith("occt-"):
        from OCP.BRepMesh import BRepMesh_IncrementalMesh
        from OCP.BRepTools import BRepTools
        from OCP.IMeshTools import (
            IMeshTools_MeshAlgoType_Delabella,
            IMeshTools_MeshAlgoType_Watson,
            IMeshTools_Parameters,
        )
        from OCP.StlAPI import StlAPI_Writer

        t = time.perf_counter()
        shape = _occt_read(path)
        res["read_seconds"] = time.perf_counter() - t
        BRepTools.Clean_s(shape)
        p = IMeshTools_Parameters()
        p.Deflection, p.Angle, p.InParallel = tol, 0.5, True
        p.MeshAlgo = IMeshTools_MeshAlgoType_Delabella if tool == "occt-delabella" else IMeshTools_MeshAlgoType_Watson
        t_mesh = time.perf_counter()
        BRepMesh_IncrementalMesh(shape, p)
        res["mesh_seconds"] = time.perf_counter() - t_mesh
        w = StlAPI_Writer()
        w.ASCIIMode = False
        w.Write(shape, out)
        res["seconds"] = time.perf_counter() - t
        res["deviation_ratio"] = _occt_deviation(shape, tol)
    elif tool == "cascadio":
        import cascadio
        import trimesh

        glb = out + ".glb"
        t = time.perf_counter()
        cascadio.step_to_glb(path, glb, tol, 0.5)
        scene = trimesh.load(glb, force="scene")
        trimesh.util.concatenate(scene.dump()).export(out)
        res["seconds"] = time.perf_counter() - t
        res["deviation_ratio"] = None
    elif tool == "gmsh":
        import gmsh

        t = time.perf_counter()
        gmsh.initialize(interruptible=False)
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setString("Geometry.OCCTargetUnit", "MM")
        gmsh.model.occ.importShapes(path)
        gmsh.model.occ.synchronize()
        # gmsh has no chord tolerance: size from curvature, elements per 2π chosen so that a radius of 5 mm
        # gets sagitta ≈ tol (n = π / acos(1 − tol / r))
        import math

        n = max(6, math.ceil(math.pi / math.acos(max(-1.0, 1 - tol / 5.0))))
        gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", n)
        gmsh.model.mesh.generate(2)
        gmsh.write(out)
        gmsh.finalize()
        res["seconds"] = time.perf_counter() - t
        res["deviation_ratio"] = None
    res["peak_rss_mb"] = _peak_rss_mb()
    res.update(_mesh_checks(out))
    return res


def _peak_rss_mb() -> float:
    """This process's own peak RSS (VmHWM: per address space, so it starts afresh at exec, unlike ru_maxrss,
    which Linux carries over from the forking parent)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


# ----------------------------------------------------------------------------------------- parent side
def test_parts(folder: Path, only: str = "") -> list[Path]:
    """The reference solids of the tests, written as STEP so that every tool reads the same file (`only`:
    comma-separated substrings of the names to build, all when empty), in `folder`: a part already there, written by
    this cadquery version, is reused (the perforated plate takes cadquery ~15 min to build)."""
    import cadquery as cq

    folder = folder / f"cadquery-{cq.__version__}"
    folder.mkdir(parents=True, exist_ok=True)

    parts = {
        "sphere_r12": lambda: cq.Solid.makeSphere(12, angleDegrees1=-90, angleDegrees2=90),
        "torus_R20_r5": lambda: cq.Solid.makeTorus(20, 5),
        "cylinder_r10": lambda: cq.Solid.makeCylinder(10, 30),
        "bspline_loft": lambda: cq.Workplane("XY").circle(8).workplane(offset=10).rect(10, 6).workplane(offset=10)
        .circle(5).loft(combine=True).val(),
        # many small faces (4,806: 1,600 holes chamfered on both sides), where per-face work outweighs the meshing
        "perforated_plate": lambda: cq.Workplane("XY").box(205, 205, 4).faces(">Z").workplane()
        .rarray(5, 5, 40, 40).hole(2.5).edges("%CIRCLE").chamfer(0.3).val(),
    }
    out = []
    for name, make in parts.items():
        if not _wanted(name, only):
            continue
        p = folder / f"{name}.step"
        if not p.exists():
            part = folder / f"{name}.part.step"
            cq.exporters.export(cq.Workplane().add(make()), str(part))
            part.replace(p)  # whole or not at all, for the next run
        out.append(p)
    return out


def _wanted(name: str, only: str) -> bool:
    """True when `only` (comma-separated substrings) is empty or names `name`."""
    return not only or any(s in name for s in only.split(","))


def wait_child(proc: subprocess.Popen, timeout: float, poll: float = 0.05) -> tuple[int, object, float] | None:
    """(wait status, resource usage (ru_maxrss: the child's peak RSS in KiB), wall seconds) of `proc` once it ends, or
    None when it outlives `timeout` seconds (it is then killed and reaped)."""
    start = time.monotonic()
    pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
    while pid == 0 and time.monotonic() - start < timeout:
        time.sleep(poll)
        pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
    if pid == 0:
        proc.kill()
        os.wait4(proc.pid, 0)
        return None
    return status, usage, time.monotonic() - start


def run_one(tool: str, path: Path, tol: float, timeout: float) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        out = str(Path(tmp) / "out.stl")
        cmd = [sys.executable, __file__, "--child", tool, str(path), str(tol), out]
        with open(Path(tmp) / "result.json", "w+") as sink:
            # every tool's child with numpy's BLAS threads off, as `import amprep` sets for amprep's (whose spinning
            # slowed OCCT's STEP reader ~15 %): all tools run alike
            env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
            proc = subprocess.Popen(cmd, stdout=sink, stderr=subprocess.DEVNULL, text=True, env=env)
            ended = wait_child(proc, timeout)
            if ended is None:
                return {"error": f"timeout {timeout:.0f}s"}
            proc.returncode = os.waitstatus_to_exitcode(ended[0])
            sink.seek(0)
            text = sink.read()
        try:
            return json.loads(text.strip().splitlines()[-1])
        except (ValueError, IndexError):
            return {"error": f"exit {proc.returncode}"}


def _diag(path: Path) -> float:
    from amprep.geometry.cad.read import read_cad
    from amprep.geometry.meshing.pipeline import bbox_diagonal

    return bbox_diagonal(read_cad(path))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--child", nargs=4, metavar=("TOOL", "INPUT", "TOL", "OUT"))
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--timeout", type=float, default=900)
    ap.add_argument("--tools", default=",".join(TOOLS))
    ap.add_argument("--only", default="", help="comma-separated substrings of part names")
    ap.add_argument("--name", default="bench_convert", help="docs/NAME.md and docs/NAME.csv")
    ap.add_argument("--parts", default=str(Path.home() / ".cache" / "amprep-bench"),
                    help="folder of the built test parts, reused between runs")
    ap.add_argument("--from-log", help="comma-separated files of the JSON lines runs printed: write the tables from them "
                    "(a cell in a later file replaces the same part, tolerance and tool of an earlier one)")
    ap.add_argument("--made-by", default="", help="with --from-log: the commands that made the logs, for the docs")
    ap.add_argument("--acis", action="store_true", help="the ACIS corpus (sat/: SAT, SAB, DXF) instead: amprep's "
                    "meshers only (those of --tools, else the default), no other tool reads ACIS")
    ap.add_argument("--tolerances", default="", help="comma-separated mm, instead of 0.1, 0.01 (and 0.001 on small parts)")
    args = ap.parse_args()
    if args.child:
        tool, path, tol, out = args.child
        from amprep.errors import AmprepError

        try:
            print(json.dumps(child(tool, path, float(tol), out)))
        except AmprepError as exc:  # refused by amprep code (amprep, or the checks every output goes through)
            print(json.dumps({"error": exc.code.value}))
        return
    if args.from_log:
        cells: dict[tuple, dict] = {}
        for log in args.from_log.split(","):
            for line in Path(log).read_text().splitlines():
                if line.startswith("{"):
                    row = json.loads(line)
                    cells[(row["part"], row["tolerance"], row["tool"])] = row
        write_tables(list(cells.values()), args.name, args.made_by or f"... (written from {args.from_log})")
        return
    tools = args.tools.split(",")
    if args.acis:
        parts, tools = sorted((CORPUS / "sat").glob("*")), [t for t in tools if t.startswith("amprep")] or ["amprep"]
    else:
        parts = test_parts(Path(args.parts), args.only) + sorted(p for p in CORPUS.glob("*") if p.suffix.lower() in (".step", ".stp", ".iges", ".igs", ".brep"))
    parts = [p for p in parts if _wanted(p.name, args.only)]
    rows = []
    for part in parts:
        diag = _diag(part)
        tols = [0.1, 0.01] + ([0.001] if diag <= SMALL_DIAG and not args.quick else [])
        if args.tolerances:
            tols = [float(t) for t in args.tolerances.split(",")]
        if args.quick and diag > SMALL_DIAG * 4:
            continue
        for tol in tols:
            for tool in tools:
                if tool == "cascadio" and part.suffix.lower() not in (".step", ".stp"):
                    continue
                res = run_one(tool, part, tol, args.timeout)
                row = {"part": part.stem, "tolerance": tol, "tool": tool, **res}
                rows.append(row)
                print(json.dumps(row), flush=True)
    write_tables(rows, args.name, " ".join(sys.argv[1:]))


def write_tables(rows: list[dict], name: str = "bench_convert", argv: str = "") -> None:
    docs = ROOT / "docs"
    docs.mkdir(exist_ok=True)
    fields = ["part", "tolerance", "tool", "seconds", "ratio_vs_fastest_occt", "read_seconds", "mesh_seconds",
              "mesh_ratio_vs_fastest_occt",
              "triangles", "closed", "boundary", "nonmanifold", "degenerate", "deviation_ratio", "peak_rss_mb", "error"]
    for r in rows:
        occt = [o["seconds"] for o in rows if o["part"] == r["part"] and o["tolerance"] == r["tolerance"]
                and o["tool"].startswith("occt-") and "seconds" in o]
        if "seconds" in r and occt:
            r["ratio_vs_fastest_occt"] = r["seconds"] / min(occt)
        occt_mesh = [o["mesh_seconds"] for o in rows if o["part"] == r["part"] and o["tolerance"] == r["tolerance"]
                     and o["tool"].startswith("occt-") and "mesh_seconds" in o]
        if "mesh_seconds" in r and occt_mesh:
            r["mesh_ratio_vs_fastest_occt"] = r["mesh_seconds"] / min(occt_mesh)
    with open(docs / f"{name}.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=fields, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)

    def fmt(v, spec):
        return "" if v is None or v == "" else format(v, spec)

    lines = ["| part | tol mm | tool | s | ×fastest OCCT | read / mesh s | mesh ×fastest OCCT | triangles | closed | "
             "boundary | non-manifold | degenerate | max dev / tol | peak RSS MB |", "|" + "---|" * 14]
    for r in rows:
        if "error" in r and "seconds" not in r:
            lines.append(f"| {r['part']} | {r['tolerance']:g} | {r['tool']} | {r['error']} |||||||||||")
            continue
        split = (f"{r['read_seconds']:.2f} / {r['mesh_seconds']:.2f}" if "mesh_seconds" in r else "")
        lines.append(
            f"| {r['part']} | {r['tolerance']:g} | {r['tool']} | {fmt(r.get('seconds'), '.2f')} | "
            f"{fmt(r.get('ratio_vs_fastest_occt'), '.2f')} | {split} | {fmt(r.get('mesh_ratio_vs_fastest_occt'), '.2f')} | "
            f"{r['triangles']:,} | {'yes' if r['closed'] else 'no'} | "
            f"{r['boundary']} | {r['nonmanifold']} | {r['degenerate']} | {fmt(r.get('deviation_ratio'), '.2f')} | "
            f"{fmt(r.get('peak_rss_mb'), '.0f')} |")
    table = "\n".join(lines)
    (docs / f"{name}.md").write_text(
        f"# Conversion benchmark\n\nMade by `python bench/convert.py {argv}` (one child process per cell, end to end: "
        "read → mesh → write STL, amprep's compiled kernels loaded and dispatched once before the clock, as in a "
        "worker that has run a job; closedness from the written STL with identical-coordinate vertices. `read / mesh s`: for OCCT "
        "the seconds of its STEP read and of BRepMesh alone; for amprep of read_cad and of mesh_model alone (edges, "
        "faces, the chordal error of every triangle measured, the weld; not the output checks or the writing), "
        "run once more in the same process; `mesh ×fastest OCCT` compares those meshing seconds. OCCT reads with its own reader and default healing, amprep with one quadratic "
        "repair skipped where its check finds nothing to repair, see docs/meshing.md). "
        "`max dev / tol` is the worst sampled chordal error over all faces divided by the tolerance (n/a for "
        "cascadio and gmsh, whose output carries no (u,v)). gmsh has no chord tolerance: its size comes from "
        "curvature with elements per 2π set so a 5 mm radius gets the tolerance as sagitta.\n\n" + table + "\n")
    print(table)


if __name__ == "__main__":
    main()
