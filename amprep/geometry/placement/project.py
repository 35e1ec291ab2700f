"""A user's STL on its CAD: which face each triangle tessellates, and each corner's (u,v) by projection."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.spatial import cKDTree

from amprep.geometry.cad.surfaces import Surface, project_settled
from amprep.geometry.core.checks import triangle_areas
from amprep.geometry.core.mesh import FaceInfo, Mesh
from amprep.geometry.core.progress import checkpoint


@dataclass(frozen=True)
class ReferenceCloud:
    """Dense points on a CAD tessellation: (p, 3) xyz, (p,) face id, (p, 2) (u,v) on that face; `slack` a bound on
    how much nearer than its nearest sample a point can be to its face (two steps of the spacing the points were
    placed at, and the tessellation's own chordal error)."""

    points: np.ndarray
    face: np.ndarray
    uv: np.ndarray
    slack: float = np.inf

    @cached_property
    def tree(self) -> cKDTree:
        """The k-d tree of the points, built once for the alignment and every isolate round."""
        return cKDTree(self.points)

    @cached_property
    def _by_face(self) -> dict[int, np.ndarray]:
        """Each face id's sample indices (ascending), from one stable sort of the samples' faces."""
        order = np.argsort(self.face, kind="stable")
        faces, first = np.unique(self.face[order], return_index=True)
        return {int(f): own for f, own in zip(faces, np.split(order, first[1:]), strict=True)}

    @cached_property
    def _face_trees(self) -> dict[int, tuple[np.ndarray, cKDTree | None]]:
        """face_tree's results so far."""
        return {}

    def face_tree(self, fid: int) -> tuple[np.ndarray, cKDTree | None]:
        """((s,) indices of face fid's samples, the k-d tree of their points), made once per face (every isolate
        round and candidate asks again); no samples: an empty index and None."""
        if fid not in self._face_trees:
            own = self._by_face.get(fid, np.zeros(0, np.int64))
            self._face_trees[fid] = (own, cKDTree(self.points[own]) if len(own) else None)
        return self._face_trees[fid]

    @classmethod
    def of(cls, mesh: Mesh, spacing: float, max_points: int = 4_000_000, error: float = np.inf) -> ReferenceCloud:
        """Points on every triangle of a tessellation that carries (u,v), no surface point farther than about
        `spacing` from one (row_samples), the spacing widened when they would exceed max_points; `error` the
        tessellation's largest chordal error (unknown: no point is ruled out by its distance to the samples)."""
        keep = np.flatnonzero(mesh.face_ids >= 0)
        tri, w, step = row_samples(mesh.corners[keep], spacing, max_points)
        sel = keep[tri]
        pts = np.einsum("pk,pkd->pd", w, mesh.corners[sel])
        uv = np.einsum("pk,pkd->pd", w, mesh.uv[sel]) if mesh.uv is not None else np.zeros((len(sel), 2))
        return cls(pts, mesh.face_ids[sel], uv, 2 * step + error)


def row_samples(corners: np.ndarray, spacing: float, max_points: int) -> tuple[np.ndarray, np.ndarray, float]:
    """((p,) triangle, (p, 3) barycentric weights, the spacing used) of points on (m, 3, 3) triangles in rows parallel to each one's
    longest edge, ⌈height / spacing⌉ rows (at least 2) and ⌈row length / spacing⌉ + 1 points a row (the apex one):
    a sliver 300 mm long and 1 mm high gets two rows along its length, where a barycentric grid fine enough along it
    would put (300 / spacing)² / 2 points on it. Spacing widened by √(count / max_points) while over max_points."""
    m = len(corners)
    edge = np.linalg.norm(np.roll(corners, -1, axis=1) - corners, axis=2)  # (m, 3): edge s is corner s → s+1
    base = np.argmax(edge, axis=1)
    length = edge[np.arange(m), base]
    height = 2 * triangle_areas(corners) / np.maximum(length, 1e-300)
    step = max(float(spacing), 1e-12)
    for _ in range(8):
        n_rows = np.maximum(np.ceil(height / step), 2).astype(np.int64)
        row_tri = np.repeat(np.arange(m), n_rows + 1)
        j = np.arange(len(row_tri)) - np.repeat(np.cumsum(n_rows + 1) - (n_rows + 1), n_rows + 1)
        f = j / n_rows[row_tri]  # 0 on the longest edge, 1 at the apex
        per_row = np.where(f < 1, np.ceil((1 - f) * length[row_tri] / step).astype(np.int64) + 1, 1)
        total = int(per_row.sum())
        if total <= max_points:
            break
        step *= np.sqrt(total / max_points)
    row = np.repeat(np.arange(len(row_tri)), per_row)
    i = np.arange(total) - np.repeat(np.cumsum(per_row) - per_row, per_row)
    g = i / np.maximum(per_row[row] - 1, 1)
    fr = f[row]
    w = np.zeros((total, 3))
    tri = row_tri[row]
    a = base[tri]  # the longest edge runs corner a → a + 1; the apex is a + 2
    w[np.arange(total), a] = (1 - fr) * (1 - g)
    w[np.arange(total), (a + 1) % 3] = (1 - fr) * g
    w[np.arange(total), (a + 2) % 3] = fr
    return tri, w, step


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


def with_free_corners_centred(mesh: Mesh, surfaces: dict[int, Surface], snap: float) -> Mesh:
    """The mesh with each corner that can take the middle of its triangle's other two corners in u (or in v) while
    its surface point moves by at most `snap` given that middle: at a pole or apex one parameter is free, and a user's
    STL, whose corners are projected one triangle at a time, gets there whatever value its projection ended at (an
    arbitrary u, or the far side of a closed B-spline's seam), so its (u,v) triangle spans the domain."""
    if mesh.uv is None:
        return mesh
    uv = mesh.uv.copy()
    for fid in np.unique(mesh.face_ids[mesh.face_ids >= 0]):
        checkpoint()
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


#: projections stop once no point moves by this × the face's (u,v) extent: a corner on its surface converges
#: quadratically and is then exact to rounding, a centroid off it (by the triangle's sag) converges linearly to a noise
#: floor of about 1e-11 set by the difference steps, and its distance, at a minimum, errs by the square of the rest
SETTLE = 1e-9
#: further starts (the next nearest samples of the face) for a point whose projection did not settle
RESTARTS = 3


def _project_faces(points: np.ndarray, face: np.ndarray, cloud: ReferenceCloud, surfaces: dict[int, Surface],
                   tolerance: float = np.inf, restarts: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """((m, k, 2) uv, (m, k) distance) of each triangle's k points (m, k, 3) (its corners, then its centroid)
    projected on the surface of its given face, the periodic parameters unwrapped together (unwrap_corners); a
    triangle with a corner farther than `tolerance` + the cloud's slack from every sample of the face cannot be within
    `tolerance` of it and is not projected (distance inf); `restarts` as _from_samples'."""
    m, k = points.shape[:2]
    uv = np.zeros((m, k, 2))
    dist = np.full((m, k), np.inf)
    for fid in np.unique(face):
        checkpoint()  # a face's projections cost a few ms; a million-triangle STL has a cancel seen between them
        surf = surfaces.get(int(fid))
        if surf is None or fid < 0:
            continue
        own, tree = cloud.face_tree(int(fid))
        if tree is None:
            continue
        tris = np.flatnonzero(face == fid)
        apart, near = tree.query(points[tris].reshape(-1, 3))  # start each point at the nearest sample of the face
        reachable = (apart.reshape(-1, k)[:, :3] <= tolerance + cloud.slack).all(axis=1)
        tris, near = tris[reachable], near.reshape(-1, k)[reachable].ravel()
        if not len(tris):
            continue
        p_uv, d = _from_samples(surf, points[tris].reshape(-1, 3), near, own, tree, cloud.uv, tolerance, restarts)
        uv[tris] = unwrap_corners(p_uv.reshape(-1, k, 2), surf.periods)
        dist[tris] = d.reshape(-1, k)
    return uv, dist


def _from_samples(surf: Surface, pts: np.ndarray, near: np.ndarray, own: np.ndarray, tree: cKDTree,
                  sample_uv: np.ndarray, tolerance: float = np.inf, restarts: int = RESTARTS) -> tuple[np.ndarray, np.ndarray]:
    """((n, 2) uv, (n,) distance) of points (n, 3) projected on a face's surface from the (u,v) of their nearest
    samples `near` (n,) (indices into the face's samples `own`, held in `tree`); a point that has not settled (a full
    step from an apex the face's bounds hold it at throws it back where it came from) within `tolerance` of the
    surface, where the face would take it with that (u,v), starts again from each of its next `restarts` nearest
    samples, and the nearest foot found is kept (most points that do not settle are far off a face tried for them)."""
    uv, dist, settled = project_settled(surf, pts, sample_uv[own[near]], within=True, settle=SETTLE)
    again = np.flatnonzero(~settled & (dist <= tolerance))
    k = min(restarts + 1, len(own))
    if not len(again) or k < 2:
        return uv, dist
    _, alt = tree.query(pts[again], k=k)
    for j in range(1, k):
        a_uv, a_dist, _ = project_settled(surf, pts[again], sample_uv[own[alt[:, j]]], within=True, settle=SETTLE)
        better = a_dist < dist[again]
        uv[again[better]], dist[again[better]] = a_uv[better], a_dist[better]
    return uv, dist


#: points per k-d tree query of nearest_faces (a cancel is looked for between queries)
QUERY_BLOCK = 200_000


def nearest_faces(cloud: ReferenceCloud, corners: np.ndarray, k: int) -> np.ndarray:
    """(m, 4·⌈k/4⌉) faces of the cloud's samples nearest each triangle's centroid and edge midpoints ((m, 3, 3)
    corners), ⌈k/4⌉ for each point, nearest first: a long strip's centroid lies by the face it borders, whose samples
    can be all those nearest it, while its own face's lie nearest its other edge."""
    mids = 0.5 * (corners + np.roll(corners, -1, axis=1))
    points = np.concatenate([corners.mean(axis=1, keepdims=True), mids], axis=1)  # (m, 4, 3)
    each = -(-k // points.shape[1])
    flat = points.reshape(-1, 3)
    dist, near = np.empty((len(flat), each)), np.empty((len(flat), each), np.int64)
    for s in range(0, len(flat), QUERY_BLOCK):  # bounded calls: a cancel or time limit seen between them
        checkpoint()
        d, i = cloud.tree.query(flat[s:s + QUERY_BLOCK], k=each)
        dist[s:s + QUERY_BLOCK], near[s:s + QUERY_BLOCK] = d.reshape(len(d), each), i.reshape(len(i), each)
    dist, near = dist.reshape(len(corners), -1), near.reshape(len(corners), -1)
    order = np.argsort(dist, axis=1, kind="stable")
    return cloud.face[np.take_along_axis(near, order, axis=1)]


#: a triangle whose face passes through its corners and within this × its smallest height of its centroid is not
#: tried on other faces: the faces that pass as near are the same surface (a B-spline continuing a cylinder), one
#: triangle's sag apart (its height, not its length: a strip 300 mm long and 2 mm wide on a cylinder sags by its width)
ON_SURFACE = 0.02


def isolate(mesh: Mesh, cloud: ReferenceCloud, surfaces: dict[int, Surface], faces: tuple[FaceInfo, ...],
            tolerance: float, snap: float = 0.0, candidates: int = 6, restarts: int = 0) -> tuple[Mesh, np.ndarray]:
    """Give each triangle of a (CAD-frame) mesh the CAD face it tessellates: the faces of the samples nearest its
    centroid and edge midpoints are tried in order, the corners and centroid projected on each face's surface; of the
    faces with every corner within `tolerance` of their surface, one through all three corners (within `snap`: a
    tessellation's corners lie on its face) is preferred, and among equals the one nearest the centroid, else the one
    the triangle strays from least (the largest distance of its corners and centroid); no such face: −1. The corners
    alone do not tell a disc's triangle, its corners on the rim, from the cone or cylinder through that rim (the
    centroid does); the centroid alone gives a fillet's triangle to the plane it is tangent to, whose untrimmed surface
    passes nearer the centroid than the triangle's own sag while its far corner lies off that plane. The search stops
    at a face through the corners whose surface passes within ON_SURFACE × the triangle's smallest height of the
    centroid. `restarts`: further starts for a projection that does not settle (_from_samples; the final isolation
    asks for them, the polish rounds, whose far corners are trimmed, do not). Returns the mesh with face_ids, uv and
    faces, and (m, 3) corner distances to the chosen face's surface."""
    corners = mesh.corners
    m = len(corners)
    points = np.concatenate([corners, corners.mean(axis=1, keepdims=True)], axis=1)  # (m, 4, 3)
    near_faces = nearest_faces(cloud, corners, 8 * candidates)
    face_ids = np.full(m, -1, np.int32)
    uv = np.zeros((m, 3, 2))
    dist = np.full((m, 3), np.inf)
    rank = np.full((m, 2), np.inf)  # of the chosen face: (0 through the corners else 1, centroid's distance or stray)
    longest = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1)
    enough = ON_SURFACE * 2 * triangle_areas(corners) / np.maximum(longest, 1e-300)  # × its smallest height
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
        p_uv, d = _project_faces(points[todo], pick, cloud, surfaces, tolerance, restarts)
        through = d[:, :3].max(axis=1) <= snap
        new = np.stack([np.where(through, 0.0, 1.0), np.where(through, d[:, 3], d.max(axis=1))], axis=1)
        old = rank[todo]
        better = (new[:, 0] < old[:, 0]) | ((new[:, 0] == old[:, 0]) & (new[:, 1] < old[:, 1]))
        fits = (d[:, :3] <= tolerance).all(axis=1) & better
        closer = (face_ids[todo] < 0) & (d[:, :3].max(axis=1) < dist[todo].max(axis=1))  # unmatched: the nearest
        take = fits | closer
        uv[todo[take]], dist[todo[take]] = p_uv[take, :3], d[take, :3]
        face_ids[todo[fits]], rank[todo[fits]] = pick[fits], new[fits]
        todo = todo[~((rank[todo, 0] == 0) & (rank[todo, 1] <= enough[todo]))]
    out = Mesh(mesh.vertices, mesh.triangles, face_ids, uv=uv,
               faces=tuple(FaceInfo(f.id, f.surface_type, f.solid, "stl") for f in faces))
    return out, dist
