"""The compiled rational B-spline surface kernel (numba), imported only when a large evaluation needs it."""

import numpy as np
from numba import njit, prange


@njit(cache=True, nogil=True)
def _span(knots, deg, n_poles, t, hint):
    """The span of t: knots[span] ≤ t < knots[span+1], clamped to [deg, n_poles−1]; `hint` (the span of a nearby t)
    first, which that interval makes the answer when it holds."""
    if deg <= hint < n_poles and knots[hint] <= t < knots[hint + 1]:
        return hint
    if t >= knots[n_poles]:
        return n_poles - 1
    if t <= knots[deg]:
        return deg
    lo, hi = deg, n_poles
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if knots[mid] <= t:
            lo = mid
        else:
            hi = mid
    return lo


@njit(cache=True, nogil=True)
def span_bernstein(knots, deg, n_poles):
    """(coef (n_poles, deg+1, deg+1), inv_h (n_poles,)): on span s (deg ≤ s < n_poles, of length h > 0) the basis value
    N_{s−deg+a}(x) = Σ_q coef[s, a, q] t^q (1−t)^(deg−q) with t = (x − knots[s])·inv_h[s], inv_h = 1/h: C(deg, q)
    times the q-th Bernstein coefficient. Made by Cox–de Boor in Bernstein form, where each factor is α(1−t) + βt
    with α, β ≥ 0 on the span: no cancellation at any degree. Empty spans are left zero."""
    coef = np.zeros((n_poles, deg + 1, deg + 1))
    inv_h = np.zeros(n_poles)
    cur = np.zeros((deg + 1, deg + 1))
    new = np.zeros((deg + 1, deg + 1))
    for s in range(deg, n_poles):
        h = knots[s + 1] - knots[s]
        if h <= 0.0:
            continue
        cur[:] = 0.0
        cur[0, 0] = 1.0  # N_{s,0} = 1 on the span
        for j in range(1, deg + 1):  # level j: cur[r] holds N_{s−j+r, j}, r = 0..j
            new[:] = 0.0
            for r in range(j + 1):
                i = s - j + r
                if r >= 1 and knots[i + j] > knots[i]:  # (x − k_i)/(k_{i+j} − k_i) · N_{i, j−1}
                    d = knots[i + j] - knots[i]
                    _add_linear_times(new[r], (knots[s] - knots[i]) / d, (knots[s + 1] - knots[i]) / d, cur[r - 1], j)
                if r <= j - 1 and knots[i + j + 1] > knots[i + 1]:  # (k_{i+j+1} − x)/(k_{i+j+1} − k_{i+1}) · N_{i+1, j−1}
                    d = knots[i + j + 1] - knots[i + 1]
                    _add_linear_times(new[r], (knots[i + j + 1] - knots[s]) / d, (knots[i + j + 1] - knots[s + 1]) / d,
                                      cur[r], j)
            cur[:] = new
        binomial = 1.0
        for q in range(deg + 1):
            coef[s, :, q] = cur[:, q] * binomial
            binomial = binomial * (deg - q) / (q + 1)
        inv_h[s] = 1.0 / h
    return coef, inv_h


@njit(cache=True, nogil=True, inline="always")
def _add_linear_times(out, alpha, beta, poly, j):
    """out += (α(1−t) + βt) · poly in Bernstein form: poly of degree j−1 (poly[:j]), out of degree j (out[:j+1])."""
    for k in range(j + 1):
        v = 0.0
        if k < j:
            v += (j - k) * alpha * poly[k]
        if k > 0:
            v += k * beta * poly[k - 1]
        out[k] += v / j


@njit(cache=True, nogil=True, inline="always")
def _basis(knots, coef, inv_h, deg, n_poles, t, basis, tp, sp, hint):
    """The span of t (_span) and basis ← its deg+1 basis values from the span's Bernstein form (tp, sp: scratch)."""
    span = _span(knots, deg, n_poles, t, hint)
    x = (t - knots[span]) * inv_h[span]
    y = 1.0 - x
    tp[0] = 1.0
    sp[0] = 1.0
    for q in range(1, deg + 1):
        tp[q] = tp[q - 1] * x
        sp[q] = sp[q - 1] * y
    for a in range(deg + 1):
        val = 0.0
        for q in range(deg + 1):
            val += coef[span, a, q] * (tp[q] * sp[deg - q])
        basis[a] = val
    return span


@njit(cache=True, nogil=True, inline="always")
def point_kernel(pw, ub, vb, udeg, vdeg, u, v, work, hu, hv):
    """(x, y, z, span in u, span in v): S(u,v) = Σ N_i(u) N_j(v) pw_ij[:3] / Σ N_i(u) N_j(v) pw_ij[3], a row of poles
    summed in v, then the rows in u; ub, vb = (knots, coef, inv_h) of each direction (span_bernstein); work: scratch's;
    hu, hv: the last point's spans, tried first."""
    bu, bv, tp, sp = work
    su = _basis(ub[0], ub[1], ub[2], udeg, pw.shape[0], u, bu, tp, sp, hu)
    sv = _basis(vb[0], vb[1], vb[2], vdeg, pw.shape[1], v, bv, tp, sp, hv)
    x = y = z = w = 0.0
    for a in range(udeg + 1):
        row = pw[su - udeg + a]
        rx = ry = rz = rw = 0.0
        for b in range(vdeg + 1):
            p = row[sv - vdeg + b]
            c = bv[b]
            rx += c * p[0]
            ry += c * p[1]
            rz += c * p[2]
            rw += c * p[3]
        c = bu[a]
        x += c * rx
        y += c * ry
        z += c * rz
        w += c * rw
    return x / w, y / w, z / w, su, sv


@njit(cache=True, nogil=True, inline="always")
def scratch(udeg, vdeg):
    """(bu, bv, tp, sp): the work arrays point_kernel needs, one set per thread."""
    deg = max(udeg, vdeg) + 1
    return np.empty(udeg + 1), np.empty(vdeg + 1), np.empty(deg), np.empty(deg)


#: points per block of the parallel kernel (one thread each); a call of at most one block runs eval_surface_serial
EVAL_BLOCK = 4096


@njit(cache=True, nogil=True)
def _eval_range(pw, ub, vb, udeg, vdeg, uv, out, start, stop):
    """out[start:stop] ← S(uv[start:stop])."""
    work = scratch(udeg, vdeg)
    su = sv = -1
    for k in range(start, stop):
        x, y, z, su, sv = point_kernel(pw, ub, vb, udeg, vdeg, uv[k, 0], uv[k, 1], work, su, sv)
        out[k, 0] = x
        out[k, 1] = y
        out[k, 2] = z


@njit(cache=True, nogil=True, parallel=True)
def eval_surface_kernel(pw, ub, vb, udeg, vdeg, uv, out):
    """out (N, 3) ← S(uv (N, 2)), in blocks over the threads (ub, vb: point_kernel's)."""
    n = uv.shape[0]
    for blk in prange((n + EVAL_BLOCK - 1) // EVAL_BLOCK):
        _eval_range(pw, ub, vb, udeg, vdeg, uv, out, blk * EVAL_BLOCK, min(n, (blk + 1) * EVAL_BLOCK))


@njit(cache=True, nogil=True)
def eval_surface_serial(pw, ub, vb, udeg, vdeg, uv, out):
    """eval_surface_kernel on the calling thread only (a parallel launch costs ~0.1 ms: more than a small call)."""
    _eval_range(pw, ub, vb, udeg, vdeg, uv, out, 0, uv.shape[0])
