"""The compiled rational B-spline surface kernel (numba), imported only when a large evaluation needs it."""

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def eval_surface_kernel(pw, uknots, vknots, udeg, vdeg, uv, out):
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
