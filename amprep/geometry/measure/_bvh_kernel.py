"""Compiled (numba) traversal of an implicit bounding-volume hierarchy: box-overlap pairs for the broad phase."""

from numba import njit


@njit(cache=True, nogil=True)
def overlap_pairs_kernel(node_lo, node_hi, n_inner, leaf_size, order, lo, hi, tris, out, stack, first, last, limit):
    """Pairs (i, j), i < j, first ≤ i < last, of boxes lo/hi (n, 3) that overlap and whose triangles (n, 3) share no
    vertex, written to `out` (pairs past its length are counted, not written).

    The tree is a heap: node k has children 2k+1, 2k+2; nodes ≥ n_inner are leaves, leaf l holding
    order[l·leaf_size : (l+1)·leaf_size]. Stops before a box i once `limit` pairs are found, so a call's work is
    bounded; returns (pairs found, the first box not queried)."""
    n = lo.shape[0]
    count = 0
    cap = out.shape[0]
    n_nodes = node_lo.shape[0]
    for i in range(first, last):
        if count >= limit:
            return count, i
        top = 0
        stack[0] = 0
        top = 1
        while top > 0:
            top -= 1
            k = stack[top]
            if (node_lo[k, 0] > hi[i, 0] or node_hi[k, 0] < lo[i, 0] or node_lo[k, 1] > hi[i, 1]
                    or node_hi[k, 1] < lo[i, 1] or node_lo[k, 2] > hi[i, 2] or node_hi[k, 2] < lo[i, 2]):
                continue
            if k >= n_inner:
                start = (k - n_inner) * leaf_size
                for s in range(start, min(start + leaf_size, n)):
                    j = order[s]
                    if j <= i:
                        continue
                    if (lo[j, 0] > hi[i, 0] or hi[j, 0] < lo[i, 0] or lo[j, 1] > hi[i, 1] or hi[j, 1] < lo[i, 1]
                            or lo[j, 2] > hi[i, 2] or hi[j, 2] < lo[i, 2]):
                        continue
                    shared = False
                    for a in range(3):
                        for b in range(3):
                            if tris[i, a] == tris[j, b]:
                                shared = True
                    if shared:
                        continue
                    if count < cap:
                        out[count, 0] = i
                        out[count, 1] = j
                    count += 1
            else:
                c = 2 * k + 1
                if c < n_nodes:
                    stack[top] = c
                    top += 1
                if c + 1 < n_nodes:
                    stack[top] = c + 1
                    top += 1
    return count, last

