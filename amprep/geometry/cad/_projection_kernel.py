"""Compiled Gauss–Newton projection on a face's surface (numba): surfaces.project_settled's loop run point by point
in one call, for closed-form and rational B-spline surfaces; imported only when a computation chose the kernels."""

import numpy as np
from numba import njit

from amprep.geometry.cad._bspline_kernel import point_kernel, scratch
from amprep.geometry.cad.surfaces import CONE, CYLINDER, PLANE, SPHERE


@njit(cache=True, nogil=True, inline="always")
def closed_form_point(kind, prm, u, v, cu, su, cv, sv, sin_b, cos_b):
    """S(u,v) of a closed-form surface given cos u, sin u, cos v, sin v; prm = O(3), X(3), Y(3), Z(3), a, b (radius /
    semi-angle / radii), sin_b, cos_b = sin b, cos b (a cone's semi-angle)."""
    if kind == PLANE:
        c0, c1, c2 = u, v, 0.0
    elif kind == CYLINDER:
        c0, c1, c2 = prm[12] * cu, prm[12] * su, v
    elif kind == CONE:
        rad = prm[12] + v * sin_b
        c0, c1, c2 = rad * cu, rad * su, v * cos_b
    elif kind == SPHERE:
        rc = prm[12] * cv
        c0, c1, c2 = rc * cu, rc * su, prm[12] * sv
    else:  # TORUS
        rad = prm[12] + prm[13] * cv
        c0, c1, c2 = rad * cu, rad * su, prm[13] * sv
    x = prm[0] + c0 * prm[3] + c1 * prm[6] + c2 * prm[9]
    y = prm[1] + c0 * prm[4] + c1 * prm[7] + c2 * prm[10]
    z = prm[2] + c0 * prm[5] + c1 * prm[8] + c2 * prm[11]
    return x, y, z


@njit(cache=True, nogil=True, inline="always")
def wrapped(t, per):
    """t moved into the period [per[0], per[1]) (per[1] ≤ per[0]: not periodic, t as it is)."""
    return per[0] + (t - per[0]) % (per[1] - per[0]) if per[1] > per[0] else t


@njit(cache=True, nogil=True, inline="always")
def _closed(kind, prm, u, v, sin_b, cos_b):
    return closed_form_point(kind, prm, u, v, np.cos(u), np.sin(u), np.cos(v), np.sin(v), sin_b, cos_b)


@njit(cache=True, nogil=True, inline="always")
def _step(s, pu, mu, pv, mv, p, u, v, h, span, lo, hi):
    """(u, v, moved) after one Gauss–Newton step on |S − p|² from S = s and the central differences S(u ± h_u, v),
    S(u, v ± h_v), as project_settled takes it: the step clipped to a quarter of the extent, the result to [lo, hi]."""
    tu0, tu1, tu2 = (pu[0] - mu[0]) / (2 * h[0]), (pu[1] - mu[1]) / (2 * h[0]), (pu[2] - mu[2]) / (2 * h[0])
    tv0, tv1, tv2 = (pv[0] - mv[0]) / (2 * h[1]), (pv[1] - mv[1]) / (2 * h[1]), (pv[2] - mv[2]) / (2 * h[1])
    r0, r1, r2 = s[0] - p[0], s[1] - p[1], s[2] - p[2]
    a = tu0 * tu0 + tu1 * tu1 + tu2 * tu2
    b = tu0 * tv0 + tu1 * tv1 + tu2 * tv2
    c = tv0 * tv0 + tv1 * tv1 + tv2 * tv2
    gu = tu0 * r0 + tu1 * r1 + tu2 * r2
    gv = tv0 * r0 + tv1 * r1 + tv2 * r2
    det = a * c - b * b
    du = dv = 0.0
    if abs(det) > 1e-30:
        du, dv = -(c * gu - b * gv) / det, -(a * gv - b * gu) / det
    lim_u, lim_v = 0.25 * span[0], 0.25 * span[1]
    nu = min(max(u + min(max(du, -lim_u), lim_u), lo[0]), hi[0])
    nv = min(max(v + min(max(dv, -lim_v), lim_v), lo[1]), hi[1])
    return nu, nv, max(abs((nu - u) / span[0]), abs((nv - v) / span[1]))


