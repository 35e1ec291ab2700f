"""3MF writer (lib3mf): one closed mesh object per solid, millimetres, CAD face ids as triangle sets."""

from __future__ import annotations

import ctypes
import hashlib
import locale
import uuid
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path

import lib3mf
import numpy as np

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.core.mesh import Mesh

NAMESPACE = "http://amprep.dev/3mf/2026"


def _set_geometry(wrapper, obj, vertices: np.ndarray, triangles: np.ndarray) -> None:  # type: ignore[no-untyped-def]
    """lib3mf SetGeometry from numpy buffers (its own wrapper builds one ctypes object per vertex)."""
    v = np.ascontiguousarray(vertices, dtype=np.float32)
    t = np.ascontiguousarray(triangles, dtype=np.uint32)
    vbuf = (lib3mf.Position * len(v)).from_buffer(v)
    tbuf = (lib3mf.Triangle * len(t)).from_buffer(t)
    wrapper.checkError(obj, wrapper.lib.lib3mf_meshobject_setgeometry(
        obj._handle, ctypes.c_uint64(len(v)), vbuf, ctypes.c_uint64(len(t)), tbuf))


def split_objects(mesh: Mesh) -> list[tuple[str, np.ndarray]]:
    """(name, triangle indices) per solid (by the faces' solid ids); faces outside any solid form one object."""
    if not mesh.faces or (mesh.face_ids < 0).all():
        return [("mesh", np.arange(mesh.n_triangles))]
    solid_of_face = np.array([f.solid for f in mesh.faces])
    tri_solid = solid_of_face[mesh.face_ids]
    out = []
    for s in np.unique(tri_solid):
        out.append((f"solid {s + 1}" if s >= 0 else "open faces", np.flatnonzero(tri_solid == s)))
    return out


def _uuid(seed: str, what: str) -> str:
    """A UUID from the mesh's content and the element's role: the same mesh gives the same 3MF bytes (lib3mf would
    draw random ones)."""
    return str(uuid.uuid5(uuid.NAMESPACE_URL, f"amprep:{seed}:{what}"))


@contextmanager
def _locale_kept() -> Iterator[None]:
    """Restore the process's locale after lib3mf: its reader and writer set every category to "C" and leave it so,
    which turns a worker's default text encoding to ASCII for every later job (open() without an encoding)."""
    saved = locale.setlocale(locale.LC_ALL)
    try:
        yield
    finally:
        locale.setlocale(locale.LC_ALL, saved)


def write_3mf(mesh: Mesh, path: str | Path, metadata: Mapping[str, str] | None = None) -> list[bool]:
    """Write a 3MF; returns lib3mf's IsManifoldAndOriented per object (vertices shared within an object)."""
    with _locale_kept():
        return _write(mesh, path, metadata)


def _write(mesh: Mesh, path: str | Path, metadata: Mapping[str, str] | None) -> list[bool]:
    wrapper = lib3mf.get_wrapper()
    model = wrapper.CreateModel()
    model.SetUnit(lib3mf.ModelUnit.MilliMeter)
    group = model.GetMetaDataGroup()
    for key, value in (metadata or {}).items():
        group.AddMetaData(NAMESPACE, key, str(value), "xs:string", False)
    seed = hashlib.sha256(mesh.vertices.tobytes() + mesh.triangles.tobytes()).hexdigest()
    model.SetBuildUUID(_uuid(seed, "build"))
    verdicts = []
    for name, tri_idx in split_objects(mesh):
        tris = mesh.triangles[tri_idx]
        used, local = np.unique(tris, return_inverse=True)
        obj = model.AddMeshObject()
        obj.SetName(name)
        _set_geometry(wrapper, obj, mesh.vertices[used], local.reshape(-1, 3))
        face_ids = mesh.face_ids[tri_idx]
        if (face_ids >= 0).any():
            order = np.argsort(face_ids, kind="stable")
            bounds = np.flatnonzero(np.diff(face_ids[order])) + 1
            for chunk in np.split(order, bounds):
                fid = int(face_ids[chunk[0]])
                ts = obj.AddTriangleSet(f"face-{fid}", f"CAD face {fid}")
                ts.SetTriangleList([int(i) for i in chunk])
        verdicts.append(bool(obj.IsManifoldAndOriented()))
        obj.SetUUID(_uuid(seed, f"object {name}"))
        model.AddBuildItem(obj, wrapper.GetIdentityTransform()).SetUUID(_uuid(seed, f"item {name}"))
    try:
        model.QueryWriter("3mf").WriteToFile(str(path))
    except lib3mf.ELib3MFException as exc:
        raise AmprepError(ErrorCode.WRITE_FAILED, f"lib3mf could not write the 3MF: {exc}") from None
    return verdicts


def read_3mf_objects(path: str | Path) -> list[tuple[str, np.ndarray, np.ndarray, bool]]:
    """(name, vertices (n, 3), triangles (m, 3), manifold-and-oriented) of each mesh object of a 3MF."""
    wrapper = lib3mf.get_wrapper()
    model = wrapper.CreateModel()
    with _locale_kept():
        model.QueryReader("3mf").ReadFromFile(str(path))
    out = []
    it = model.GetMeshObjects()
    while it.MoveNext():
        obj = it.GetCurrentMeshObject()
        verts = np.array([list(v.Coordinates) for v in obj.GetVertices()], dtype=float).reshape(-1, 3)
        tris = np.array([list(t.Indices) for t in obj.GetTriangleIndices()], dtype=np.int64).reshape(-1, 3)
        out.append((obj.GetName(), verts, tris, bool(obj.IsManifoldAndOriented())))
    return out
