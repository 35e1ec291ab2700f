"""Compiled (numba) objective of the minimum-zone cylindricity: the width of the radial band about an axis."""

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def zone_width(points, ax, ay, az, dx, dy, dz):
    """max_i r_i − min_i r_i, r_i the distance of points[i] (n, 3) from the axis through a along the unit d."""
    rmin = np.inf
    rmax = -np.inf
    for i in range(points.shape[0]):
        x = points[i, 0] - ax
        y = points[i, 1] - ay
        z = points[i, 2] - az
        t = x * dx + y * dy + z * dz
        r2 = x * x + y * y + z * z - t * t
        r = np.sqrt(r2) if r2 > 0.0 else 0.0
        if r < rmin:
            rmin = r
        if r > rmax:
            rmax = r
    return rmax - rmin


@njit(cache=True, nogil=True)
def zone_at(points, a, d, e1, e2, x):
    """zone_width about the axis tilted by x[0:2] (along e1, e2) and shifted by x[2:4] from (a, d)."""
    dx = d[0] + x[0] * e1[0] + x[1] * e2[0]
    dy = d[1] + x[0] * e1[1] + x[1] * e2[1]
    dz = d[2] + x[0] * e1[2] + x[1] * e2[2]
    n = np.sqrt(dx * dx + dy * dy + dz * dz)
    return zone_width(points, a[0] + x[2] * e1[0] + x[3] * e2[0], a[1] + x[2] * e1[1] + x[3] * e2[1],
                      a[2] + x[2] * e1[2] + x[3] * e2[2], dx / n, dy / n, dz / n)


@njit(cache=True, nogil=True)
def nelder_mead_zone(points, a, d, e1, e2, simplex, xatol, fatol, maxiter):
    """Nelder–Mead (reflection 1, expansion 2, contraction ½, shrink ½; scipy's stopping rule: every vertex within
    xatol and every value within fatol of the best) of zone_at over x (4,) from simplex (5, 4); returns (x, f)."""
    m = simplex.shape[0]
    nd = simplex.shape[1]
    sim = simplex.copy()
    f = np.empty(m)
    for i in range(m):
        f[i] = zone_at(points, a, d, e1, e2, sim[i])
    for _ in range(maxiter):
        order = np.argsort(f)
        sim = sim[order]
        f = f[order]
        xspread = 0.0
        fspread = 0.0
        for i in range(1, m):
            fspread = max(fspread, abs(f[i] - f[0]))
            for j in range(nd):
                xspread = max(xspread, abs(sim[i, j] - sim[0, j]))
        if xspread <= xatol and fspread <= fatol:
            break
        centre = np.zeros(nd)
        for i in range(m - 1):
            centre += sim[i]
        centre /= m - 1
        xr = centre + (centre - sim[-1])
        fr = zone_at(points, a, d, e1, e2, xr)
        if fr < f[0]:
            xe = centre + 2.0 * (centre - sim[-1])
            fe = zone_at(points, a, d, e1, e2, xe)
            if fe < fr:
                sim[-1], f[-1] = xe, fe
            else:
                sim[-1], f[-1] = xr, fr
        elif fr < f[-2]:
            sim[-1], f[-1] = xr, fr
        else:
            if fr < f[-1]:
                xc = centre + 0.5 * (xr - centre)
            else:
                xc = centre + 0.5 * (sim[-1] - centre)
            fc = zone_at(points, a, d, e1, e2, xc)
            if fc < min(fr, f[-1]):
                sim[-1], f[-1] = xc, fc
            else:
                for i in range(1, m):
                    sim[i] = sim[0] + 0.5 * (sim[i] - sim[0])
                    f[i] = zone_at(points, a, d, e1, e2, sim[i])
    best = np.argmin(f)
    return sim[best].copy(), f[best]
