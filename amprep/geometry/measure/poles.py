"""Poles of a (u,v) tessellation: corners at a cone's apex or a sphere's pole, where one parameter is free and a
triangle's (u,v) folds unless that corner takes the middle of its triangle's other corners in it."""

from __future__ import annotations

import numpy as np

from amprep.geometry.cad.surfaces import Surface, tangents
from amprep.geometry.core.mesh import NO_TOPOLOGY, ON_BREP_VERTEX, Mesh

PoleCorners = tuple[np.ndarray, np.ndarray, np.ndarray]


def pole_vertices(verts: np.ndarray, tris: np.ndarray, uvs: np.ndarray, fids: np.ndarray, vdim: np.ndarray,
                  surfaces: dict[int, Surface], faces: np.ndarray) -> dict[tuple[int, int], int]:
    """{(vertex, face): free (u,v) coordinate} of the poles among the B-rep vertices of `faces` (any vertex of a mesh
    with no B-rep topology: a user's STL placed on its CAD): a vertex whose corners in the face differ in one
    coordinate only, and whose surface point halfway between two of them is the vertex itself (a cone's apex, a
    sphere's pole; on a seam the point halfway is elsewhere)."""
    r, c = np.nonzero(np.isin(vdim[tris], (ON_BREP_VERTEX, NO_TOPOLOGY)) & np.isin(fids, faces)[:, None])
    if not len(r):
        return {}
    key = tris[r, c].astype(np.int64) * (int(fids.max()) + 1) + fids[r]  # one group per (vertex, face)
    order = np.argsort(key, kind="stable")
    start = np.flatnonzero(np.r_[True, np.diff(key[order]) != 0])
    uv = uvs[r, c][order]
    lo, hi = np.minimum.reduceat(uv, start, axis=0), np.maximum.reduceat(uv, start, axis=0)
    one_way = ((hi - lo) > 1e-9).sum(axis=1) == 1
    v, f = tris[r, c][order][start][one_way], fids[r][order][start][one_way]
    half = np.empty((len(v), 3))
    for face in np.unique(f):
        sel = f == face
        half[sel] = surfaces[int(face)].evaluate(0.5 * (lo + hi)[one_way][sel])
    at_vertex = np.linalg.norm(half - verts[v], axis=1) <= 1e-6 * (1.0 + np.abs(verts[v]).max(axis=1))
    free = np.argmax((hi - lo)[one_way], axis=1)
    found = {(int(a), int(b)): int(k) for a, b, k in zip(v[at_vertex], f[at_vertex], free[at_vertex], strict=True)}
    same = ((hi - lo) > 1e-9).sum(axis=1) == 0  # one (u,v) in every corner (a projected STL vertex): S_u or S_v ≈ 0
    v, f = tris[r, c][order][start][same], fids[r][order][start][same]
    for face in np.unique(f):
        sel = np.flatnonzero(f == face)
        free = degenerate_direction(surfaces[int(face)], lo[same][sel])
        found.update(((int(v[i]), int(face)), int(k)) for i, k in zip(sel[free >= 0], free[free >= 0], strict=True))
    return found


def degenerate_direction(surface: Surface, uv: np.ndarray) -> np.ndarray:
    """(n,) 0 where S_u ≈ 0 at (n, 2) uv (u free: an apex, a pole), 1 where S_v ≈ 0, −1 elsewhere (surfaces.tangents),
    ≈ 0 meaning under 1e-6 of the other direction's."""
    su, sv = (np.linalg.norm(t, axis=1) for t in tangents(surface, uv))
    return np.where(su <= 1e-6 * sv, 0, np.where(sv <= 1e-6 * su, 1, -1))


