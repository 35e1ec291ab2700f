"""Where a mesh is wrong: boundary loops, non-manifold vertices, self-intersections, and defect locations."""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from amprep.geometry.core.checks import degenerate_mask
from amprep.geometry.core.edges import EdgeIncidence, edge_incidence
from amprep.geometry.core.mesh import Mesh
from amprep.geometry.core.progress import ProgressFn
from amprep.geometry.core.vectors import cross


def boundary_loops(mesh: Mesh, inc: EdgeIncidence | None = None) -> list[float]:
    """Lengths (mm) of the loops formed by boundary edges (edges used once), longest first."""
    inc = inc or edge_incidence(mesh.triangles)
    edges = inc.edges[inc.count == 1]
    if len(edges) == 0:
        return []
    verts, local = np.unique(edges, return_inverse=True)
    local = local.reshape(-1, 2)
    graph = coo_matrix((np.ones(len(local)), (local[:, 0], local[:, 1])), shape=(len(verts),) * 2)
    _, labels = connected_components(graph, directed=False)
    lengths = np.linalg.norm(mesh.vertices[edges[:, 0]] - mesh.vertices[edges[:, 1]], axis=1)
    per_loop = np.bincount(labels[local[:, 0]], weights=lengths)
    return sorted((float(x) for x in per_loop), reverse=True)


