"""The compiled rational B-spline surface kernel (numba), imported only when a large evaluation needs it."""

import numpy as np
from numba import njit, prange


@njit(cache=True, nogil=True)
def _span_basis(knots, deg, n_poles, t, basis, left, right):
    """The span of t (knots[span] ≤ t < knots[span+1], clamped to [deg, n_poles−1]); basis ← its deg+1 non-zero
    basis values (Piegl–Tiller A2.1, A2.2)."""
    lo, hi = deg, n_poles
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
    return span


@njit(cache=True, nogil=True)
def point_kernel(pw, uknots, vknots, udeg, vdeg, u, v, bu, bv, left, right):
    """S(u,v) = Σ N_i(u) N_j(v) pw_ij[:3] / Σ N_i(u) N_j(v) pw_ij[3]; bu, bv, left, right: scratch arrays."""
    su = _span_basis(uknots, udeg, pw.shape[0], u, bu, left, right)
    sv = _span_basis(vknots, vdeg, pw.shape[1], v, bv, left, right)
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
    return x / w, y / w, z / w


@njit(cache=True, nogil=True)
def scratch(udeg, vdeg):
    """(bu, bv, left, right): the work arrays point_kernel needs, one set per thread."""
    deg = max(udeg, vdeg) + 1
    return np.empty(udeg + 1), np.empty(vdeg + 1), np.empty(deg), np.empty(deg)


#: points per block of the parallel kernel (one thread each); a call of at most one block runs eval_surface_serial
EVAL_BLOCK = 4096


@njit(cache=True, nogil=True)
def _eval_range(pw, uknots, vknots, udeg, vdeg, uv, out, start, stop):
    """out[start:stop] ← S(uv[start:stop])."""
    bu, bv, left, right = scratch(udeg, vdeg)
    for k in range(start, stop):
        x, y, z = point_kernel(pw, uknots, vknots, udeg, vdeg, uv[k, 0], uv[k, 1], bu, bv, left, right)
        out[k, 0] = x
        out[k, 1] = y
        out[k, 2] = z


@njit(cache=True, nogil=True, parallel=True)
def eval_surface_kernel(pw, uknots, vknots, udeg, vdeg, uv, out):
    """out (N, 3) ← S(uv (N, 2)), in blocks over the threads."""
    n = uv.shape[0]
    for blk in prange((n + EVAL_BLOCK - 1) // EVAL_BLOCK):
        _eval_range(pw, uknots, vknots, udeg, vdeg, uv, out, blk * EVAL_BLOCK, min(n, (blk + 1) * EVAL_BLOCK))


@njit(cache=True, nogil=True)
def eval_surface_serial(pw, uknots, vknots, udeg, vdeg, uv, out):
    """eval_surface_kernel on the calling thread only (a parallel launch costs ~0.1 ms: more than a small call)."""
    _eval_range(pw, uknots, vknots, udeg, vdeg, uv, out, 0, uv.shape[0])
