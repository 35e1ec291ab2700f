"""`amprep` command line: convert (local), serve, submit (HTTP client), key. Errors print one line with their stable code, exit status 2."""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from amprep import __version__
from amprep.errors import AmprepError, ErrorCode
from amprep.jobs.params import KINDS, build, check, parse_cli_value

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


def _job_values(kind: str, args: argparse.Namespace) -> dict[str, Any]:
    """The kind's parameters from the CLI's options (those given; defaults and bounds from jobs.params.check); the
    output format from -o's extension when --format is not given."""
    spec = KINDS[kind]
    raw = {p.name: parse_cli_value(p, v) if isinstance(v, str) else v
           for p in spec.params if not p.service_only and (v := getattr(args, p.name)) is not None}
    output = getattr(args, "output", None)
    if output is not None and "format" in {p.name for p in spec.params}:
        ext = Path(output).suffix.lower().lstrip(".")
        if ext not in ("stl", "3mf"):
            raise AmprepError(ErrorCode.INVALID_PARAMETER, f"output must end in .stl or .3mf, got '{Path(output).name}'")
        if raw.setdefault("format", ext) != ext:
            raise AmprepError(ErrorCode.INVALID_PARAMETER, f"--format {raw['format']} but -o ends in .{ext}")
    return check(kind, raw)


def _write_json(path: str | None, data: dict[str, Any], indent: int = 1) -> None:
    if path:
        with open(path, "w", encoding="utf-8") as fh:
            json.dump(data, fh, indent=indent, default=float)


def _closed_by_index(by_position: int) -> str:
    """The CLI's state of a mesh closed by index that joining its STL's vertices by float32 position opens."""
    return f"closed by index, {by_position} non-manifold edges once joined by position"


def cmd_convert(args: argparse.Namespace) -> int:
    from amprep.geometry.meshing.params import MeshParams
    from amprep.jobs.convert import convert, write_result

    values = _job_values("convert", args)
    update, close = _progress_bar(args.quiet)
    try:
        result = convert(args.input, build(MeshParams, values), update)
        written = write_result(result, args.output, ascii=values["ascii"])
    finally:
        close()
    summary = result.summary()
    summary["output"] = written
    _write_json(args.report, summary, indent=2)
    if not args.quiet:
        m, c = result.meshing, result.checks
        state = "closed" if c.closed else f"OPEN ({c.boundary_edges} boundary, {c.nonmanifold_edges} non-manifold edges)"
        if c.closed and not result.closed_by_position and str(args.output).lower().endswith(".stl"):
            state = _closed_by_index(result.nonmanifold_by_position)
        line = f"{args.output}: {c.triangles:,} triangles, {state}, {written['bytes']:,} bytes"
        if m is not None:
            line += f"; max chordal error {m.max_error:.4g} mm (tolerance {m.tolerance:.4g} mm)"
        line += f"; mean angle regularity {result.regularity['angle']['mean']:.3f}"
        units = result.input.get("units")
        if units and units != "mm":
            line += f"; file unit {units}, written in mm"
        print(line)
        for note in result.notes:
            print(f"  note: {note}")
    return 0


def cmd_analyze(args: argparse.Namespace) -> int:
    from amprep.geometry.measure.analysis import AnalysisParams
    from amprep.geometry.meshing.params import MeshParams
    from amprep.jobs.analyze import analyze_file
    from amprep.jobs.artifacts import write_analysis

    values = _job_values("analyze", args)
    update, close = _progress_bar(args.quiet)
    try:
        a = analyze_file(args.input, args.stl, build(MeshParams, values), build(AnalysisParams, values), update)
    finally:
        close()
    _write_json(args.report, a.report)
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


