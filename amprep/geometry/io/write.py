"""Write a mesh by the output's extension: .stl (binary, or ASCII) or .3mf; one place for both jobs that write."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.core.mesh import Mesh
from amprep.geometry.io.stl import write_stl
from amprep.geometry.io.threemf import write_3mf

EXTENSIONS = (".stl", ".3mf")


def write_mesh(mesh: Mesh, out: str | Path, generator: str, source_sha256: str = "",
               ascii: bool = False) -> dict[str, Any]:
    """Write `mesh` to `out` (generator: the STL header, ≤ 80 characters, or the 3MF's metadata, with the source's
    sha256); {path, bytes} and, for 3MF, lib3mf's manifold-and-oriented verdict per object."""
    out = Path(out)
    ext = out.suffix.lower()
    if ext not in EXTENSIONS:
        raise AmprepError(ErrorCode.INVALID_PARAMETER, f"output must end in .stl or .3mf, got '{out.name}'")
    written: dict[str, Any] = {"path": str(out)}
    try:
        if ext == ".stl":
            write_stl(mesh, out, ascii=ascii, header=generator[:80])
        else:
            meta = {"generator": generator[:80], "units": "millimetre", "source_sha256": source_sha256}
            written["objects_manifold_and_oriented"] = write_3mf(mesh, out, meta)
    except OSError as exc:
        raise AmprepError(ErrorCode.WRITE_FAILED, f"cannot write {out}: {exc.strerror}") from None
    written["bytes"] = out.stat().st_size
    return written
