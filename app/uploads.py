"""Uploads: sniff the format from the first bytes, stream the file into the job's input directory with its sha256."""

from __future__ import annotations

import hashlib
import re
import shutil
from pathlib import Path
from typing import Any

from fastapi import UploadFile
from starlette.concurrency import run_in_threadpool

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.core.formats import sniff_bytes

from .problems import ApiError

EXTENSION = {"step": ".step", "iges": ".iges", "brep": ".brep", "sat": ".sat", "sab": ".sab", "dxf": ".dxf", "stl": ".stl"}


def _safe_name(name: str | None) -> str:
    base = Path(name or "upload").name
    return re.sub(r"[^\w.\- ]", "_", base)[:200] or "upload"


def _copy(src: Any, dst: Path) -> str:
    dst.parent.mkdir(parents=True, exist_ok=True)
    h = hashlib.sha256()
    src.seek(0)
    with dst.open("wb") as out:
        while block := src.read(1 << 20):
            h.update(block)
            out.write(block)
    return h.hexdigest()


async def sniff(upload: UploadFile, part: str) -> dict[str, Any]:
    """{name, size, format} of an upload; a 422 problem with the library's code when it is empty or unknown."""
    head = await upload.read(8192)
    await upload.seek(0)
    size = upload.size if upload.size is not None else len(head)
    try:
        fmt = sniff_bytes(head, size)
    except AmprepError as exc:
        raise ApiError(422, exc.code, f"{part}: {exc.message}") from None
    return {"name": _safe_name(upload.filename), "size": size, "format": fmt}


async def store_upload(upload: UploadFile, info: dict[str, Any], dst_dir: Path, stem: str) -> dict[str, Any]:
    """Copy the upload into dst_dir as `<stem>.<format>`; info plus sha256 and stored_as."""
    stored_as = stem + EXTENSION[info["format"]]
    try:
        digest = await run_in_threadpool(_copy, upload.file, dst_dir / stored_as)
    except OSError as exc:
        shutil.rmtree(dst_dir, ignore_errors=True)
        raise ApiError(507, ErrorCode.WRITE_FAILED, f"cannot store the upload: {exc.strerror}") from None
    return info | {"sha256": digest, "stored_as": stored_as}


def require_stl(info: dict[str, Any]) -> None:
    if info["format"] != "stl":
        raise ApiError(422, ErrorCode.UNSUPPORTED_FORMAT, f"stl: the part named 'stl' must be an STL, got {info['format']}")


def require_cad(info: dict[str, Any]) -> None:
    """With an 'stl' part, 'file' is the CAD it is scored against."""
    if info["format"] == "stl":
        raise ApiError(422, ErrorCode.INVALID_REQUEST, "file: with an 'stl' part, 'file' must be the CAD (STEP, IGES, BREP, ACIS SAT/SAB/DXF)")
