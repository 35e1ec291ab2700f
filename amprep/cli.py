"""`amprep` command line: convert (local), serve, submit (HTTP client), key. Errors print one line with their stable code, exit status 2."""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections.abc import Callable, Sequence

from .geometry.errors import AmprepError, ErrorCode

EXIT_ERROR = 2


def _progress_bar(quiet: bool) -> tuple[Callable[[str, float], None] | None, Callable[[], None]]:
    """A rich progress bar on stderr that appears only once work has run for over a second."""
    if quiet or not sys.stderr.isatty():
        return None, lambda: None
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    start = time.monotonic()
    state: dict = {}

    def update(stage: str, fraction: float) -> None:
        if "bar" not in state:
            if time.monotonic() - start < 1.0:
                return
            bar = Progress(TextColumn("{task.description:<20}"), BarColumn(), TextColumn("{task.percentage:>3.0f}%"),
                           TimeElapsedColumn(), transient=True)
            bar.start()
            state["bar"], state["task"] = bar, bar.add_task(stage, total=1.0)
        state["bar"].update(state["task"], description=stage, completed=fraction)

    def close() -> None:
        if "bar" in state:
            state["bar"].stop()

    return update, close


def _quiet_occt() -> None:
    """Stop OCCT printing its readers' messages on stdout."""
    from OCP.Message import Message

    messenger = Message.DefaultMessenger_s()
    printers = messenger.Printers()
    for printer in [printers.Value(i) for i in range(1, printers.Length() + 1)]:
        messenger.RemovePrinter(printer)


def cmd_convert(args: argparse.Namespace) -> int:
    from .geometry.convert import convert, write_result
    from .geometry.tessellate import MeshParams

    params = MeshParams(tolerance=args.tolerance, relative=args.relative, angular=args.angular,
                        min_size=args.min_size, algorithm=args.algorithm,
                        occt_edges=args.occt_edges, own_large_faces=not args.occt_large_faces)
    update, close = _progress_bar(args.quiet)
    try:
        result = convert(args.input, params, update)
        written = write_result(result, args.output, ascii=args.ascii)
    finally:
        close()
    summary = result.summary()
    summary["output"] = written
    if args.report:
        with open(args.report, "w") as fh:
            json.dump(summary, fh, indent=2, default=float)
    if not args.quiet:
        m, c = result.meshing, result.checks
        state = "closed" if c.closed else f"OPEN ({c.boundary_edges} boundary, {c.nonmanifold_edges} non-manifold edges)"
        line = f"{args.output}: {c.triangles:,} triangles, {state}, {written['bytes']:,} bytes"
        if m is not None:
            line += f"; max chordal error {m.max_error:.4g} mm (tolerance {m.tolerance:.4g} mm)"
        units = result.input.get("units")
        if units and units != "mm":
            line += f"; file unit {units}, written in mm"
        print(line)
        for note in result.notes:
            print(f"  note: {note}")
    return 0


def _build_dir(text: str) -> tuple[float, float, float]:
    parts = [float(x) for x in text.split(",")]
    if len(parts) != 3:
        raise AmprepError(ErrorCode.INVALID_PARAMETER, f"--build-dir takes x,y,z, got '{text}'")
    return parts[0], parts[1], parts[2]


def cmd_analyze(args: argparse.Namespace) -> int:
    from pathlib import Path

    from .geometry.analysis import AnalysisParams, analyze_file
    from .geometry.report_files import write_analysis
    from .geometry.tessellate import MeshParams

    params = AnalysisParams(layer=args.layer, build_dir=_build_dir(args.build_dir), sample_order=args.sample_order,
                            cloud_density=args.cloud_density, bounding_box=not args.no_box)
    mesh_params = MeshParams(tolerance=args.tolerance, relative=args.relative, angular=args.angular)
    update, close = _progress_bar(args.quiet)
    try:
        a = analyze_file(args.input, args.stl, mesh_params, params, update)
    finally:
        close()
    if args.report:
        with open(args.report, "w") as fh:
            json.dump(a.report, fh, indent=1, default=float)
    if args.out_dir:
        write_analysis(a, Path(args.out_dir))
    if not args.quiet:
        r = a.report
        m = r["mesh"]
        state = "watertight" if m["watertight"] else "NOT watertight"
        print(f"{args.input}: {m['triangles']:,} triangles, {state}, {m['shells']} shell(s), volume {m['volume']:.6g} mm³")
        if r["chordal_error"]:
            print(f"  chordal error: mean {r['chordal_error']['mean']:.4g} mm, max {r['chordal_error']['max']:.4g} mm")
        c = r["cusp_height"]
        line = f"  cusp height (t = {c['layer']:g} mm): approximate mean {c['approximate']['mean']:.4g}, max {c['approximate']['max']:.4g}"
        if c["bounding_box"] and c["bounding_box"]["mean"] is not None:
            line += f"; bounding box mean {c['bounding_box']['mean']:.4g}, max {c['bounding_box']['max']:.4g}"
        print(line)
        reg = r["regularity"]
        print("  regularity means: " + ", ".join(f"{k} {reg[k]['mean']:.3f}" for k in ("angle", "area", "edge")))
        for issue in r["issues"]:
            print(f"  {issue['severity']}: {issue['code']} ({issue['count']}): {issue['message']}")
    return 0


