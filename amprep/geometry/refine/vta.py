"""VTA, the Vertex Translation Algorithm the thesis compares SMA with: per iteration, every triangle of a chosen face
gets one new vertex, S(u,v) at the interior sample point of largest chordal error, and becomes three triangles.
No edge is split, so contour and inner edges stay as they are and a closed mesh stays closed."""

from __future__ import annotations

import numpy as np

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.cad.surfaces import Surface
from amprep.geometry.core.mesh import IN_FACE, Mesh
from amprep.geometry.core.progress import checkpoint
from amprep.geometry.core.vectors import unit_normals
from amprep.geometry.measure.chordal import barycentric_grid
from amprep.geometry.refine.sma import Refinement


def _interior_grid(order: int) -> np.ndarray:
    """(p, 3) barycentric weights of the order-k grid with every weight > 0 (k ≥ 3)."""
    w = barycentric_grid(order)
    return w[(w > 0).all(axis=1)]


def _worst_points(corners: np.ndarray, uv: np.ndarray, surf: Surface, w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """((k, 2) uv, (k, 3) S(uv), (k,) error) of each triangle's interior sample farthest from its plane."""
    unit = unit_normals(corners)[0]
    pts_uv = np.einsum("pk,mkd->mpd", w, uv)
    xyz = surf.evaluate(pts_uv.reshape(-1, 2)).reshape(len(corners), len(w), 3)
    d = np.abs(np.einsum("mpd,md->mp", xyz - corners[:, None, 0], unit))
    best = d.argmax(axis=1)
    rows = np.arange(len(corners))
    return pts_uv[rows, best], xyz[rows, best], d[rows, best]


def vta_refine(mesh: Mesh, faces: list[int] | np.ndarray, surfaces: dict[int, Surface], iterations: int = 1,
               order: int = 6, threshold: float | None = None) -> Refinement:
    """`iterations` rounds of 1 → 3 splits of every triangle of `faces` (with `threshold`, only those whose
    sampled chordal error exceeds it); the new vertex is the worst of the order-k grid's interior points."""
    if mesh.uv is None:
        raise AmprepError(ErrorCode.INVALID_PARAMETER, "VTA needs the (u,v) of every triangle corner")
    if iterations < 1 or order < 3:
        raise AmprepError(ErrorCode.INVALID_PARAMETER, "VTA needs iterations ≥ 1 and a sample order ≥ 3")
    faces = np.unique(np.asarray(faces, dtype=np.int64))
    w = _interior_grid(order)
    verts, tris, fids, uvs = mesh.vertices, mesh.triangles, mesh.face_ids, mesh.uv
    parent = np.arange(mesh.n_triangles)
    new_face: list[np.ndarray] = []
    for _ in range(iterations):
        sel = np.flatnonzero(np.isin(fids, faces))
        new_uv, new_xyz, chosen = [], [], []
        for f in np.unique(fids[sel]):
            checkpoint()
            t = sel[fids[sel] == f]
            p_uv, p_xyz, err = _worst_points(verts[tris[t]], uvs[t], surfaces[int(f)], w)
            keep = err > (threshold if threshold is not None else 0.0)
            chosen.append(t[keep])
            new_uv.append(p_uv[keep])
            new_xyz.append(p_xyz[keep])
            new_face.append(np.full(int(keep.sum()), f))
        split = np.concatenate(chosen) if chosen else np.zeros(0, np.int64)
        if len(split) == 0:
            break
        pv = len(verts) + np.arange(len(split))
        verts = np.concatenate([verts, *new_xyz])
        p_uv = np.concatenate(new_uv)
        a, b, c = tris[split].T
        ua, ub, uc = uvs[split].transpose(1, 0, 2)
        child = np.concatenate([np.stack([a, b, pv], 1), np.stack([b, c, pv], 1), np.stack([c, a, pv], 1)])
        child_uv = np.concatenate([np.stack([ua, ub, p_uv], 1), np.stack([ub, uc, p_uv], 1),
                                   np.stack([uc, ua, p_uv], 1)])
        keep = np.ones(len(tris), bool)
        keep[split] = False
        tris = np.concatenate([tris[keep], child])
        uvs = np.concatenate([uvs[keep], child_uv])
        fids = np.concatenate([fids[keep], np.tile(fids[split], 3)])
        parent = np.concatenate([parent[keep], np.tile(parent[split], 3)])
    order_ = np.argsort(parent, kind="stable")
    n_new = len(verts) - mesh.n_vertices
    added = np.concatenate(new_face) if new_face else np.zeros(0, np.int64)

    def extend(arr: np.ndarray | None, fill: np.ndarray) -> np.ndarray | None:
        return None if arr is None else np.concatenate([arr, fill.astype(arr.dtype)])

    refined = Mesh(verts, tris[order_], fids[order_], uvs[order_], extend(mesh.vertex_dim, np.full(n_new, IN_FACE)),
                   extend(mesh.vertex_entity, added), extend(mesh.vertex_param, np.full(n_new, np.nan)), mesh.faces)
    return Refinement(refined, {}, parent[order_])
