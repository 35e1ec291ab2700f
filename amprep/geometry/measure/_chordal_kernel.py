"""Compiled chordal error (numba, parallel over triangles): S(u,v) evaluated and its distance to the triangle's plane
taken in one pass, with no (m, k, 3) intermediate; imported only when a large evaluation needs it."""

import numpy as np
from numba import njit, prange

from amprep.geometry.cad._bspline_kernel import point_kernel, scratch
from amprep.geometry.cad._projection_kernel import closed_form_point, wrapped
from amprep.geometry.cad.surfaces import CONE, CYLINDER, PLANE, SPHERE, TORUS


@njit(cache=True, nogil=True, inline="always")
def _unit_normal(c):
    ax, ay, az = c[1, 0] - c[0, 0], c[1, 1] - c[0, 1], c[1, 2] - c[0, 2]
    bx, by, bz = c[2, 0] - c[0, 0], c[2, 1] - c[0, 1], c[2, 2] - c[0, 2]
    nx, ny, nz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
    n = np.sqrt(nx * nx + ny * ny + nz * nz)
    if n == 0.0:
        return 0.0, 0.0, 0.0, False
    return nx / n, ny / n, nz / n, True


@njit(cache=True, nogil=True, inline="always")
def _sample(w, uv, m, p):
    """(u, v) of grid point p of triangle m: Σ_k w[p,k] uv[m,k]."""
    u = w[p, 0] * uv[m, 0, 0] + w[p, 1] * uv[m, 1, 0] + w[p, 2] * uv[m, 2, 0]
    v = w[p, 0] * uv[m, 0, 1] + w[p, 1] * uv[m, 1, 1] + w[p, 2] * uv[m, 2, 1]
    return u, v


@njit(cache=True, nogil=True, inline="always")
def _distance(c, nx, ny, nz, xyz):
    """|(xyz − c[0]) · n̂|."""
    return abs((xyz[0] - c[0, 0]) * nx + (xyz[1] - c[0, 1]) * ny + (xyz[2] - c[0, 2]) * nz)


@njit(cache=True, nogil=True, inline="always")
def _offset2(c, w, p, xyz):
    """|xyz − a_p|² with a_p = Σ_k w[p,k] c[k], the grid point on the triangle."""
    dx = xyz[0] - (w[p, 0] * c[0, 0] + w[p, 1] * c[1, 0] + w[p, 2] * c[2, 0])
    dy = xyz[1] - (w[p, 0] * c[0, 1] + w[p, 1] * c[1, 1] + w[p, 2] * c[2, 1])
    dz = xyz[2] - (w[p, 0] * c[0, 2] + w[p, 1] * c[1, 2] + w[p, 2] * c[2, 2])
    return dx * dx + dy * dy + dz * dz


#: triangles per block of the parallel B-spline kernel; calls of at most one block (and every analytic call of at
#: most this many) run the serial kernels: a parallel launch costs ~0.1 ms
BLOCK = 1024


@njit(cache=True, nogil=True, inline="always")
def _turns(a, m, k, cos_t, sin_t):
    """cos_t[i, j], sin_t[i, j] ← cos, sin of a_2 + i(a_0 − a_2)/k + j(a_1 − a_2)/k (i + j ≤ k), the angle at the
    order-k grid's point (i, j)/k of triangle m (a (M, 3): its corners' angles): e^{i a_2} times powers of the two
    steps' turns, three sin/cos pairs per triangle instead of one per point."""
    c0, s0 = np.cos(a[m, 2]), np.sin(a[m, 2])
    ca, sa = np.cos((a[m, 0] - a[m, 2]) / k), np.sin((a[m, 0] - a[m, 2]) / k)
    cb, sb = np.cos((a[m, 1] - a[m, 2]) / k), np.sin((a[m, 1] - a[m, 2]) / k)
    ci, si = c0, s0  # e^{i(a_2 + i·step_a)}, row by row
    for i in range(k + 1):
        cj, sj = ci, si
        for j in range(k + 1 - i):
            cos_t[i, j], sin_t[i, j] = cj, sj
            cj, sj = cj * cb - sj * sb, cj * sb + sj * cb
        ci, si = ci * ca - si * sa, ci * sa + si * ca


@njit(cache=True, nogil=True, inline="always")
def _centroid(uv, m):
    """(u, v) of triangle m's (u,v) centroid, as numpy's uv.mean(axis=1) sums it."""
    return (uv[m, 0, 0] + uv[m, 1, 0] + uv[m, 2, 0]) / 3.0, (uv[m, 0, 1] + uv[m, 1, 1] + uv[m, 2, 1]) / 3.0


