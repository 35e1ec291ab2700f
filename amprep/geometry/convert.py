"""The conversion job: read any supported input, mesh CAD closed within tolerance, check, write STL or 3MF."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

import numpy as np

from .cad import CadModel, read_cad
from .checks import MeshChecks, check_mesh, float32_degenerate_count, manifold3d_accepts
from .errors import AmprepError, ErrorCode
from .forked import Forked
from .formats import CAD_FORMATS, sniff_path
from .io_3mf import write_3mf
from .io_stl import read_stl, write_stl
from .mesh import Mesh
from .mesher import MeshResult, mesh_model
from .progress import ProgressFn
from .read_ahead import read_and_mesh_ahead
from .tessellate import MeshParams


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


@dataclass(frozen=True, eq=False)
class ConvertResult:
    """A converted part: the mesh, its checks and how it was made (`meshing` is None for STL passthrough)."""

    mesh: Mesh
    input: dict[str, Any]
    checks: MeshChecks
    manifold3d: bool
    meshing: MeshResult | None
    provenance: dict[str, Any]
    notes: list[str] = field(default_factory=list)
    float32_degenerate: int = 0  # triangles degenerate only after rounding to the file's float32 coordinates

    def summary(self) -> dict[str, Any]:
        """JSON-ready summary of the conversion (the `convert` part of a job's report)."""
        c = self.checks
        out: dict[str, Any] = {
            "input": self.input,
            "mesh": {
                "triangles": c.triangles, "vertices": c.vertices, "watertight": c.closed and self.manifold3d,
                "closed": c.closed, "manifold3d": self.manifold3d, "boundary_edges": c.boundary_edges,
                "nonmanifold_edges": c.nonmanifold_edges, "misoriented_edges": c.misoriented_edges,
                "degenerate_triangles": c.degenerate_triangles, "duplicate_triangles": c.duplicate_triangles,
                "shells": c.shells, "volume": c.volume, "area": c.area,
                "float32_degenerate_triangles": self.float32_degenerate,
            },
            "provenance": self.provenance,
            "notes": self.notes,
        }
        if self.meshing is not None:
            m = self.meshing
            out["meshing"] = {
                "tolerance": m.tolerance,
                "max_chordal_error": m.max_error,
                "within_tolerance": bool(m.max_error <= m.tolerance * (1 + 1e-9)) if m.max_error == m.max_error else None,
                "fallback_faces": {str(k): v for k, v in sorted(m.fallback_faces.items())},
                "unmeshed_faces": list(m.unmeshed_faces),
            }
        return out


def load(path: str | Path) -> CadModel | Mesh:
    """A CadModel for STEP/IGES/BREP, a Mesh for STL; the format comes from the bytes."""
    fmt = sniff_path(path)
    if fmt in CAD_FORMATS:
        return read_cad(path, fmt)
    return read_stl(path)


#: output checks of a mesh this large run beside manifold3d's in a forked child (forking costs ~10 ms)
FORK_CHECKS_MIN = 100_000


def output_checks(mesh: Mesh) -> tuple[MeshChecks, int]:
    """(check_mesh, float32_degenerate_count) of a mesh."""
    degenerate = np.zeros(mesh.n_triangles, bool)
    checks = check_mesh(mesh, degenerate)
    return checks, float32_degenerate_count(mesh, degenerate)


def convert(path: str | Path, params: MeshParams = MeshParams(), progress: ProgressFn | None = None) -> ConvertResult:
    """Read `path` and return its closed mesh within tolerance (CAD) or its checked mesh (STL passthrough)."""
    params.validate()
    fmt = sniff_path(path)
    info: dict[str, Any] = {"format": fmt, "sha256": sha256_file(path)}
    notes: list[str] = []
    meshing = None
    if fmt in CAD_FORMATS:
        if progress:
            progress("reading", 0.0)
        model, meshed_at = read_and_mesh_ahead(path, fmt, params)
        info.update(units=model.units, solids=model.solids, faces=len(model.faces))
        if model.units == "none":
            notes.append("the file declares no length unit: read as millimetres")
        if model.sewn:
            notes.append("loose faces were sewn into shells")
        meshing = mesh_model(model, params, progress, meshed_at)
        mesh = meshing.mesh
        if meshing.unmeshed_faces:
            notes.append(f"{len(meshing.unmeshed_faces)} face(s) could not be meshed")
    else:
        mesh = read_stl(path)
        info.update(units="none", solids=None, faces=None)
        notes.append("STL input passed through: no unit in the file, values taken as millimetres")
    if mesh.n_triangles == 0:
        raise AmprepError(ErrorCode.EMPTY_MODEL, "the model produced no triangles")
    # our own checks in a forked child while manifold3d (which holds the GIL) runs here
    own = Forked(output_checks, mesh, fork=mesh.n_triangles >= FORK_CHECKS_MIN)
    ok3d = manifold3d_accepts(mesh)
    try:
        checks, rounded = own.result()
    except AmprepError:  # the child died: check here
        checks, rounded = output_checks(mesh)
    if rounded:
        notes.append(f"{rounded} triangle(s) become degenerate when rounded to the float32 coordinates STL and 3MF "
                     "store (a part far from the origin at a micron tolerance)")
    if not checks.closed:
        notes.append(f"the mesh is open: {checks.boundary_edges} boundary and {checks.nonmanifold_edges} non-manifold edges")
    return ConvertResult(mesh, info, checks, ok3d, meshing, provenance(params if meshing else None), notes, rounded)


def header_text(result: ConvertResult) -> str:
    """≤ 80-character STL header naming the tools and parameters that made the mesh."""
    p = result.provenance
    text = f"amprep {p['amprep']} occt {p['occt']} cq {p['cadquery']}"
    if result.meshing is not None:
        params = p["params"]
        text += f" tol {result.meshing.tolerance:g}mm ang {params['angular']:g} {params['algorithm']}"
    return text[:80]


def write_result(result: ConvertResult, out: str | Path, ascii: bool = False) -> dict[str, Any]:
    """Write the mesh by the output's extension (.stl binary or ASCII, .3mf); returns what was written."""
    out = Path(out)
    ext = out.suffix.lower()
    written: dict[str, Any] = {"path": str(out)}
    try:
        if ext == ".stl":
            write_stl(result.mesh, out, ascii=ascii, header=header_text(result))
        elif ext == ".3mf":
            meta = {"generator": header_text(result), "units": "millimetre",
                    "source_sha256": result.input.get("sha256", "")}
            written["objects_manifold_and_oriented"] = write_3mf(result.mesh, out, meta)
        else:
            raise AmprepError(ErrorCode.INVALID_PARAMETER, f"output must end in .stl or .3mf, got '{out.name}'")
    except OSError as exc:
        raise AmprepError(ErrorCode.WRITE_FAILED, f"cannot write {out}: {exc.strerror}") from None
    written["bytes"] = out.stat().st_size
    return written
