"""Recognise an input format from its leading bytes, never from its file name."""

from __future__ import annotations

import struct
from pathlib import Path

from amprep.errors import AmprepError, ErrorCode

CAD_FORMATS = ("step", "iges", "brep")
MESH_FORMATS = ("stl",)


def sniff_bytes(head: bytes, size: int) -> str:
    """Format of a file from its first bytes (≥ 4 KiB when the file has them) and its total size.

    Returns step | iges | brep | stl; raises AmprepError(empty_model | unsupported_format).
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
    first = head.split(b"\n", 1)[0].rstrip(b"\r")
    if len(first) >= 73 and first[72:73] in (b"S", b"G", b"F"):
        return "iges"
    if head.startswith(b"PK\x03\x04"):
        raise AmprepError(ErrorCode.UNSUPPORTED_FORMAT, "a ZIP archive (3MF, compressed CAD) is not a supported input")
    raise AmprepError(
        ErrorCode.UNSUPPORTED_FORMAT,
        "not a STEP, IGES, BREP or STL file (recognised from its bytes)",
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