@njit(cache=True, nogil=True, inline="always")
def _facing(kind, prm, uv, m, nx, ny, nz, sin_b, cos_b):
    """|n̂ · S_u × S_v| / |S_u × S_v| at triangle m's (u,v) centroid, the tangents in closed form (surfaces.py's
    formulas differentiated: e' = −sin u·X + cos u·Y times the ring's radius, and S_v); 0 where |S_u × S_v| ≤
    1e-9 |S_u||S_v| (a pole, an apex), as surfaces.surface_normals gives it."""
    u, v = _centroid(uv, m)
    if kind == PLANE:
        a0, a1, a2, b0, b1, b2 = 1.0, 0.0, 0.0, 0.0, 1.0, 0.0
    else:
        cu, su = np.cos(u), np.sin(u)
        if kind == CYLINDER:
            ring, b0, b1, b2 = prm[12], 0.0, 0.0, 1.0
        elif kind == CONE:
            ring, b0, b1, b2 = prm[12] + v * sin_b, sin_b * cu, sin_b * su, cos_b
        else:
            cv, sv = np.cos(v), np.sin(v)
            r = prm[12] if kind == SPHERE else prm[13]
            ring = r * cv if kind == SPHERE else prm[12] + prm[13] * cv
            b0, b1, b2 = -r * sv * cu, -r * sv * su, r * cv
        a0, a1, a2 = -ring * su, ring * cu, 0.0
    tu = (a0 * prm[3] + a1 * prm[6] + a2 * prm[9], a0 * prm[4] + a1 * prm[7] + a2 * prm[10],
          a0 * prm[5] + a1 * prm[8] + a2 * prm[11])
    tv = (b0 * prm[3] + b1 * prm[6] + b2 * prm[9], b0 * prm[4] + b1 * prm[7] + b2 * prm[10],
          b0 * prm[5] + b1 * prm[8] + b2 * prm[11])
    return _tilt_cos(nx, ny, nz, tu, tv)


@njit(cache=True, nogil=True, inline="always")
def _tilt_cos(nx, ny, nz, tu, tv):
    """|n̂ · (tu × tv)| / |tu × tv|, 0 where |tu × tv| ≤ 1e-9 |tu||tv| (surfaces.surface_normals' zero normal)."""
    gx, gy, gz = tu[1] * tv[2] - tu[2] * tv[1], tu[2] * tv[0] - tu[0] * tv[2], tu[0] * tv[1] - tu[1] * tv[0]
    size = np.sqrt(gx * gx + gy * gy + gz * gz)
    scale = np.sqrt(tu[0] * tu[0] + tu[1] * tu[1] + tu[2] * tu[2]) * np.sqrt(tv[0] * tv[0] + tv[1] * tv[1] + tv[2] * tv[2])
    if not size > 1e-9 * scale:
        return 0.0
    return abs(gx * nx + gy * ny + gz * nz) / size


@njit(cache=True, nogil=True)
def _analytic_range(kind, prm, corners, uv, w, ij, k, stop, screen, out, off, facing, start, end):
    """out, off and facing [start:end] of analytic_chordal_kernel; a revolved surface's sin and cos from _turns'
    tables."""
    cu, su, cv, sv = np.empty((k + 1, k + 1)), np.empty((k + 1, k + 1)), np.empty((k + 1, k + 1)), np.empty((k + 1, k + 1))
    turn_u = kind != PLANE
    turn_v = kind == SPHERE or kind == TORUS
    sin_b, cos_b = np.sin(prm[13]), np.cos(prm[13])
    au, av = uv[:, :, 0], uv[:, :, 1]
    for m in range(start, end):
        c = corners[m]
        nx, ny, nz, ok = _unit_normal(c)
        best = whole = 0.0
        if ok:
            if turn_u:
                _turns(au, m, k, cu, su)
            if turn_v:
                _turns(av, m, k, cv, sv)
            for p in range(w.shape[0]):
                u, v = _sample(w, uv, m, p)
                i, j = ij[p, 0], ij[p, 1]
                xyz = closed_form_point(kind, prm, u, v, cu[i, j], su[i, j], cv[i, j], sv[i, j], sin_b, cos_b)
                best = max(best, _distance(c, nx, ny, nz, xyz))
                whole = max(whole, _offset2(c, w, p, xyz))
                if best > stop:
                    break
        out[m] = best
        off[m] = np.sqrt(whole)
        facing[m] = _facing(kind, prm, uv, m, nx, ny, nz, sin_b, cos_b) if ok and off[m] > screen * best else 1.0


