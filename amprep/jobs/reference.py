"""docs/params.md, the parameter reference, written from jobs.params.KINDS (a test keeps it current):
`python -m amprep.jobs.reference > docs/params.md`."""

from __future__ import annotations

import sys

from amprep.jobs.params import KINDS, Param


def _default(p: Param) -> str:
    if p.default is None:
        return "—"
    if isinstance(p.default, tuple):
        return "`" + ",".join(f"{v:g}" for v in p.default) + "`"
    if isinstance(p.default, bool):
        return "on" if p.default else "off"
    return f"`{p.default:,}`" if isinstance(p.default, int) and p.default >= 10_000 else f"`{p.default}`"


def _kind_of(p: Param) -> str:
    if p.choices:
        return " \\| ".join(p.choices)
    return {"vector3": "x,y,z", "ids": "ids", "text": "text", "url": "URL"}.get(p.type, p.type)


def markdown() -> str:
    """The reference: per job kind, every parameter with its API key, CLI option, type, default, bounds and help."""
    lines = ["# Job parameters", "",
             "Generated from `amprep/jobs/params.py` by `python -m amprep.jobs.reference > docs/params.md` (a test "
             "fails when it is stale). The same names, defaults and bounds hold for the CLI (`--kebab-case`; a "
             "switch `--x` / `--no-x`), the HTTP API (`params` JSON, snake_case) and the dashboard form. "
             "Service-only keys have no CLI option.", ""]
    for kind in KINDS.values():
        lines += [f"## {kind.name}", "", f"{kind.help}. Input: {kind.input_help}. Main artifact: "
                  f"{' or '.join(f'`{a}`' for a in kind.artifacts)}; queue `{kind.queue}`.", "",
                  "| API key | CLI option | type | default | unit | bounds | what it does |", "|---|---|---|---|---|---|---|"]
        for p in kind.params:
            option = "(service only)" if p.service_only else (
                f"`{p.option}` / `--no-{p.option[2:]}`" if p.type == "bool" else f"`{p.option}`")
            text = p.help.replace("|", "\\|")
            lines.append(f"| `{p.name}` | {option} | {_kind_of(p)} | {_default(p)} | {p.unit} | "
                         f"{p.bounds_text()} | {text} |")
        lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":
    sys.stdout.write(markdown())
