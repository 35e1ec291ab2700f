"""Chordal error: distance from the exact surface to each triangle's plane, sampled in the face's (u,v)."""

from __future__ import annotations

from collections.abc import Callable
from functools import lru_cache

import numpy as np

_CHUNK_POINTS = 1_000_000


@lru_cache(maxsize=32)
def barycentric_grid(order: int) -> np.ndarray:
    """((k+1)(k+2)/2, 3) barycentric weights (i, j, k−i−j)/k of the order-k grid on a triangle (k=6: 28)."""
    pts = [(i, j, order - i - j) for i in range(order + 1) for j in range(order + 1 - i)]
    w = np.array(pts, dtype=float) / order
    w.flags.writeable = False
    return w


def affine_chordal_bound(corners: np.ndarray, uv: np.ndarray, evaluate: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """(m,) max_i |S(u_i, v_i) − c_i| over the corners: the exact bound of ε_T when S is affine in (u,v) (a plane),
    since every S(Σ w_i uv_i) − (plane of T) = Σ w_i (S(uv_i) − c_i) · n̂."""
    exact = evaluate(uv.reshape(-1, 2)).reshape(-1, 3, 3)
    return np.linalg.norm(exact - corners, axis=2).max(axis=1)


def triangle_chordal_error(
    corners: np.ndarray, uv: np.ndarray, evaluate: Callable[[np.ndarray], np.ndarray], order: int = 6,
    affine: bool = False,
) -> np.ndarray:
    """(m,) ε_T = max_p |(S(u_p, v_p) − a) · n̂| over the order-k barycentric grid in (u,v);
    corners (m, 3, 3) mm, uv (m, 3, 2) on the surface `evaluate` ((N, 2) → (N, 3)). Zero-area: 0.
    affine=True (planes): the corner bound of affine_chordal_bound instead of sampling."""
    m = len(corners)
    if m == 0:
        return np.zeros(0)
    if affine:
        return affine_chordal_bound(corners, uv, evaluate)
    w = barycentric_grid(order)
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    norm = np.linalg.norm(normal, axis=1)
    unit = np.divide(normal, norm[:, None], out=np.zeros_like(normal), where=norm[:, None] > 0)
    out = np.empty(m)
    step = max(1, _CHUNK_POINTS // len(w))
    for s in range(0, m, step):
        sl = slice(s, s + step)
        pts_uv = np.einsum("pk,mkd->mpd", w, uv[sl]).reshape(-1, 2)
        xyz = evaluate(pts_uv).reshape(-1, len(w), 3)
        d = np.einsum("mpd,md->mp", xyz - corners[sl, None, 0], unit[sl])
        out[sl] = np.abs(d).max(axis=1)
    return out