def nonmanifold_vertices(mesh: Mesh, inc: EdgeIncidence | None = None) -> np.ndarray:
    """(k,) vertices whose triangles form more than one fan (joined through edges at the vertex): a bow-tie."""
    t = mesh.triangles
    m = len(t)
    if m == 0:
        return np.zeros(0, np.int64)
    inc = inc or edge_incidence(t)
    corner_id = np.arange(3 * m).reshape(m, 3)  # corner (triangle, k) ↔ vertex t[tri, k]
    # side k joins corners k and k+1; the triangles sharing an edge join their corners at both ends
    side = np.repeat(np.arange(3)[None, :], m, axis=0)
    edge = inc.edge_of.reshape(-1)
    tri = np.repeat(np.arange(m), 3)
    k = side.reshape(-1)
    order = np.argsort(edge, kind="stable")
    e_sorted = edge[order]
    same = e_sorted[1:] == e_sorted[:-1]  # consecutive uses of one edge
    a, b = order[:-1][same], order[1:][same]
    rows, cols = [], []
    for end in (0, 1):  # the vertex at each end of the shared edge
        va = t[tri[a], (k[a] + end) % 3]
        # in triangle b, find the corner holding the same vertex
        kb0, kb1 = k[b], (k[b] + 1) % 3
        cb = np.where(t[tri[b], kb0] == va, kb0, kb1)
        rows.append(corner_id[tri[a], (k[a] + end) % 3])
        cols.append(corner_id[tri[b], cb])
    r, c = np.concatenate(rows), np.concatenate(cols)
    graph = coo_matrix((np.ones(len(r)), (r, c)), shape=(3 * m, 3 * m))
    _, labels = connected_components(graph, directed=False)
    fan = np.unique(t.reshape(-1).astype(np.int64) * (3 * m) + labels)  # (vertex, fan) pairs as one int64 key
    fans = np.bincount(fan // (3 * m), minlength=len(mesh.vertices))
    return np.flatnonzero(fans > 1)


def _morton(points: np.ndarray, bits: int = 10) -> np.ndarray:
    """(n,) int64 Morton codes of (n, 3) points quantised to 2^bits cells per axis of their bounding box."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    q = ((points - lo) / np.maximum(hi - lo, 1e-300) * ((1 << bits) - 1)).astype(np.int64)
    code = np.zeros(len(points), np.int64)
    for b in range(bits):
        for axis in range(3):
            code |= ((q[:, axis] >> b) & 1) << (3 * b + axis)
    return code


def box_tree(lo: np.ndarray, hi: np.ndarray, leaf_size: int = 4) -> tuple[np.ndarray, np.ndarray, int, np.ndarray]:
    """Implicit bounding-volume hierarchy over boxes (n, 3): boxes in Morton order of their centres, leaf_size per
    leaf, leaves padded to a power of two; returns (node lo (2P−1, 3), node hi, number of inner nodes P−1, order)."""
    n = len(lo)
    order = np.argsort(_morton((lo + hi) / 2), kind="stable")
    leaves = -(-n // leaf_size)
    size = 1 << max(0, int(np.ceil(np.log2(max(leaves, 1)))))
    pad = size * leaf_size - n
    slo = np.concatenate([lo[order], np.full((pad, 3), np.inf)]).reshape(size, leaf_size, 3).min(axis=1)
    shi = np.concatenate([hi[order], np.full((pad, 3), -np.inf)]).reshape(size, leaf_size, 3).max(axis=1)
    node_lo = np.empty((2 * size - 1, 3))
    node_hi = np.empty((2 * size - 1, 3))
    node_lo[size - 1:], node_hi[size - 1:] = slo, shi
    width = size // 2
    while width >= 1:  # each level from its children, bottom up
        k = np.arange(width - 1, 2 * width - 1)
        node_lo[k] = np.minimum(node_lo[2 * k + 1], node_lo[2 * k + 2])
        node_hi[k] = np.maximum(node_hi[2 * k + 1], node_hi[2 * k + 2])
        width //= 2
    return node_lo, node_hi, size - 1, order


#: the broad phase stops after this many candidate pairs (a triangle soup has ~n²/2): the test is then incomplete
MAX_PAIRS = 20_000_000
#: candidate pairs found per kernel call, between which cancel and the time limit are checked (progress)
PAIRS_PER_CALL = 2_000_000


def _candidate_pairs(corners: np.ndarray, triangles: np.ndarray, progress: ProgressFn | None = None,
                     max_pairs: int = MAX_PAIRS) -> tuple[np.ndarray, bool]:
    """((p, 2) triangle pairs i < j whose bounding boxes overlap and which share no vertex, complete): the broad
    phase, each box queried against an implicit BVH in Morton order (the compiled kernel of _bvh_kernel.py), in calls
    of at most PAIRS_PER_CALL pairs with `progress` between them, and stopped (complete False) past max_pairs."""
    from amprep.geometry.measure._bvh_kernel import overlap_pairs_kernel

    lo, hi = corners.min(axis=1), corners.max(axis=1)
    node_lo, node_hi, n_inner, order = box_tree(lo, hi)
    tris = np.ascontiguousarray(triangles, dtype=np.int64)
    stack = np.empty(256, np.int64)
    n = len(lo)
    out = np.empty((min(PAIRS_PER_CALL, max_pairs) + n, 2), np.int64)  # room for the last box's pairs past a limit
    pieces, total, i = [], 0, 0
    while i < n:
        limit = min(PAIRS_PER_CALL, max_pairs - total)
        count, i = overlap_pairs_kernel(node_lo, node_hi, n_inner, 4, order, lo, hi, tris, out, stack, i, n, limit)
        if count > len(out):  # one box overlapping more than the room left: its pairs are not all written
            return np.concatenate(pieces) if pieces else np.zeros((0, 2), np.int64), False
        pieces.append(out[:count].copy())
        total += count
        if progress:
            progress("self-intersections", i / n)
        if i < n and total >= max_pairs:
            return np.concatenate(pieces), False
    return np.concatenate(pieces) if pieces else np.zeros((0, 2), np.int64), True


def _interval_on_line(p: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where a triangle meets the other's plane, as an interval of the line parameter: p (n, 3) vertex parameters
    along the intersection line, d (n, 3) signed vertex distances to the other plane (the triangle straddles it)."""
    q, dq = np.roll(p, -1, axis=1), np.roll(d, -1, axis=1)
    crossing = d * dq < 0
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(crossing, p + (q - p) * d / (d - dq), np.nan)
    on = np.where(d == 0, p, np.nan)
    cand = np.concatenate([t, on], axis=1)
    return np.nanmin(cand, axis=1), np.nanmax(cand, axis=1)


def triangles_cross(A: np.ndarray, B: np.ndarray, rel_eps: float = 1e-12) -> np.ndarray:
    """(n,) bool for (n, 3, 3) triangle pairs: each has vertices strictly on both sides of the other's plane and their
    stretches on the planes' common line overlap over a positive length (Möller's interval test). Coplanar pairs
    and pairs that only touch are not crossings."""
    nA = cross(A[:, 1] - A[:, 0], A[:, 2] - A[:, 0])
    nB = cross(B[:, 1] - B[:, 0], B[:, 2] - B[:, 0])
    scale = np.maximum(np.ptp(A.reshape(-1, 3), axis=0).max(), 1e-300)
    dA = np.einsum("nkd,nd->nk", A - B[:, None, 0], nB)
    dB = np.einsum("nkd,nd->nk", B - A[:, None, 0], nA)
    tolA = rel_eps * np.linalg.norm(nB, axis=1)[:, None] * scale
    tolB = rel_eps * np.linalg.norm(nA, axis=1)[:, None] * scale
    dA = np.where(np.abs(dA) <= tolA, 0.0, dA)
    dB = np.where(np.abs(dB) <= tolB, 0.0, dB)
    straddle = ((dA > 0).any(1) & (dA < 0).any(1)) & ((dB > 0).any(1) & (dB < 0).any(1))
    line = cross(nA, nB)
    out = np.zeros(len(A), bool)
    if not straddle.any():
        return out
    s = np.flatnonzero(straddle)
    dirn = line[s] / np.linalg.norm(line[s], axis=1)[:, None]
    a0, a1 = _interval_on_line(np.einsum("nkd,nd->nk", A[s], dirn), dA[s])
    b0, b1 = _interval_on_line(np.einsum("nkd,nd->nk", B[s], dirn), dB[s])
    out[s] = (np.minimum(a1, b1) - np.maximum(a0, b0)) > 1e-9 * scale
    return out


def self_intersections(mesh: Mesh, examples: int = 100, progress: ProgressFn | None = None,
                       max_pairs: int = MAX_PAIRS) -> tuple[int, np.ndarray, bool]:
    """(count, (≤ examples, 2) pairs, complete) of triangles that share no vertex and cross each other
    (triangles_cross); coplanar overlaps and duplicates are counted elsewhere. `progress` is called between blocks
    (a cancel or a time limit raised there stops the test); past max_pairs candidate pairs (a soup) the test stops
    and complete is False, the count a lower bound."""
    t = mesh.triangles
    if len(t) < 2:
        return 0, np.zeros((0, 2), np.int64), True
    idx = np.flatnonzero(~degenerate_mask(mesh))
    if len(idx) < 2:  # nothing with an area to cross (an STL of points, a single facet)
        return 0, np.zeros((0, 2), np.int64), True
    corners = mesh.vertices[t[idx]]
    pairs, complete = _candidate_pairs(corners, t[idx], progress, max_pairs)
    hit = np.zeros(len(pairs), bool)
    step = 500_000
    for s in range(0, len(pairs), step):
        p = pairs[s:s + step]
        hit[s:s + step] = triangles_cross(corners[p[:, 0]], corners[p[:, 1]])
        if progress:
            progress("self-intersections", 1.0)
    found = idx[pairs[hit]]
    return int(len(found)), found[:examples], complete


def defect_locations(mesh: Mesh, inc: EdgeIncidence, nmv: np.ndarray,
                     cap: int = 1000) -> dict[str, dict]:  # type: ignore[type-arg]
    """Up to `cap` locations per defect kind: edges as vertex pairs with coordinates, triangles as indices with
    corners, vertices with coordinates (for the viewer to draw); `nmv` the non-manifold vertices
    (nonmanifold_vertices)."""
    v = mesh.vertices

    def edges(mask: np.ndarray) -> dict:  # type: ignore[type-arg]
        e = inc.edges[mask][:cap]
        return {"count": int(mask.sum()), "edges": e.tolist(), "coordinates": v[e].round(6).tolist()}

    def triangles(index: np.ndarray) -> dict:  # type: ignore[type-arg]
        i = index[:cap]
        return {"count": int(len(index)), "triangles": i.tolist(), "coordinates": v[mesh.triangles[i]].round(6).tolist()}

    srt = np.sort(mesh.triangles, axis=1)
    order = np.lexsort(srt.T[::-1])  # stable: each group of copies in index order
    copy = (srt[order[1:]] == srt[order[:-1]]).all(axis=1)
    dup_mask = np.zeros(len(srt), bool)
    dup_mask[order[1:][copy]] = True  # every copy after the first
    return {
        "boundary_edges": edges(inc.count == 1),
        "nonmanifold_edges": edges(inc.count > 2),
        "misoriented_edges": edges((inc.count == 2) & (inc.forward != 1)),
        "degenerate_triangles": triangles(np.flatnonzero(degenerate_mask(mesh))),
        "duplicate_triangles": triangles(np.flatnonzero(dup_mask)),
        "nonmanifold_vertices": {"count": int(len(nmv)), "vertices": nmv[:cap].tolist(),
                                 "coordinates": v[nmv[:cap]].round(6).tolist()},
    }
