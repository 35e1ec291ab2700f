"""Compiled (numba) walk of the irregular Butterfly mask around each request's centre: the same sums, in the same
order, as a numpy walk over all requests at once, without its (requests × valence) temporaries."""

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def ring_walk(v, tgt, next_out, centre, first, h0, k, table):
    """(pos (r, 3), ring2 (r,), ringm2 (r,)): 3/4·v[centre] + Σ_j table[k, j]·v[q_j] with q_0 = first and q_j the target
    of next_out^(j−1)(h0) for j = 1..k−1 (stopping at a hole, h = −1); ring2 = q_2 and ringm2 = q_(k−2) when reached
    (else −1)."""
    r = centre.shape[0]
    pos = np.empty((r, 3))
    ring2 = np.full(r, -1, np.int64)
    ringm2 = np.full(r, -1, np.int64)
    for i in range(r):
        c, f, ki = centre[i], first[i], k[i]
        w0 = table[ki, 0]
        for d in range(3):
            pos[i, d] = 0.75 * v[c, d] + w0 * v[f, d]
        h = h0[i]
        if ki <= 1:
            continue
        for j in range(1, ki):
            if h < 0:
                break
            q = tgt[h]
            w = table[ki, j]
            for d in range(3):
                pos[i, d] += w * v[q, d]
            if j == 2:
                ring2[i] = q
            if j == ki - 2:
                ringm2[i] = q
            h = next_out[h]
    return pos, ring2, ringm2
