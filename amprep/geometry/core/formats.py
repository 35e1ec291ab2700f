"""Recognise an input format from its leading bytes, never from its file name."""

from __future__ import annotations

import re
import struct
from pathlib import Path

from amprep.errors import AmprepError, ErrorCode

CAD_FORMATS = ("step", "iges", "brep", "sat", "sab", "dxf")
ACIS_FORMATS = ("sat", "sab", "dxf")
_DXF = re.compile(rb"\A\s*(999\s*\r?\n[^\n]*\r?\n\s*)*0\s*\r?\nSECTION\s*\r?\n")
MESH_FORMATS = ("stl",)

_SAT_HEAD = re.compile(r"^[ \t]*(\d{2,6})[ \t]+\d+[ \t]+\d+[ \t]+\d+[ \t]*\n[^\n]*\n[ \t]*[-+]?\d[\d.eE+-]*[ \t]", re.M)


def sat_start(text: str) -> int | None:
    """Offset of a SAT header (`version records bodies flags`, the writer's line, `unit resabs resnor`) within the
    first 4 KiB, past any preamble such as Fusion's .smt lines; None when there is none."""
    m = _SAT_HEAD.search(text[:4096])
    return m.start() if m else None


def sniff_bytes(head: bytes, size: int) -> str:
    """Format of a file from its first bytes (≥ 4 KiB when the file has them) and its total size.

    Returns step | iges | brep | sat | sab | dxf | stl; raises AmprepError(empty_model | unsupported_format).
    """
    if size == 0 or not head.strip():
        raise AmprepError(ErrorCode.EMPTY_MODEL, "the file is empty")
    if size >= 84 and len(head) >= 84:  # a head shorter than the size says cannot hold the count
        (n,) = struct.unpack_from("<I", head, 80)
        if 84 + 50 * n == size and n > 0:
            return "stl"
    text = head.lstrip(b"\xef\xbb\xbf \t\r\n")
    if text.startswith(b"ISO-10303-21"):
        return "step"
    if text.startswith((b"DBRep_DrawableShape", b"CASCADE Topology")):
        return "brep"
    if text.startswith(b"Open CASCADE Topology"):
        return "brep"
    if text[:5].lower() == b"solid" and b"facet" in text[:4096].lower():
        return "stl"
    if text.startswith((b"ACIS BinaryFile", b"ASM BinaryFile")):
        return "sab"
    if _DXF.match(head) or head.startswith(b"AutoCAD Binary DXF"):
        return "dxf"
    if sat_start(head.decode("latin-1").replace("\r\n", "\n")) is not None:
        return "sat"
    first = head.split(b"\n", 1)[0].rstrip(b"\r")
    if len(first) >= 73 and first[72:73] in (b"S", b"G", b"F"):
        return "iges"
    if head.startswith(b"PK\x03\x04"):
        raise AmprepError(ErrorCode.UNSUPPORTED_FORMAT, "a ZIP archive (3MF, compressed CAD) is not a supported input")
    raise AmprepError(
        ErrorCode.UNSUPPORTED_FORMAT,
        "not a STEP, IGES, BREP, ACIS (SAT, SAB, DXF) or STL file (recognised from its bytes)",
    )


def sniff_path(path: str | Path) -> str:
    """Format of a file on disk, from its bytes."""
    p = Path(path)
    try:
        size = p.stat().st_size
        with p.open("rb") as fh:
            head = fh.read(8192)
    except OSError as exc:
        raise AmprepError(ErrorCode.UNREADABLE_CAD, f"cannot read {p.name}: {exc.strerror}") from None
    return sniff_bytes(head, size)
