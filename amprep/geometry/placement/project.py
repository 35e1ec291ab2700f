"""A user's STL on its CAD: which face each triangle tessellates, and each corner's (u,v) by projection."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from amprep.geometry.cad.surfaces import Surface, project_points, tangents
from amprep.geometry.core.mesh import FaceInfo, Mesh
from amprep.geometry.core.vectors import cross
from amprep.geometry.measure.chordal import barycentric_grid


@dataclass(frozen=True)
class ReferenceCloud:
    """Dense points on a CAD tessellation: (p, 3) xyz, (p,) face id, (p, 2) (u,v) on that face."""

    points: np.ndarray
    face: np.ndarray
    uv: np.ndarray

    @classmethod
    def of(cls, mesh: Mesh, spacing: float, max_order: int = 32) -> ReferenceCloud:
        """Barycentric grids on every triangle of a tessellation that carries (u,v), of order ⌈longest edge /
        spacing⌉ (at least 2, at most max_order), so large flat triangles are sampled as densely as small ones."""
        keep = np.flatnonzero(mesh.face_ids >= 0)
        corners = mesh.corners[keep]
        longest = np.linalg.norm(np.roll(corners, -1, axis=1) - corners, axis=2).max(axis=1)
        order = np.clip(np.ceil(longest / spacing), 2, max_order).astype(np.int64)
        pts, face, uv = [], [], []
        for k in np.unique(order):
            sel = keep[order == k]
            w = barycentric_grid(int(k))
            pts.append(np.einsum("pk,mkd->mpd", w, mesh.corners[sel]).reshape(-1, 3))
            face.append(np.repeat(mesh.face_ids[sel], len(w)))
            uv.append(np.einsum("pk,mkd->mpd", w, mesh.uv[sel]).reshape(-1, 2) if mesh.uv is not None
                      else np.zeros((len(sel) * len(w), 2)))
        return cls(np.concatenate(pts), np.concatenate(face), np.concatenate(uv))


def surface_normals(surface: Surface, uv: np.ndarray) -> np.ndarray:
    """(n, 3) unit normals S_u × S_v / |S_u × S_v| at (n, 2) uv; zero where the two are parallel (a pole, an apex)."""
    su, sv = tangents(surface, np.asarray(uv, float))
    n = cross(su, sv)
    size = np.linalg.norm(n, axis=1, keepdims=True)
    scale = np.linalg.norm(su, axis=1, keepdims=True) * np.linalg.norm(sv, axis=1, keepdims=True)
    return np.where(size > 1e-9 * scale, n / np.where(size > 0, size, 1.0), 0.0)


def unwrap_corners(uv: np.ndarray, periods: tuple[float | None, float | None]) -> np.ndarray:
    """(m, k, 2) points' parameters with each periodic one moved by whole periods next to one point's, the point whose
    choice spans the least: at a cone's apex or a sphere's pole u is arbitrary, and the rim's corners must not be
    wrapped about it."""
    out = np.array(uv, dtype=float)
    for c, per in enumerate(periods):
        if per:
            ref = out[:, :, c]  # (m, k): every point tried as the one the others move next to
            moved = ref[:, :, None] + (ref[:, None, :] - ref[:, :, None] + per / 2) % per - per / 2  # (m, ref, k)
            best = np.argmin(moved.max(axis=2) - moved.min(axis=2), axis=1)
            out[:, :, c] = moved[np.arange(len(out)), best]
    return out


def _project_faces(points: np.ndarray, face: np.ndarray, cloud: ReferenceCloud, surfaces: dict[int, Surface],
                   trees: dict[int, tuple[np.ndarray, cKDTree]]) -> tuple[np.ndarray, np.ndarray]:
    """((m, k, 2) uv, (m, k) distance) of each triangle's k points (m, k, 3) (its corners, then its centroid)
    projected on the surface of its given face, the periodic parameters unwrapped together (unwrap_corners)."""
    m, k = points.shape[:2]
    uv = np.zeros((m, k, 2))
    dist = np.full((m, k), np.inf)
    for fid in np.unique(face):
        surf = surfaces.get(int(fid))
        if surf is None or fid < 0:
            continue
        if fid not in trees:
            own = np.flatnonzero(cloud.face == fid)
            trees[int(fid)] = (own, cKDTree(cloud.points[own]))
        own, tree = trees[int(fid)]
        tris = np.flatnonzero(face == fid)
        pts = points[tris].reshape(-1, 3)
        _, near = tree.query(pts)  # start each point at the nearest sample of the same face
        p_uv, d = project_points(surf, pts, cloud.uv[own[near]])
        uv[tris] = unwrap_corners(p_uv.reshape(-1, k, 2), surf.periods)
        dist[tris] = d.reshape(-1, k)
    return uv, dist


#: a triangle whose centroid lies within this × its longest edge of its face's surface is not tried on other faces:
#: the faces that pass as near are the same surface (a B-spline continuing a cylinder), one triangle's sag apart
ON_SURFACE = 0.02


def isolate(mesh: Mesh, cloud: ReferenceCloud, surfaces: dict[int, Surface], faces: tuple[FaceInfo, ...],
            tolerance: float, candidates: int = 6) -> tuple[Mesh, np.ndarray]:
    """Give each triangle of a (CAD-frame) mesh the CAD face it tessellates: the faces of the samples nearest its
    centroid are tried in order, the corners and centroid projected on each face's surface, and of the faces with
    every corner within `tolerance` of their surface the one nearest the centroid is kept (else face −1): corners
    alone do not tell a disc's triangle, its corners on the rim, from the cone or cylinder through that rim; the
    search stops at a face whose surface passes within ON_SURFACE × the longest edge of the centroid. Returns the mesh with
    face_ids, uv and faces, and (m, 3) corner distances to the chosen face's surface."""
    corners = mesh.corners
    m = len(corners)
    points = np.concatenate([corners, corners.mean(axis=1, keepdims=True)], axis=1)  # (m, 4, 3)
    _, near = cKDTree(cloud.points).query(points[:, 3], k=8 * candidates)
    near_faces = cloud.face[near]  # (m, k) faces of the nearest samples, nearest first
    face_ids = np.full(m, -1, np.int32)
    uv = np.zeros((m, 3, 2))
    dist = np.full((m, 3), np.inf)
    centre = np.full(m, np.inf)  # the centroid's distance to the chosen face's surface
    enough = ON_SURFACE * np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1)
    trees: dict[int, tuple[np.ndarray, cKDTree]] = {}
    todo = np.arange(m)
    tried = np.full((m, 1), -2, np.int64)
    for _ in range(candidates):
        if len(todo) == 0:
            break
        # the nearest face not tried yet, per triangle still searching
        nf = near_faces[todo]
        fresh = ~(nf[:, :, None] == tried[todo][:, None, :]).any(axis=2)
        has = fresh.any(axis=1)
        todo = todo[has]
        if len(todo) == 0:
            break
        pick = nf[has][np.arange(len(todo)), np.argmax(fresh[has], axis=1)]
        tried = np.concatenate([tried, np.full((m, 1), -2, np.int64)], axis=1)
        tried[todo, -1] = pick
        p_uv, d = _project_faces(points[todo], pick, cloud, surfaces, trees)
        fits = (d[:, :3] <= tolerance).all(axis=1) & (d[:, 3] < centre[todo])
        closer = (face_ids[todo] < 0) & (d[:, :3].max(axis=1) < dist[todo].max(axis=1))  # unmatched: the nearest
        take = fits | closer
        uv[todo[take]], dist[todo[take]] = p_uv[take, :3], d[take, :3]
        face_ids[todo[fits]], centre[todo[fits]] = pick[fits], d[fits, 3]
        todo = todo[~(centre[todo] <= enough[todo])]
    out = Mesh(mesh.vertices, mesh.triangles, face_ids, uv=uv,
               faces=tuple(FaceInfo(f.id, f.surface_type, f.solid, "stl") for f in faces))
    return out, dist
