"""Vectorised (rational) B-spline evaluation from poles, weights and flat knot vectors."""

from __future__ import annotations

import numpy as np

_CHUNK = 65536


def find_span(knots: np.ndarray, degree: int, t: np.ndarray) -> np.ndarray:
    """(N,) int: the span i with knots[i] ≤ t < knots[i+1], clamped to [degree, n_poles − 1]."""
    n_poles = len(knots) - degree - 1
    span = np.searchsorted(knots, t, side="right") - 1
    return np.clip(span, degree, n_poles - 1)


def basis_functions(knots: np.ndarray, degree: int, t: np.ndarray, span: np.ndarray) -> np.ndarray:
    """(N, degree+1) non-zero basis values N_{span−p+a, p}(t) by the Cox–de Boor triangle (Piegl–Tiller A2.2)."""
    n = len(t)
    basis = np.zeros((n, degree + 1))
    basis[:, 0] = 1.0
    left = np.zeros((n, degree + 1))
    right = np.zeros((n, degree + 1))
    for j in range(1, degree + 1):
        left[:, j] = t - knots[span + 1 - j]
        right[:, j] = knots[span + j] - t
        saved = np.zeros(n)
        for r in range(j):
            denom = right[:, r + 1] + left[:, j - r]
            temp = np.divide(basis[:, r], denom, out=np.zeros(n), where=denom != 0)
            basis[:, r] = saved + right[:, r + 1] * temp
            saved = left[:, j - r] * temp
        basis[:, j] = saved
    return basis


def eval_surface(
    poles: np.ndarray, weights: np.ndarray, uknots: np.ndarray, vknots: np.ndarray,
    udeg: int, vdeg: int, uv: np.ndarray,
) -> np.ndarray:
    """(N, 3) S(u,v) = Σ N_i(u) N_j(v) w_ij P_ij / Σ N_i(u) N_j(v) w_ij; poles (nu, nv, 3), weights (nu, nv)."""
    pw = np.concatenate([poles * weights[..., None], weights[..., None]], axis=2)  # (nu, nv, 4)
    out = np.empty((len(uv), 3))
    a = np.arange(udeg + 1)[None, :, None]
    b = np.arange(vdeg + 1)[None, None, :]
    for s in range(0, len(uv), _CHUNK):
        u, v = uv[s:s + _CHUNK, 0], uv[s:s + _CHUNK, 1]
        su, sv = find_span(uknots, udeg, u), find_span(vknots, vdeg, v)
        nu, nv = basis_functions(uknots, udeg, u, su), basis_functions(vknots, vdeg, v, sv)
        block = pw[(su - udeg)[:, None, None] + a, (sv - vdeg)[:, None, None] + b]  # (n, p+1, q+1, 4)
        h = np.einsum("na,nb,nabk->nk", nu, nv, block)
        out[s:s + _CHUNK] = h[:, :3] / h[:, 3:4]
    return out


def eval_curve(poles: np.ndarray, weights: np.ndarray, knots: np.ndarray, degree: int, t: np.ndarray) -> np.ndarray:
    """(N, d) C(t) = Σ N_i(t) w_i P_i / Σ N_i(t) w_i; poles (n, d), weights (n,)."""
    pw = np.concatenate([poles * weights[:, None], weights[:, None]], axis=1)
    span = find_span(knots, degree, t)
    nb = basis_functions(knots, degree, t, span)
    block = pw[(span - degree)[:, None] + np.arange(degree + 1)[None, :]]  # (N, p+1, d+1)
    h = np.einsum("na,nak->nk", nb, block)
    return h[:, :-1] / h[:, -1:]