@njit(cache=True, nogil=True, parallel=True)
def analytic_chordal_kernel(kind, prm, corners, uv, w, ij, k, stop, screen, out, off, facing):
    """out[m] = max_p |(S(Σ_k w[p,k] uv[m,k]) − corners[m,0]) · n̂_m| and off[m] = max_p |S(…) − Σ_k w[p,k] corners[m,k]|
    (0 for a zero-area triangle); corners (M,3,3), uv (M,3,2), w (P,3) the order-k grid, ij (P, 2) its points'
    (i, j) = k·w[:, :2]; a triangle's points stop at the first over `stop` (out[m] is then a value > stop, not the
    maximum, and off[m] the maximum so far); facing[m] = |n̂_m · n̂_S| at the triangle's (u,v) centroid (_facing)
    where off[m] > screen · out[m] (chordal.tilted_bound's screen), else 1 (and for a zero-area triangle)."""
    n = corners.shape[0]
    for blk in prange((n + BLOCK - 1) // BLOCK):
        _analytic_range(kind, prm, corners, uv, w, ij, k, stop, screen, out, off, facing, blk * BLOCK,
                        min(n, (blk + 1) * BLOCK))


@njit(cache=True, nogil=True)
def analytic_chordal_serial(kind, prm, corners, uv, w, ij, k, stop, screen, out, off, facing):
    """analytic_chordal_kernel on the calling thread only."""
    _analytic_range(kind, prm, corners, uv, w, ij, k, stop, screen, out, off, facing, 0, corners.shape[0])


@njit(cache=True, nogil=True)
def _bspline_range(pw, ub, vb, udeg, vdeg, uper, vper, corners, uv, w, stop, screen, h, out, off, facing, start, end):
    work = scratch(udeg, vdeg)
    su = sv = -1
    for m in range(start, end):
        c = corners[m]
        nx, ny, nz, ok = _unit_normal(c)
        best = whole = 0.0
        if ok:
            for p in range(w.shape[0]):
                u, v = _sample(w, uv, m, p)
                x, y, z, su, sv = point_kernel(pw, ub, vb, udeg, vdeg, wrapped(u, uper), wrapped(v, vper), work,
                                               su, sv)
                best = max(best, _distance(c, nx, ny, nz, (x, y, z)))
                whole = max(whole, _offset2(c, w, p, (x, y, z)))
                if best > stop:
                    break
        out[m] = best
        off[m] = np.sqrt(whole)
        facing[m] = 1.0
        if ok and off[m] > screen * best:  # S_u, S_v by central differences of h at the (u,v) centroid, as numpy's
            u, v = _centroid(uv, m)
            ax, ay, az, su, sv = point_kernel(pw, ub, vb, udeg, vdeg, wrapped(u + h[0], uper), wrapped(v, vper),
                                              work, su, sv)
            bx, by, bz, su, sv = point_kernel(pw, ub, vb, udeg, vdeg, wrapped(u - h[0], uper), wrapped(v, vper),
                                              work, su, sv)
            cx, cy, cz, su, sv = point_kernel(pw, ub, vb, udeg, vdeg, wrapped(u, uper), wrapped(v + h[1], vper),
                                              work, su, sv)
            dx, dy, dz, su, sv = point_kernel(pw, ub, vb, udeg, vdeg, wrapped(u, uper), wrapped(v - h[1], vper),
                                              work, su, sv)
            tu = ((ax - bx) / (2 * h[0]), (ay - by) / (2 * h[0]), (az - bz) / (2 * h[0]))
            tv = ((cx - dx) / (2 * h[1]), (cy - dy) / (2 * h[1]), (cz - dz) / (2 * h[1]))
            facing[m] = _tilt_cos(nx, ny, nz, tu, tv)


@njit(cache=True, nogil=True, parallel=True)
def bspline_chordal_kernel(pw, ub, vb, udeg, vdeg, uper, vper, corners, uv, w, stop, screen, h, out, off, facing):
    """The same for a rational B-spline (poles·weights | weights (nu, nv, 4); ub, vb: each direction's knots and the
    Bernstein forms of its basis, _bspline_kernel.point_kernel's); a periodic direction's parameter is wrapped into
    [uper[0], uper[1]) (uper[1] ≤ uper[0]: not periodic); the tangents of facing by central differences of h (2,)
    (surfaces.tangents' steps)."""
    n = corners.shape[0]
    for blk in prange((n + BLOCK - 1) // BLOCK):
        _bspline_range(pw, ub, vb, udeg, vdeg, uper, vper, corners, uv, w, stop, screen, h, out, off, facing,
                       blk * BLOCK, min(n, (blk + 1) * BLOCK))


@njit(cache=True, nogil=True)
def bspline_chordal_serial(pw, ub, vb, udeg, vdeg, uper, vper, corners, uv, w, stop, screen, h, out, off, facing):
    """bspline_chordal_kernel on the calling thread only."""
    _bspline_range(pw, ub, vb, udeg, vdeg, uper, vper, corners, uv, w, stop, screen, h, out, off, facing, 0,
                   corners.shape[0])
