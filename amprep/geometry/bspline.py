"""Vectorised (rational) B-spline evaluation from poles, weights and flat knot vectors."""

from __future__ import annotations

import numpy as np
from numba import njit


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


@njit(cache=True, nogil=True)
def _eval_surface_kernel(pw, uknots, vknots, udeg, vdeg, uv, out):  # pragma: no cover - compiled
    nu_poles = pw.shape[0]
    nv_poles = pw.shape[1]
    bu = np.empty(udeg + 1)
    bv = np.empty(vdeg + 1)
    left = np.empty(max(udeg, vdeg) + 1)
    right = np.empty(max(udeg, vdeg) + 1)
    for n in range(uv.shape[0]):
        for d in range(2):
            t = uv[n, d]
            knots = uknots if d == 0 else vknots
            deg = udeg if d == 0 else vdeg
            basis = bu if d == 0 else bv
            n_poles = nu_poles if d == 0 else nv_poles
            lo, hi = deg, n_poles  # span: knots[span] <= t < knots[span + 1], clamped to [deg, n_poles - 1]
            if t >= knots[n_poles]:
                span = n_poles - 1
            elif t <= knots[deg]:
                span = deg
            else:
                while hi - lo > 1:
                    mid = (lo + hi) // 2
                    if knots[mid] <= t:
                        lo = mid
                    else:
                        hi = mid
                span = lo
            basis[0] = 1.0
            for j in range(1, deg + 1):
                left[j] = t - knots[span + 1 - j]
                right[j] = knots[span + j] - t
                saved = 0.0
                for r in range(j):
                    denom = right[r + 1] + left[j - r]
                    temp = basis[r] / denom if denom != 0.0 else 0.0
                    basis[r] = saved + right[r + 1] * temp
                    saved = left[j - r] * temp
                basis[j] = saved
            if d == 0:
                su = span
            else:
                sv = span
        x = 0.0
        y = 0.0
        z = 0.0
        w = 0.0
        for a in range(udeg + 1):
            for b in range(vdeg + 1):
                c = bu[a] * bv[b]
                i = su - udeg + a
                j = sv - vdeg + b
                x += c * pw[i, j, 0]
                y += c * pw[i, j, 1]
                z += c * pw[i, j, 2]
                w += c * pw[i, j, 3]
        out[n, 0] = x / w
        out[n, 1] = y / w
        out[n, 2] = z / w


def eval_surface(
    poles: np.ndarray, weights: np.ndarray, uknots: np.ndarray, vknots: np.ndarray,
    udeg: int, vdeg: int, uv: np.ndarray,
) -> np.ndarray:
    """(N, 3) S(u,v) = Σ N_i(u) N_j(v) w_ij P_ij / Σ N_i(u) N_j(v) w_ij; poles (nu, nv, 3), weights (nu, nv).

    Compiled with numba: span by bisection, Cox–de Boor basis (Piegl–Tiller A2.2), weighted sum, per point."""
    pw = np.ascontiguousarray(np.concatenate([poles * weights[..., None], weights[..., None]], axis=2))
    out = np.empty((len(uv), 3))
    _eval_surface_kernel(pw, np.ascontiguousarray(uknots, dtype=np.float64),
                         np.ascontiguousarray(vknots, dtype=np.float64), int(udeg), int(vdeg),
                         np.ascontiguousarray(uv, dtype=np.float64), out)
    return out


def eval_curve(poles: np.ndarray, weights: np.ndarray, knots: np.ndarray, degree: int, t: np.ndarray) -> np.ndarray:
    """(N, d) C(t) = Σ N_i(t) w_i P_i / Σ N_i(t) w_i; poles (n, d), weights (n,)."""
    pw = np.concatenate([poles * weights[:, None], weights[:, None]], axis=1)
    span = find_span(knots, degree, t)
    nb = basis_functions(knots, degree, t, span)
    block = pw[(span - degree)[:, None] + np.arange(degree + 1)[None, :]]  # (N, p+1, d+1)
    h = np.einsum("na,nak->nk", nb, block)
    return h[:, :-1] / h[:, -1:]
