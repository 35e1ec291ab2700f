"""Compiled (numba) kernels of the thesis's bounding-box cusp-height method: slicing and the box rays."""

import numpy as np
from numba import njit, prange


@njit(cache=True, nogil=True)
def _find(keys, key):
    lo, hi = 0, keys.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        if keys[mid] < key:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(cache=True, nogil=True, parallel=True)
def box_cusp_kernel(seg_k, p1, e, side, length, b, frame2, layer, cell, origin2, nx, ny, cell_keys, cell_start,
                    cell_end, pts, normals, height):
    """Thesis 3.1 step 4 for every segment at once: the cloud points (sorted by (layer, cell) key, cells listed in
    cell_keys with [start, end) ranges) inside the segment's two boxes (+side: box s, −side: box s + ns), and the
    ray from each along its normal to the box boundary; height[box] = the largest distance (−inf: no point).
    Segments run in parallel, each writing its own two boxes only: the result is the serial one."""
    for s in prange(seg_k.shape[0]):
        _segment(np.int64(s), seg_k, p1, e, side, length, b, frame2, layer, cell, origin2, nx, ny, cell_keys,
                 cell_start, cell_end, pts, normals, height)  # int64: a prange index plus an int64 types as float


@njit(cache=True, nogil=True)
def _segment(s, seg_k, p1, e, side, length, b, frame2, layer, cell, origin2, nx, ny, cell_keys, cell_start,
             cell_end, pts, normals, height):
    """box_cusp_kernel's work for segment s."""
    ns = seg_k.shape[0]
    eps = 1e-9 * layer
    step = 2.0 * cell
    k = seg_k[s]
    L = length[s]
    n_sub = int(np.ceil(L / step)) if L > step else 1
    for q in range(n_sub):
        u0 = L * q / n_sub
        u1 = L * (q + 1) / n_sub
        xmin = 1e300
        xmax = -1e300
        ymin = 1e300
        ymax = -1e300
        for cu in range(2):
            for cv in range(2):
                uu = u0 if cu == 0 else u1
                vv = -layer if cv == 0 else layer
                px = p1[s, 0] + uu * e[s, 0] + vv * side[s, 0]
                py = p1[s, 1] + uu * e[s, 1] + vv * side[s, 1]
                pz = p1[s, 2] + uu * e[s, 2] + vv * side[s, 2]
                x = px * frame2[0, 0] + py * frame2[0, 1] + pz * frame2[0, 2]
                y = px * frame2[1, 0] + py * frame2[1, 1] + pz * frame2[1, 2]
                xmin = min(xmin, x)
                xmax = max(xmax, x)
                ymin = min(ymin, y)
                ymax = max(ymax, y)
        cx0 = max(int(np.floor((xmin - origin2[0]) / cell)), 0)
        cx1 = min(int(np.floor((xmax - origin2[0]) / cell)), nx - 1)
        cy0 = max(int(np.floor((ymin - origin2[1]) / cell)), 0)
        cy1 = min(int(np.floor((ymax - origin2[1]) / cell)), ny - 1)
        for cy in range(cy0, cy1 + 1):
            for cx in range(cx0, cx1 + 1):
                key = (k * ny + cy) * nx + cx
                at = _find(cell_keys, key)
                if at >= cell_keys.shape[0] or cell_keys[at] != key:
                    continue
                for p in range(cell_start[at], cell_end[at]):
                    rx = pts[p, 0] - p1[s, 0]
                    ry = pts[p, 1] - p1[s, 1]
                    rz = pts[p, 2] - p1[s, 2]
                    u = rx * e[s, 0] + ry * e[s, 1] + rz * e[s, 2]
                    v = rx * side[s, 0] + ry * side[s, 1] + rz * side[s, 2]
                    w = rx * b[0] + ry * b[1] + rz * b[2]
                    if u < -eps or u > L + eps or w < -eps or w > layer + eps or abs(v) > layer + eps:
                        continue
                    nb = normals[p, 0] * b[0] + normals[p, 1] * b[1] + normals[p, 2] * b[2]
                    ns_ = normals[p, 0] * side[s, 0] + normals[p, 1] * side[s, 1] + normals[p, 2] * side[s, 2]
                    for sign in (1.0, -1.0):
                        vv = sign * v
                        if vv < -eps:
                            continue
                        nv = sign * ns_
                        nw = nb
                        if abs(nv) <= 1e-9:  # a surface parallel to the wall says nothing about it
                            continue
                        if nv > 0:  # the wall P1P2 is at v = 0: the ray heads towards it
                            nv = -nv
                            nw = -nw
                        norm = np.hypot(nv, nw)
                        if norm <= 1e-12:
                            continue
                        nv /= norm
                        nw /= norm
                        tv = -vv / nv
                        if nw > 0:
                            tw = (layer - w) / nw
                        elif nw < 0:
                            tw = -w / nw
                        else:
                            tw = np.inf
                        dist = max(min(tv, tw), 0.0)
                        box = s if sign > 0 else s + ns
                        if dist > height[box]:
                            height[box] = dist


@njit(cache=True, nogil=True)
def slice_kernel(corners, z, z0, layer, first, count, offset, k_out, p1, p2, valid):
    """Thesis 3.1 step 2: triangle t meets planes z = z0 + k·layer for k in first[t] .. first[t] + count[t] − 1;
    row offset[t] + i gets that cut's slice index and end points (valid: the plane crosses two sides)."""
    for t in range(corners.shape[0]):
        for i in range(count[t]):
            row = offset[t] + i
            k = first[t] + i
            h = z0 + k * layer
            k_out[row] = k
            found = 0
            for a in range(3):
                b = (a + 1) % 3
                za = z[t, a]
                zb = z[t, b]
                if (za - h) * (zb - h) < 0 or (za == h and zb != h):
                    f = (h - za) / (zb - za)
                    for d in range(3):
                        x = corners[t, a, d] + f * (corners[t, b, d] - corners[t, a, d])
                        if found == 0:
                            p1[row, d] = x
                        else:
                            p2[row, d] = x
                    found += 1
            if found == 2:
                dx = p2[row, 0] - p1[row, 0]
                dy = p2[row, 1] - p1[row, 1]
                dz = p2[row, 2] - p1[row, 2]
                valid[row] = dx * dx + dy * dy + dz * dz > 1e-24
            else:
                valid[row] = False