@njit(cache=True, nogil=True)
def project_closed_form(kind, prm, points, uv, lo, hi, span, iterations, settle, dist, moved):
    """uv (n, 2) ← each point of (n, 3) projected on a closed-form surface (_closed_form's kind and prm) from its uv,
    Gauss–Newton with central differences of 1e-6 × span, until a step moves it by under `settle` × span or after
    `iterations` steps, inside [lo, hi]; dist (n,) ← |S(uv) − p|, moved (n,) ← its last step / span."""
    h = (1e-6 * span[0], 1e-6 * span[1])
    sin_b, cos_b = np.sin(prm[13]), np.cos(prm[13])
    for k in range(points.shape[0]):
        p = (points[k, 0], points[k, 1], points[k, 2])
        u, v = min(max(uv[k, 0], lo[0]), hi[0]), min(max(uv[k, 1], lo[1]), hi[1])
        last = 0.0
        for _ in range(iterations):
            s = _closed(kind, prm, u, v, sin_b, cos_b)
            pu, mu = _closed(kind, prm, u + h[0], v, sin_b, cos_b), _closed(kind, prm, u - h[0], v, sin_b, cos_b)
            pv, mv = _closed(kind, prm, u, v + h[1], sin_b, cos_b), _closed(kind, prm, u, v - h[1], sin_b, cos_b)
            u, v, last = _step(s, pu, mu, pv, mv, p, u, v, h, span, lo, hi)
            if last < settle:
                break
        x, y, z = _closed(kind, prm, u, v, sin_b, cos_b)
        uv[k, 0], uv[k, 1] = u, v
        dist[k] = np.sqrt((x - p[0]) ** 2 + (y - p[1]) ** 2 + (z - p[2]) ** 2)
        moved[k] = last


@njit(cache=True, nogil=True)
def project_bspline(pw, ub, vb, udeg, vdeg, uper, vper, points, uv, lo, hi, span, iterations, settle, dist, moved):
    """project_closed_form on a rational B-spline (pw, ub, vb as _bspline_kernel.point_kernel takes them), a periodic
    direction's parameter wrapped into [per[0], per[1]) where it is evaluated (per[1] ≤ per[0]: not periodic)."""
    h = (1e-6 * span[0], 1e-6 * span[1])
    work = scratch(udeg, vdeg)
    su = sv = -1
    for k in range(points.shape[0]):
        p = (points[k, 0], points[k, 1], points[k, 2])
        u, v = min(max(uv[k, 0], lo[0]), hi[0]), min(max(uv[k, 1], lo[1]), hi[1])
        last = 0.0
        for _ in range(iterations):
            wu, wv = wrapped(u, uper), wrapped(v, vper)
            x, y, z, su, sv = point_kernel(pw, ub, vb, udeg, vdeg, wu, wv, work, su, sv)
            ax, ay, az, su, sv = point_kernel(pw, ub, vb, udeg, vdeg, wrapped(u + h[0], uper), wv, work, su, sv)
            bx, by, bz, su, sv = point_kernel(pw, ub, vb, udeg, vdeg, wrapped(u - h[0], uper), wv, work, su, sv)
            cx, cy, cz, su, sv = point_kernel(pw, ub, vb, udeg, vdeg, wu, wrapped(v + h[1], vper), work, su, sv)
            dx, dy, dz, su, sv = point_kernel(pw, ub, vb, udeg, vdeg, wu, wrapped(v - h[1], vper), work, su, sv)
            u, v, last = _step((x, y, z), (ax, ay, az), (bx, by, bz), (cx, cy, cz), (dx, dy, dz), p, u, v, h, span,
                               lo, hi)
            if last < settle:
                break
        x, y, z, su, sv = point_kernel(pw, ub, vb, udeg, vdeg, wrapped(u, uper), wrapped(v, vper), work, su, sv)
        uv[k, 0], uv[k, 1] = u, v
        dist[k] = np.sqrt((x - p[0]) ** 2 + (y - p[1]) ** 2 + (z - p[2]) ** 2)
        moved[k] = last
