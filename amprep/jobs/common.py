"""What every job shares: its input read by the format its bytes show, the report's `input` section, the file hash
and the provenance record."""

from __future__ import annotations

import hashlib
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.cad.read import CadModel
from amprep.geometry.core.formats import CAD_FORMATS, sniff_path
from amprep.geometry.core.mesh import Mesh
from amprep.geometry.io.stl import read_stl
from amprep.geometry.meshing.params import MeshParams


def _version(pkg: str) -> str:
    try:
        return version(pkg)
    except PackageNotFoundError:
        return "unknown"


def provenance(params: MeshParams | None = None) -> dict[str, Any]:
    """What made a result: amprep, OCCT and cadquery versions and the meshing parameters (after defaults)."""
    ocp = _version("cadquery-ocp")
    out: dict[str, Any] = {
        "amprep": _version("amprep"),
        "occt": ".".join(ocp.split(".")[:3]) if ocp != "unknown" else ocp,
        "cadquery_ocp": ocp,
        "cadquery": _version("cadquery"),
    }
    if params is not None:
        out["params"] = {k: getattr(params, k) for k in params.__dataclass_fields__}
    return out


def sha256_file(path: str | Path) -> str:
    """Hex SHA-256 of a file's bytes."""
    h = hashlib.sha256()
    with Path(path).open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def input_of(path: str | Path) -> tuple[str, dict[str, Any]]:
    """(format recognised from the bytes, the report's `input` section so far: format and sha256)."""
    fmt = sniff_path(path)
    return fmt, {"format": fmt, "sha256": sha256_file(path)}


def is_cad(fmt: str) -> bool:
    """True for the B-rep formats (meshed by the pipeline), False for a mesh format (STL)."""
    return fmt in CAD_FORMATS


def model_info(model: CadModel) -> dict[str, Any]:
    """The `input` keys a CAD model adds: its declared unit, solids and faces, and the faces the reader left out
    (`unsupported_geometry`: ACIS faces on surfaces with no exact or stored form; empty for other formats)."""
    return {"units": model.units, "solids": model.solids, "faces": len(model.faces),
            "unsupported_geometry": [dict(f) for f in model.unsupported]}


#: the `input` keys of an STL, which declares no unit, solids or faces
STL_INFO = {"units": "none", "solids": None, "faces": None}


def read_mesh(path: str | Path, what: str = "the STL") -> Mesh:
    """An STL's mesh; empty_model when it holds no triangles."""
    mesh = read_stl(path)
    if mesh.n_triangles == 0:
        raise AmprepError(ErrorCode.EMPTY_MODEL, f"{what} holds no triangles")
    return mesh
