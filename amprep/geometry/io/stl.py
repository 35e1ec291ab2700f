"""STL read and write (binary and ASCII), vectorised."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.core.mesh import Mesh
from amprep.geometry.core.vectors import group_rows, unit_normals

_BINARY = np.dtype([("normal", "<f4", 3), ("corners", "<f4", (3, 3)), ("attr", "<u2")])


def stl_bytes(mesh: Mesh, ascii: bool = False, header: str = "amprep") -> bytes:
    """The mesh as STL: binary (80-byte header, float32) or ASCII (`solid <header>` … `endsolid`)."""
    corners = mesh.corners
    normals = unit_normals(corners)[0]
    if ascii:
        rows = np.concatenate([normals[:, None, :], corners], axis=1).reshape(-1, 12)
        body = "".join(
            "facet normal {:.9e} {:.9e} {:.9e}\n outer loop\n  vertex {:.9e} {:.9e} {:.9e}\n  vertex {:.9e} {:.9e} {:.9e}\n"
            "  vertex {:.9e} {:.9e} {:.9e}\n endloop\nendfacet\n".format(*tuple(r)) for r in rows
        ) if len(rows) else ""
        name = header.replace("\n", " ")
        return f"solid {name}\n{body}endsolid {name}\n".encode()
    return _binary_head(mesh, header) + _binary_records(corners, normals).tobytes()


def _binary_head(mesh: Mesh, header: str) -> bytes:
    """The 80-byte header (never starting "solid", which would make it look ASCII) and the triangle count."""
    head = header.encode("ascii", "replace")[:80].ljust(80, b" ")
    if head.lower().startswith(b"solid"):
        head = (b"amprep " + head)[:80]
    return head + np.uint32(mesh.n_triangles).tobytes()


def _binary_records(corners: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(m,) binary STL records: normal, corners (float32), attribute 0."""
    data = np.zeros(len(corners), _BINARY)
    data["normal"] = normals
    data["corners"] = corners
    return data


def write_stl(mesh: Mesh, path: str | Path, ascii: bool = False, header: str = "amprep") -> None:
    """Write the mesh as STL to a file (binary: the records straight from their array, no copy into one bytes)."""
    if ascii:
        Path(path).write_bytes(stl_bytes(mesh, ascii, header))
        return
    corners = mesh.corners
    with Path(path).open("wb") as fh:
        fh.write(_binary_head(mesh, header))
        _binary_records(corners, unit_normals(corners)[0]).tofile(fh)


def _index(corners: np.ndarray) -> Mesh:
    """Indexed mesh from (m, 3, 3) corners: vertices are identical coordinate triples (an STL's only topology)."""
    flat = np.ascontiguousarray(corners.reshape(-1, 3), dtype=np.float64)
    group, first = group_rows(flat)
    return Mesh.from_arrays(flat[first], group.reshape(-1, 3))


def read_stl(path: str | Path) -> Mesh:
    """Read a binary or ASCII STL; identical coordinates are one vertex (no merging of nearby ones)."""
    raw = Path(path).read_bytes()
    if len(raw) >= 84:
        n = int(np.frombuffer(raw, "<u4", 1, 80)[0])
        if 84 + 50 * n == len(raw):
            data = np.frombuffer(raw, _BINARY, n, 84)
            corners = data["corners"].astype(np.float64)
            if not np.isfinite(corners).all():
                raise AmprepError(ErrorCode.UNREADABLE_MESH, "the STL holds non-finite coordinates")
            return _index(corners)
    text = raw.decode("ascii", "replace")
    if not text.lstrip().lower().startswith("solid"):
        raise AmprepError(ErrorCode.UNREADABLE_MESH, "neither a binary nor an ASCII STL")
    nums = re.findall(r"vertex\s+(\S+)\s+(\S+)\s+(\S+)", text)
    if not nums:
        raise AmprepError(ErrorCode.EMPTY_MODEL, "the STL holds no triangles")
    try:
        coords = np.array(nums, dtype=np.float64)
    except ValueError:
        raise AmprepError(ErrorCode.UNREADABLE_MESH, "the ASCII STL has a malformed vertex line") from None
    if len(coords) % 3 or not np.isfinite(coords).all():
        raise AmprepError(ErrorCode.UNREADABLE_MESH, "the ASCII STL has incomplete facets or bad numbers")
    return _index(coords.reshape(-1, 3, 3))