def with_poles_centred(mesh: Mesh, faces: np.ndarray, surfaces: dict[int, Surface]) -> Mesh:
    """The mesh with each pole corner of `faces` given the middle of its triangle's other corners in its free
    coordinate (pole_vertices, centre_poles): a user's STL placed on its CAD has one (u,v) per apex, which SMA's
    (u,v) centroids and VTA's would fold about."""
    if mesh.uv is None:
        return mesh
    vdim = vertex_keys(mesh)[0]
    poles = pole_vertices(mesh.vertices, mesh.triangles, mesh.uv, mesh.face_ids, vdim, surfaces, np.asarray(faces))
    n_faces = int(mesh.face_ids.max()) + 1 if mesh.n_triangles else 1
    return mesh.with_arrays(uv=centre_poles(mesh.uv, pole_corners(mesh.triangles, mesh.face_ids, poles, n_faces)))


def pole_corners(tris: np.ndarray, fids: np.ndarray, poles: dict[tuple[int, int], int],
                  n_faces: int) -> PoleCorners:
    """(rows, cols, free coordinate) of the triangle corners that are poles of their triangle's face."""
    if not poles:
        empty = np.zeros(0, np.int64)
        return empty, empty, empty
    keys = np.array([v * n_faces + f for v, f in poles], np.int64)
    free = np.array(list(poles.values()), np.int64)
    order = np.argsort(keys)
    keys, free = keys[order], free[order]
    corner = tris.astype(np.int64) * n_faces + fids[:, None]
    at = np.minimum(np.searchsorted(keys, corner), len(keys) - 1)
    r, c = np.nonzero(keys[at] == corner)
    return r, c, free[at[r, c]]


def centre_poles(uvs: np.ndarray, pole: PoleCorners) -> np.ndarray:
    """(m, 3, 2) the corners' (u,v) with each pole corner (`pole`: pole_corners) given, in its free coordinate, the
    mean of the triangle's two other corners' (where the triangle leaves the pole), so the (u,v) triangle maps onto
    the 3D one without a fold."""
    out = uvs.copy()
    r, c, k = pole
    out[r, c, k] = 0.5 * (uvs[r, (c + 1) % 3, k] + uvs[r, (c + 2) % 3, k])
    return out


def vertex_keys(mesh: Mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(dim, entity, param) (n,) of every vertex: the mesh's own, or −1, −1, nan where it has none."""
    return (mesh.vertex_dim if mesh.vertex_dim is not None else np.full(mesh.n_vertices, -1, np.int8),
            mesh.vertex_entity if mesh.vertex_entity is not None else np.full(mesh.n_vertices, -1, np.int32),
            mesh.vertex_param if mesh.vertex_param is not None else np.full(mesh.n_vertices, np.nan))


def with_free_corners_centred(mesh: Mesh, surfaces: dict[int, Surface], snap: float) -> Mesh:
    """The mesh with each corner that can take the middle of its triangle's other two corners in u (or in v) while
    its surface point moves by at most `snap` given that middle: at a pole or apex one parameter is free, and a user's
    STL, whose corners are projected one triangle at a time, gets there whatever value its projection ended at (an
    arbitrary u, or the far side of a closed B-spline's seam), so its (u,v) triangle spans the domain."""
    if mesh.uv is None:
        return mesh
    uv = mesh.uv.copy()
    for fid in np.unique(mesh.face_ids[mesh.face_ids >= 0]):
        t = np.flatnonzero(mesh.face_ids == fid)
        surf = surfaces[int(fid)]
        here = surf.evaluate(uv[t].reshape(-1, 2)).reshape(-1, 3, 3)
        for k in (0, 1):
            alt = uv[t].copy()
            alt[:, :, k] = 0.5 * (np.roll(uv[t][:, :, k], -1, axis=1) + np.roll(uv[t][:, :, k], 1, axis=1))
            moved = np.linalg.norm(surf.evaluate(alt.reshape(-1, 2)).reshape(-1, 3, 3) - here, axis=2)
            free = moved <= snap
            r, c = np.nonzero(free)
            uv[t[r], c, k] = alt[r, c, k]
    return mesh.with_arrays(uv=uv)