def cmd_refine(args: argparse.Namespace) -> int:
    from amprep.geometry.meshing.params import MeshParams
    from amprep.geometry.refine.compare import RefineParams
    from amprep.jobs.artifacts import write_refined_mesh, write_refinement
    from amprep.jobs.refine import refine_file

    values = _job_values("refine", args)
    out = Path(args.output)
    if not out.resolve().parent.is_dir():
        raise AmprepError(ErrorCode.WRITE_FAILED, f"cannot write {out}: no directory {out.parent}")
    update, close = _progress_bar(args.quiet)
    try:
        r = refine_file(args.input, args.stl, build(MeshParams, values), build(RefineParams, values), update)
    finally:
        close()
    write_refined_mesh(r, out, values["ascii"])
    _write_json(args.report, r.report)
    if args.out_dir:
        write_refinement(r, Path(args.out_dir), out.name, values["ascii"])
    if not args.quiet:
        rep = r.report
        b, a = rep["mesh_before"], rep["mesh"]
        state = "closed" if a["watertight"] else "open"
        if a["watertight"] and not a.get("closed_by_position", True) and out.suffix.lower() == ".stl":
            state = _closed_by_index(a["nonmanifold_edges_by_position"])
        bf = rep.get("butterfly")
        how = (f"{len(rep['refined_faces'])} face(s) refined by {rep['method'].upper()}" if bf is None else
               f"re-meshed to edges ≤ {bf['max_edge']:g} mm on the Butterfly limit surface (longest "
               f"{bf['longest_edge']:.4g} mm)" if bf.get("max_edge") else
               f"{bf['levels']} level(s) of Butterfly, new nodes moved up to {bf['moved']['max']:.4g} mm")
        print(f"{out}: {a['triangles']:,} triangles (from {b['triangles']:,}), {state}; {how}")
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

    from amprep.logs import setup_logging
    from amprep.serve import serve

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

    from amprep.client import Client, main_artifact

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

    from amprep.settings import hash_key

    key = "amp_" + secrets.token_urlsafe(32)
    print(f"key (give to the client, shown once): {key}")
    print(f"sha256 (add to AMPREP_API_KEYS on the server): {hash_key(key)}")
    return 0


def cmd_warm(args: argparse.Namespace) -> int:
    """Compile (or load) every numba kernel now, into numba's cache: NUMBA_CACHE_DIR, else beside the sources when
    writable, else the user's cache directory. The image runs it at build time."""
    import numba

    from amprep.geometry.measure.chordal import warm_kernels
    from amprep.geometry.refine.butterfly import warm_ring_kernel

    start = time.perf_counter()
    warm_kernels()
    warm_ring_kernel()
    where = numba.config.CACHE_DIR or "beside amprep's sources (or the user's cache directory where not writable)"
    print(f"kernels ready in {time.perf_counter() - start:.1f} s, cached in {where}")
    return 0


#: the CLI's own options of each job command, beside the kind's parameters (jobs.params.KINDS)
LOCAL_OPTIONS = {
    "convert": (("-o", "--output", dict(required=True, help="OUT.stl or OUT.3mf")),
                ("--report", dict(help="write a JSON summary here"))),
    "analyze": (("--stl", dict(help="an STL made elsewhere, scored against the CAD INPUT")),
                ("--report", dict(help="write report.json here")),
                ("--out-dir", dict(help="write the report, the scored mesh, per-triangle fields and PNG plots here"))),
    "refine": (("--stl", dict(help="refine this STL made elsewhere (placed on the CAD; written back in its own frame)")),
               ("-o", "--output", dict(required=True, help="OUT.stl or OUT.3mf")),
               ("--report", dict(help="write report.json here")),
               ("--out-dir", dict(help="write the refined mesh, report, per-triangle error and the PNG plot here"))),
}


def _job_parser(sub: Any, kind: str, func: Callable[[argparse.Namespace], int]) -> None:
    """The subcommand of a job kind: INPUT, the CLI's own options, and one option per parameter of the kind."""
    spec = KINDS[kind]
    sp = sub.add_parser(kind, help=spec.help, description=spec.help)
    sp.add_argument("input", help=spec.input_help)
    for *flags, kw in LOCAL_OPTIONS[kind]:
        sp.add_argument(*flags, **kw)
    sp.add_argument("--quiet", action="store_true", help="no progress bar and no summary line")
    for p in spec.params:
        if p.service_only:
            continue
        default = "none" if p.default is None else ",".join(map(str, p.default)) if isinstance(p.default, tuple) \
            else ("on" if p.default else "off") if p.type == "bool" else p.default
        text = f"{p.describe()}; default {default}".replace("%", "%%")
        if p.type == "bool":
            sp.add_argument(p.option, action=argparse.BooleanOptionalAction, default=None, help=text)
        else:
            metavar = "{" + ",".join(p.choices) + "}" if p.choices else {"vector3": "X,Y,Z", "ids": "ID,ID"}.get(
                p.type, p.name.upper())
            sp.add_argument(p.option, default=None, metavar=metavar, help=text)
    sp.set_defaults(func=func)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="amprep", description="CAD to print-ready STL, with numbers.")
    parser.add_argument("--version", action="version", version=f"amprep {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    for kind, func in (("convert", cmd_convert), ("analyze", cmd_analyze), ("refine", cmd_refine)):
        _job_parser(sub, kind, func)

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
    sb.add_argument("--kind", choices=list(KINDS), required=True)
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
    w = sub.add_parser("warm", help="compile the numba kernels into numba's cache now (a first large job then loads "
                       "them instead of compiling for ~20 s)")
    w.set_defaults(func=cmd_warm)
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
