"""`amprep` command line: convert (local). Errors print one line with their stable code, exit status 2."""

from __future__ import annotations

import argparse
import json
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
                        min_size=args.min_size, algorithm=args.algorithm)
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


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="amprep", description="CAD to print-ready STL, with numbers.")
    sub = parser.add_subparsers(dest="command", required=True)
    c = sub.add_parser("convert", help="STEP/IGES/BREP/STL → closed STL or 3MF within a chord tolerance")
    c.add_argument("input")
    c.add_argument("-o", "--output", required=True, help="OUT.stl or OUT.3mf")
    tol = c.add_mutually_exclusive_group()
    tol.add_argument("--tolerance", type=float, default=0.1, help="max chord deviation in mm (default 0.1)")
    tol.add_argument("--relative", type=float, default=None, help="tolerance as a fraction of the bounding-box diagonal")
    c.add_argument("--angular", type=float, default=0.5, help="angular deflection in radians (default 0.5)")
    c.add_argument("--min-size", type=float, default=0.0, help="smallest triangle edge in mm (default: tolerance/10)")
    c.add_argument("--algorithm", choices=["delabella", "watson"], default="delabella", help="OCCT mesh algorithm")
    c.add_argument("--ascii", action="store_true", help="ASCII STL instead of binary")
    c.add_argument("--report", help="write a JSON summary here")
    c.add_argument("--quiet", action="store_true", help="no progress bar and no summary line")
    c.set_defaults(func=cmd_convert)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    _quiet_occt()
    try:
        return int(args.func(args))
    except AmprepError as exc:
        print(f"amprep: error [{exc.code.value}]: {exc.message}", file=sys.stderr)
        return EXIT_ERROR
    except KeyboardInterrupt:
        print(f"amprep: error [{ErrorCode.CANCELLED.value}]: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
