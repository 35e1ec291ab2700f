"""Bring a meshed face within tolerance where only some of its triangles exceed it: re-triangulate just the
neighbourhood of those triangles (constrained Delaunay in scaled (u,v), new points inserted), keeping the rest of
the mesh and every boundary node, so a face OCCT meshed 99 % right is not meshed again from scratch."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .chordal import triangle_chordal_error
from .errors import AmprepError
from .fallback import (
    MAX_ROUNDS,
    MIN_SPACING,
    _apart,
    _insertion_points,
    _metric_scale,
    _triangle_codes,
    triangulate_pslg,
)
from .surfaces import Surface
from .tessellate import FacePatch

#: a re-triangulated region must cover the (u,v) area it replaced to this relative precision
AREA_RTOL = 1e-9


def _edge_codes(tris: np.ndarray, base: int) -> np.ndarray:
    """(t, 3) int64 code lo·base + hi of each triangle's edges (i→i+1)."""
    a, b = tris, np.roll(tris, -1, axis=1)
    return np.minimum(a, b).astype(np.int64) * base + np.maximum(a, b)


def _signed_area2(pts: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """(t,) twice the signed (u,v) area of each triangle (> 0: counter-clockwise)."""
    a, b, c = pts[tris[:, 0]], pts[tris[:, 1]], pts[tris[:, 2]]
    return (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])


def _retriangulate(pts: np.ndarray, region: np.ndarray, outside_seeds: np.ndarray,
                   new: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """CDT of a region of triangles (r, 3) over pts (n, 2) with `new` (k, 2) points inside it, its boundary edges
    kept as segments; returns (nodes (m,) global ids of its old nodes, triangles (r + 2k, 3) over
    [pts[nodes]; new]) counter-clockwise, or None when Triangle's result does not tile the region exactly."""
    nodes, local = np.unique(region, return_inverse=True)
    local = local.reshape(region.shape)
    code = _edge_codes(local, len(nodes) + 1).ravel()
    uniq, first, count = np.unique(code, return_index=True, return_counts=True)
    once = first[count == 1]
    a, b = local.ravel(), np.roll(local, -1, axis=1).ravel()
    segments = np.stack([a[once], b[once]], axis=1)
    vertices = np.concatenate([pts[nodes], new])
    try:
        tris = triangulate_pslg(vertices, segments, outside_seeds)
    except AmprepError:
        return None
    if len(tris) != len(region) + 2 * len(new):
        return None
    area_old = np.abs(_signed_area2(pts, region)).sum()
    area_new = _signed_area2(vertices, tris)
    if (area_new <= 0).any() or abs(area_new.sum() - area_old) > AREA_RTOL * area_old:
        return None
    return nodes, tris


def refine_patch(patch: FacePatch, error: np.ndarray, surface: Surface, tolerance: float, order: int = 6,
                 rounds: int = MAX_ROUNDS) -> FacePatch | None:
    """The patch with every triangle whose chordal error `error` (t,) exceeds the tolerance replaced, with the
    triangles sharing a node with it, by a CDT of that region plus one point per such triangle (midpoint of its
    longest inner edge, else centroid), until none exceeds it; boundary nodes and all other triangles are kept
    (`error` of the result is set). None when a region cannot be re-triangulated (a fold in the face's (u,v))."""
    assert patch.uv is not None
    tris, err = patch.tris, np.asarray(error, float)
    scale = _metric_scale(surface, patch.uv)
    pts = patch.uv * scale
    xyz, uv = patch.nodes, patch.uv
    sign = 1.0 if _signed_area2(pts, tris).sum() >= 0 else -1.0
    codes, count = np.unique(_edge_codes(tris, len(pts) + 1), return_counts=True)
    boundary_pairs = np.stack(np.divmod(codes[count == 1], len(pts) + 1), axis=1)  # the face's boundary: kept
    for _ in range(rounds):
        bad = err > tolerance
        if not bad.any():
            break
        base = len(pts) + 1
        boundary = boundary_pairs[:, 0] * base + boundary_pairs[:, 1]
        marked = np.zeros(len(pts), bool)
        marked[tris[bad]] = True
        in_region = marked[tris].any(axis=1)
        region = tris[in_region]
        new = _insertion_points(pts, tris[bad], boundary, base)
        new = _apart(new, pts[np.unique(region)], MIN_SPACING * tolerance)
        if not len(new):
            break
        # a hole seed in every kept triangle across an inner edge of the region's border: Triangle must not fill
        # what the region surrounds
        rim_codes = np.setdiff1d(_edge_codes(region, base), boundary)
        rim = np.zeros(len(tris), bool)
        rim[~in_region] = np.isin(_edge_codes(tris[~in_region], base), rim_codes).any(axis=1)
        seeds = pts[tris[rim]].mean(axis=1)
        done = _retriangulate(pts, region, seeds, new)
        if done is None:
            return None
        nodes, local = done
        ids = np.concatenate([nodes, len(pts) + np.arange(len(new))])
        fresh = ids[local]
        if sign < 0:
            fresh = fresh[:, [0, 2, 1]]
        pts = np.concatenate([pts, new])
        uv = np.concatenate([uv, new / scale])
        xyz = np.concatenate([xyz, surface.evaluate(uv[-len(new):])])
        old_code, old_err = _triangle_codes(region, len(pts)), err[in_region]
        fresh_err = np.empty(len(fresh))
        if old_code is not None:
            new_code = _triangle_codes(fresh, len(pts))
            order_ = np.argsort(old_code)
            pos = np.minimum(np.searchsorted(old_code[order_], new_code), len(old_code) - 1)
            seen = old_code[order_][pos] == new_code
            fresh_err[seen] = old_err[order_][pos[seen]]
        else:
            seen = np.zeros(len(fresh), bool)
        fresh_err[~seen] = triangle_chordal_error(xyz[fresh[~seen]], uv[fresh[~seen]], surface, order,
                                                  affine=surface.affine)
        tris = np.concatenate([tris[~in_region], fresh])
        err = np.concatenate([err[~in_region], fresh_err])
    k = len(pts) - len(patch.uv)
    return replace(patch, nodes=xyz, uv=uv, tris=tris,
                   node_vertex=np.concatenate([patch.node_vertex, np.full(k, -1, np.int64)]),
                   node_edge=np.concatenate([patch.node_edge, np.full(k, -1, np.int64)]),
                   node_param=np.concatenate([patch.node_param, np.full(k, np.nan)]),
                   meshed_by="refined" if patch.meshed_by == "occt" else patch.meshed_by, error=err)