def _faces(text: str | None) -> tuple[int, ...] | None:
    if text is None:
        return None
    try:
        return tuple(int(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise AmprepError(ErrorCode.INVALID_PARAMETER, f"--faces takes face ids like 3,7, got '{text}'") from None


def cmd_refine(args: argparse.Namespace) -> int:
    from pathlib import Path

    from .geometry.refine import RefineParams, refine_file
    from .geometry.report_files import write_refinement
    from .geometry.tessellate import MeshParams

    params = RefineParams(method=args.method, faces=_faces(args.faces), max_chordal=args.max_chordal,
                          max_cusp=args.max_cusp, max_cylindricity=args.max_cylindricity, layer=args.layer,
                          build_dir=_build_dir(args.build_dir), ratios=args.ratios, iterations=args.iterations,
                          target=args.target,
                          compare=not args.no_compare, max_triangles=args.max_triangles)
    mesh_params = MeshParams(tolerance=args.tolerance, relative=args.relative, angular=args.angular)
    out = Path(args.output)
    if out.suffix.lower() not in (".stl", ".3mf"):
        raise AmprepError(ErrorCode.INVALID_PARAMETER, f"output must end in .stl or .3mf, got '{out.name}'")
    if not out.resolve().parent.is_dir():
        raise AmprepError(ErrorCode.WRITE_FAILED, f"cannot write {out}: no directory {out.parent}")
    update, close = _progress_bar(args.quiet)
    try:
        r = refine_file(args.input, args.stl, mesh_params, params, update)
    finally:
        close()
    from .geometry.report_files import write_refined_mesh

    write_refined_mesh(r, out, args.ascii)
    if args.report:
        with open(args.report, "w") as fh:
            json.dump(r.report, fh, indent=1, default=float)
    if args.out_dir:
        write_refinement(r, Path(args.out_dir), out.name, args.ascii)
    if not args.quiet:
        rep = r.report
        b, a = rep["mesh_before"], rep["mesh"]
        state = "closed" if a["watertight"] else "open"
        print(f"{out}: {a['triangles']:,} triangles (from {b['triangles']:,}), {state}; "
              f"{len(rep['refined_faces'])} face(s) refined by {rep['method'].upper()}")
        for f in rep["refined_faces"]:
            cb, ca = f["chordal_error_before"], f["chordal_error_after"]
            err = f"chordal mean {cb['mean']:.4g} → {ca['mean']:.4g} mm" if cb and ca else "no chordal error"
            print(f"  face {f['id']} {f['surface_type']}: {f['triangles_before']} → {f['triangles_after']} triangles, "
                  f"{err} ({f['reason']})")
        for issue in rep["issues"]:
            print(f"  {issue['severity']}: {issue['code']}: {issue['message']}")
    return 0


def cmd_serve(args: argparse.Namespace) -> int:
    from pathlib import Path

    from .logs import setup_logging
    from .serve import serve

    setup_logging()
    return serve(args.host, args.port, args.workers, Path(args.data), args.redis_url or os.environ.get("AMPREP_REDIS_URL"),
                 run_workers=not args.no_workers)


def _param_value(text: str) -> object:
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


def cmd_submit(args: argparse.Namespace) -> int:
    from pathlib import Path

    from .client import Client, main_artifact

    params = json.loads(args.params) if args.params else {}
    for item in args.param or []:
        key, sep, value = item.partition("=")
        if not sep:
            raise AmprepError(ErrorCode.INVALID_PARAMETER, f"-p takes key=value, got '{item}'")
        params[key.replace("-", "_")] = _param_value(value)
    client = Client(args.server, args.api_key or os.environ.get("AMPREP_API_KEY"))
    job = client.submit(Path(args.input), args.kind, params, Path(args.stl) if args.stl else None, args.idempotency_key)
    if args.wait or args.output:
        update, close = _progress_bar(args.quiet)
        try:
            job = client.follow(job["id"], (lambda j: update(j["stage"], j["progress"])) if update else None)
        finally:
            close()
    if args.output and job["status"] == "succeeded":
        name = main_artifact(job)
        if name is None:
            raise AmprepError(ErrorCode.NOT_FOUND, f"job {job['id']} has no main artifact to write")
        client.download(job, name, Path(args.output))
    if not args.quiet or job["status"] not in ("queued", "running", "succeeded"):
        print(json.dumps(job, indent=2) if args.json else _job_line(job))
    if job["status"] in ("failed", "cancelled"):
        err = job.get("error") or {}
        print(f"amprep: error [{err.get('code', 'cancelled')}]: {err.get('message', '')}", file=sys.stderr)
        return EXIT_ERROR
    return 0


def _job_line(job: dict) -> str:  # type: ignore[type-arg]
    line = f"job {job['id']} {job['kind']} {job['status']}"
    if job.get("reused_from"):
        line += f" (reused the result of {job['reused_from']})"
    for a in job.get("artifacts", []):
        line += f"\n  {a['name']}  {a['size']:,} bytes  {a['url']}"
    return line


def cmd_key(args: argparse.Namespace) -> int:
    import secrets

    from .settings import hash_key

    key = "amp_" + secrets.token_urlsafe(32)
    print(f"key (give to the client, shown once): {key}")
    print(f"sha256 (add to AMPREP_API_KEYS on the server): {hash_key(key)}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="amprep", description="CAD to print-ready STL, with numbers.")
    sub = parser.add_subparsers(dest="command", required=True)
    c = sub.add_parser("convert", help="STEP/IGES/BREP/STL → closed STL or 3MF within a chord tolerance")
    c.add_argument("input")
    c.add_argument("-o", "--output", required=True, help="OUT.stl or OUT.3mf")
    tol = c.add_mutually_exclusive_group()
    tol.add_argument("--tolerance", type=float, default=0.1, help="max chord deviation in mm (default 0.1)")
    tol.add_argument("--relative", type=float, default=None, help="tolerance as a fraction of the bounding-box diagonal")
    c.add_argument("--angular", type=float, default=0.5, help="largest angle one segment of a curved edge turns through, radians (default 0.5)")
    c.add_argument("--min-size", type=float, default=0.0, help="smallest triangle edge in mm (default: tolerance/10)")
    c.add_argument("--algorithm", choices=["delabella", "watson"], default="delabella", help="OCCT mesh algorithm")
    c.add_argument("--occt-edges", action="store_true",
                   help="discretise every edge as OCCT does, at half the tolerance and angle (more triangles)")
    c.add_argument("--occt-large-faces", action="store_true",
                   help="let OCCT mesh large torus faces too (by default they are ours: faster, fewer triangles)")
    c.add_argument("--ascii", action="store_true", help="ASCII STL instead of binary")
    c.add_argument("--report", help="write a JSON summary here")
    c.add_argument("--quiet", action="store_true", help="no progress bar and no summary line")
    c.set_defaults(func=cmd_convert)

    an = sub.add_parser("analyze", help="the error report: mesh checks, chordal error, cusp height, cylindricity, regularity")
    an.add_argument("input", help="STEP/IGES/BREP (tessellated as convert does) or STL")
    an.add_argument("--stl", help="an STL made elsewhere, scored against the CAD INPUT")
    an.add_argument("--layer", type=float, default=0.2, help="layer thickness in mm (default 0.2)")
    an.add_argument("--build-dir", default="0,0,1", help="build direction x,y,z (default 0,0,1)")
    an.add_argument("--sample-order", type=int, default=6, help="chordal sampling order (default 6: 28 points)")
    an.add_argument("--cloud-density", type=float, help="points per mm² for the bounding-box method (default (4/t)²)")
    an.add_argument("--no-box", action="store_true", help="skip the bounding-box cusp method")
    an_tol = an.add_mutually_exclusive_group()
    an_tol.add_argument("--tolerance", type=float, default=0.1, help="tessellation tolerance for CAD input (mm)")
    an_tol.add_argument("--relative", type=float, default=None)
    an.add_argument("--angular", type=float, default=0.5)
    an.add_argument("--report", help="write report.json here")
    an.add_argument("--out-dir", help="write the report, the scored mesh, per-triangle fields and PNG plots here")
    an.add_argument("--quiet", action="store_true")
    an.set_defaults(func=cmd_analyze)

    rf = sub.add_parser("refine", help="densify the curved faces whose error is too high (SMA, or VTA), keeping the mesh closed")
    rf.add_argument("input", help="STEP/IGES/BREP")
    rf.add_argument("--stl", help="refine this STL made elsewhere (placed on the CAD; written back in its own frame)")
    rf.add_argument("-o", "--output", required=True, help="OUT.stl or OUT.3mf")
    rf.add_argument("--method", choices=["sma", "vta", "adaptive"], default="sma")
    rf.add_argument("--faces", help="CAD face ids to refine, e.g. 3,7 (else chosen by the thresholds)")
    rf.add_argument("--max-chordal", type=float, help="refine curved faces whose mean chordal error exceeds this (mm)")
    rf.add_argument("--max-cusp", type=float, help="refine curved faces whose mean cusp height exceeds this (mm)")
    rf.add_argument("--max-cylindricity", type=float, help="refine cylinders whose cylindricity zone exceeds this (mm)")
    rf.add_argument("--layer", type=float, default=0.2, help="layer thickness for the cusp height (mm)")
    rf.add_argument("--build-dir", default="0,0,1", help="build direction x,y,z")
    rf.add_argument("--ratios", default="3:4:3,3:4:3", help="SMA spoke a:b:c and edge p:q:p ratios")
    rf.add_argument("--iterations", type=int, default=1, help="VTA iterations")
    rf.add_argument("--target", type=float, help="adaptive: chordal error to reach (mm; default a tenth of the worst)")
    rf_tol = rf.add_mutually_exclusive_group()
    rf_tol.add_argument("--tolerance", type=float, default=0.2, help="first tessellation's tolerance without --stl (mm)")
    rf_tol.add_argument("--relative", type=float, default=None)
    rf.add_argument("--angular", type=float, default=0.5)
    rf.add_argument("--ascii", action="store_true", help="ASCII STL")
    rf.add_argument("--no-compare", action="store_true", help="skip the uniform re-tessellations and the other method")
    rf.add_argument("--max-triangles", type=int, default=10_000_000,
                    help="refuse a refinement predicted to output more triangles (default 10,000,000)")
    rf.add_argument("--report", help="write report.json here")
    rf.add_argument("--out-dir", help="write the refined mesh, report, per-triangle error and the PNG plot here")
    rf.add_argument("--quiet", action="store_true")
    rf.set_defaults(func=cmd_refine)

    sv = sub.add_parser("serve", help="run the service on this machine: private Redis, workers and the API")
    sv.add_argument("--host", default="127.0.0.1", help="address to bind (not loopback: API keys required)")
    sv.add_argument("--port", type=int, default=8000)
    sv.add_argument("--workers", type=int, default=2, help="worker processes for convert/analyze (refine: half)")
    sv.add_argument("--data", default=os.environ.get("AMPREP_DATA_DIR", "amprep-data"),
                    help="jobs, artifacts and Redis's append-only file (default: $AMPREP_DATA_DIR or ./amprep-data)")
    sv.add_argument("--redis-url", help="use this Redis instead of a private one (default: $AMPREP_REDIS_URL)")
    sv.add_argument("--no-workers", action="store_true", help="the API only (workers run elsewhere: Docker, many hosts)")
    sv.set_defaults(func=cmd_serve)

    sb = sub.add_parser("submit", help="send a file to an amprep server and (with --wait or -o) wait for the result")
    sb.add_argument("input")
    sb.add_argument("--kind", choices=["convert", "analyze", "refine"], required=True)
    sb.add_argument("--stl", help="an STL made elsewhere, scored or refined against INPUT")
    sb.add_argument("--server", default="http://127.0.0.1:8000")
    sb.add_argument("--api-key", help="default: $AMPREP_API_KEY")
    sb.add_argument("--params", help="JSON object of the kind's params")
    sb.add_argument("-p", "--param", action="append", help="one param as key=value (value read as JSON if it parses)")
    sb.add_argument("--idempotency-key")
    sb.add_argument("--wait", action="store_true", help="follow the job to its end")
    sb.add_argument("-o", "--output", help="write the main artifact here (implies --wait)")
    sb.add_argument("--json", action="store_true", help="print the job as JSON")
    sb.add_argument("--quiet", action="store_true")
    sb.set_defaults(func=cmd_submit)

    k = sub.add_parser("key", help="make an API key and the sha256 digest the server is configured with")
    k.set_defaults(func=cmd_key)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    for stream in (sys.stdout, sys.stderr):  # summaries use µ, →, ³: never crash on an ASCII terminal
        if hasattr(stream, "reconfigure") and (stream.encoding or "").lower().replace("-", "") != "utf8":
            stream.reconfigure(errors="replace")
    args = build_parser().parse_args(argv)
    if args.command in ("convert", "analyze", "refine"):
        _quiet_occt()
    try:
        return int(args.func(args))
    except AmprepError as exc:
        print(f"amprep: error [{exc.code.value}]: {exc.message}", file=sys.stderr)
        return EXIT_ERROR
    except KeyboardInterrupt:
        print(f"amprep: error [{ErrorCode.CANCELLED.value}]: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # a bug of ours: one line with a code, the traceback only when asked for
        if os.environ.get("AMPREP_DEBUG"):
            raise
        print(f"amprep: error [{ErrorCode.INTERNAL_ERROR.value}]: {type(exc).__name__}: {exc} "
              "(a bug in amprep: AMPREP_DEBUG=1 shows the traceback; please report it with the input)", file=sys.stderr)
        return EXIT_ERROR


if __name__ == "__main__":
    sys.exit(main())
