"""Compiled smallest angles, unit normals and flip candidates of triangles over nodes, with no (m, 3, 3) gather: each
product and sum in the order of the numpy formulas beside them (regularity.min_angles, core.vectors.unit_normals, written
out per component as core.vectors does), so the two give the same bits; the angle's arctan2 is left to numpy."""

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, inline="always")
def _angle_parts(xyz, i0, i1, i2):
    """(|a × b|, a · b, shortest side > 0) of a triangle's corner opposite its shortest side (the first, numpy's
    argmin: a NaN side counts as shortest), a and b its two sides from that corner."""
    # side k runs from corner k to corner k+1
    s0x, s0y, s0z = xyz[i1, 0] - xyz[i0, 0], xyz[i1, 1] - xyz[i0, 1], xyz[i1, 2] - xyz[i0, 2]
    s1x, s1y, s1z = xyz[i2, 0] - xyz[i1, 0], xyz[i2, 1] - xyz[i1, 1], xyz[i2, 2] - xyz[i1, 2]
    s2x, s2y, s2z = xyz[i0, 0] - xyz[i2, 0], xyz[i0, 1] - xyz[i2, 1], xyz[i0, 2] - xyz[i2, 2]
    q0 = s0x * s0x + s0y * s0y + s0z * s0z
    q1 = s1x * s1x + s1y * s1y + s1z * s1z
    q2 = s2x * s2x + s2y * s2y + s2z * s2z
    k, q = 0, q0
    if not np.isnan(q0):
        if np.isnan(q1) or q1 < q0:
            k, q = 1, q1
        if not np.isnan(q) and (np.isnan(q2) or q2 < q):
            k, q = 2, q2
    if k == 0:  # a = side k+2, b = −side k+1
        a0, a1, a2, b0, b1, b2 = s2x, s2y, s2z, -s1x, -s1y, -s1z
    elif k == 1:
        a0, a1, a2, b0, b1, b2 = s0x, s0y, s0z, -s2x, -s2y, -s2z
    else:
        a0, a1, a2, b0, b1, b2 = s1x, s1y, s1z, -s0x, -s0y, -s0z
    c0, c1, c2 = a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0
    return np.sqrt(c0 * c0 + c1 * c1 + c2 * c2), a0 * b0 + a1 * b1 + a2 * b2, q > 0


@njit(cache=True, nogil=True)
def min_angle_parts(xyz, tris, y, x, ok):
    """y, x, ok (m,) of triangles tris (m, 3) over xyz (n, 3): the smallest angle is arctan2(y, x) where ok."""
    for m in range(tris.shape[0]):
        y[m], x[m], ok[m] = _angle_parts(xyz, tris[m, 0], tris[m, 1], tris[m, 2])


@njit(cache=True, nogil=True, inline="always")
def _unit_normal(xyz, i0, i1, i2, out):
    """out (3,) ← (c₁ − c₀) × (c₂ − c₀) / its length, 0 where that length is not > 0 (core.vectors.unit_normals)."""
    ax, ay, az = xyz[i1, 0] - xyz[i0, 0], xyz[i1, 1] - xyz[i0, 1], xyz[i1, 2] - xyz[i0, 2]
    bx, by, bz = xyz[i2, 0] - xyz[i0, 0], xyz[i2, 1] - xyz[i0, 1], xyz[i2, 2] - xyz[i0, 2]
    nx, ny, nz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
    length = np.sqrt(nx * nx + ny * ny + nz * nz)
    if length > 0:
        out[0], out[1], out[2] = nx / length, ny / length, nz / length
    else:
        out[0], out[1], out[2] = 0.0, 0.0, 0.0


@njit(cache=True, nogil=True)
def unit_normals(xyz, tris, out):
    """out (m, 3) ← unit normals of triangles tris (m, 3) over xyz (n, 3) (0 for a degenerate one)."""
    for m in range(tris.shape[0]):
        _unit_normal(xyz, tris[m, 0], tris[m, 1], tris[m, 2], out[m])


@njit(cache=True, nogil=True)
def flip_candidates(xyz, uv, tris, normals, t1, k1, t2, k2, new, y, x, ok, fold_old, fold_new, new_normals, area):
    """For each shared side (triangle t1's side k1 is t2's side k2; p of them): new (2p, 3) the flipped pair (rows
    j, p + j: [a, d, c], [d, b, c] with t1 = [a, b, c] from corner k1, d t2's far corner), their angle parts y, x, ok
    (2p,), new_normals (2p, 3), fold_old (p,) the old pair's normals' dot (normals (t, 3)), fold_new (p,) the new's,
    area (2p,) twice their signed (u,v) areas."""
    p = t1.shape[0]
    for j in range(p):
        a, b, c = tris[t1[j], k1[j]], tris[t1[j], (k1[j] + 1) % 3], tris[t1[j], (k1[j] + 2) % 3]
        d = tris[t2[j], (k2[j] + 2) % 3]
        new[j, 0], new[j, 1], new[j, 2] = a, d, c
        new[p + j, 0], new[p + j, 1], new[p + j, 2] = d, b, c
        n1, n2 = normals[t1[j]], normals[t2[j]]
        fold_old[j] = n1[0] * n2[0] + n1[1] * n2[1] + n1[2] * n2[2]
        for r in (j, p + j):
            i0, i1, i2 = new[r, 0], new[r, 1], new[r, 2]
            y[r], x[r], ok[r] = _angle_parts(xyz, i0, i1, i2)
            _unit_normal(xyz, i0, i1, i2, new_normals[r])
            area[r] = ((uv[i1, 0] - uv[i0, 0]) * (uv[i2, 1] - uv[i0, 1])
                       - (uv[i1, 1] - uv[i0, 1]) * (uv[i2, 0] - uv[i0, 0]))
        m1, m2 = new_normals[j], new_normals[p + j]
        fold_new[j] = m1[0] * m2[0] + m1[1] * m2[1] + m1[2] * m2[2]
