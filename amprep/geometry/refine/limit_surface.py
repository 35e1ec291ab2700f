"""The modified Butterfly limit surface of an STL as a function of (input triangle, barycentric point), after 001:
the input refined `depth` levels by butterfly.py (children of triangle p at level l are p + k·m_l, k = 0..3, corner
k's child then the middle one), a point located by descending the regular 1-to-4 split of its triangle's (u, v)
domain and evaluated on the finest level's triangle (exact at every node of levels ≤ depth, linear between them).
The other way, a 3D point is localised on the surface by a k-d tree of sample points spread over the finest
triangles (scipy's, in place of 001's octree; slivers get as many samples as their length needs) and its nearest
point there, mapped back up to (input triangle, barycentric).

`remesh_to_edge` uses it: longest-edge bisection with closure (an edge is split once for both its triangles, so the
mesh stays closed by topology) until no edge exceeds the given length, every new node evaluated on the limit surface.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.core.edges import edge_incidence
from amprep.geometry.core.mesh import Mesh
from amprep.geometry.core.progress import Progress, ProgressFn
from amprep.geometry.core.vectors import norms, triangle_normals
from amprep.geometry.refine.butterfly import ButterflyParams, ButterflyResult, butterfly_refine

#: the finest level kept for evaluation: 4^depth · m triangles, at most this many (depth ≥ 1)
EVAL_BUDGET = 4_000_000
#: longest-edge bisection rounds before giving up (each round at least halves every marked edge)
MAX_ROUNDS = 64

# child k's corners as barycentric points of its parent (rows: the child's corners)
_CHILD = np.array([[[1, 0, 0], [.5, .5, 0], [.5, 0, .5]],
                   [[0, 1, 0], [0, .5, .5], [.5, .5, 0]],
                   [[0, 0, 1], [.5, 0, .5], [0, .5, .5]],
                   [[.5, .5, 0], [0, .5, .5], [.5, 0, .5]]])


def _to_child(bary: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(k (q,), local (q, 3)): the child of the 1-to-4 split holding each barycentric point, and the point in it."""
    b0, b1, b2 = bary[:, 0], bary[:, 1], bary[:, 2]
    k = np.where(b0 >= 0.5, 0, np.where(b1 >= 0.5, 1, np.where(b2 >= 0.5, 2, 3)))
    local = np.select([k[:, None] == 0, k[:, None] == 1, k[:, None] == 2],
                      [np.stack([2 * b0 - 1, 2 * b1, 2 * b2], 1), np.stack([2 * b1 - 1, 2 * b2, 2 * b0], 1),
                       np.stack([2 * b2 - 1, 2 * b0, 2 * b1], 1)],
                      np.stack([1 - 2 * b2, 1 - 2 * b0, 1 - 2 * b1], 1))
    return k, np.clip(local, 0.0, 1.0)


@dataclass(frozen=True)
class LimitSurface:
    """The limit surface over a mesh of m triangles: fine (4^depth·m triangles) from `depth` Butterfly levels, and
    that refinement's record (node classes, triangles by region)."""

    coarse: Mesh
    fine: Mesh
    depth: int
    refinement: ButterflyResult

    @classmethod
    def of(cls, mesh: Mesh, params: ButterflyParams = ButterflyParams(), depth: int | None = None,
           progress: ProgressFn | None = None) -> LimitSurface:
        """Refine `depth` levels (default: as many as EVAL_BUDGET allows, 1 to 3)."""
        m = mesh.n_triangles
        if depth is None:
            depth = int(np.clip(np.floor(np.log(max(EVAL_BUDGET / max(m, 1), 1)) / np.log(4)), 1, 3))
        result = butterfly_refine(mesh, ButterflyParams(depth, params.feature_angle, params.flat_faces), progress)
        return cls(mesh, result.mesh, depth, result)

    def evaluate(self, tri: np.ndarray, bary: np.ndarray) -> np.ndarray:
        """(q, 3) points of the limit surface at (q,) input triangles and (q, 3) barycentric coordinates."""
        m = self.coarse.n_triangles
        idx = np.asarray(tri, np.int64).copy()
        b = np.asarray(bary, float)
        b = b / b.sum(axis=1, keepdims=True)
        for level in range(self.depth):
            k, b = _to_child(b)
            idx = idx + k * (m * 4**level)
        corners = self.fine.vertices[self.fine.triangles[idx]]  # (q, 3, 3)
        return np.einsum("qk,qkd->qd", b, corners)

    def locate(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(tri (q,), bary (q, 3), distance (q,)): the nearest point of the limit surface to each of (q, 3) points,
        as an input triangle and barycentric point (nearest_on_mesh on the finest level, mapped back up)."""
        d, f, b = nearest_on_mesh(np.asarray(points, float), self.fine)
        tri, bary = self._lift(f, b)
        return tri, bary, d

    def _lift(self, f: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Fine triangles and barycentric points in them → input triangles and barycentric points in those."""
        m = self.coarse.n_triangles
        idx = f.astype(np.int64).copy()
        for level in reversed(range(self.depth)):
            size = m * 4**level
            k, idx = idx // size, idx % size
            b = np.einsum("qk,qkd->qd", b, _CHILD[k])
        return idx, b


def _samples(corners: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """((s, 3) points, (s,) triangle) on a grid over each of (m, 3, 3) triangles, ceil(|side|/spacing) steps along
    its two sides from corner 0 (at least its corners and centroid): every point of a triangle lies within
    `spacing` of one of its samples, however long and thin it is."""
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    na = np.maximum(np.ceil(np.linalg.norm(b - a, axis=1) / spacing), 1).astype(np.int64)
    nb = np.maximum(np.ceil(np.linalg.norm(c - a, axis=1) / spacing), 1).astype(np.int64)
    pts, owner = [corners.mean(axis=1)], [np.arange(len(corners))]
    for n_a, n_b in set(zip(na.tolist(), nb.tolist())):
        tri = np.flatnonzero((na == n_a) & (nb == n_b))
        i, j = np.meshgrid(np.arange(n_a + 1), np.arange(n_b + 1), indexing="ij")
        keep = i / n_a + j / n_b <= 1 + 1e-12
        u, w = (i[keep] / n_a)[None, :, None], (j[keep] / n_b)[None, :, None]
        grid = a[tri, None] + u * (b[tri] - a[tri])[:, None] + w * (c[tri] - a[tri])[:, None]
        pts.append(grid.reshape(-1, 3))
        owner.append(np.repeat(tri, keep.sum()))
    return np.concatenate(pts), np.concatenate(owner)


def nearest_on_mesh(points: np.ndarray, mesh: Mesh, candidates: int = 16
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """((q,) distance, (q,) triangle, (q, 3) barycentric): the nearest point of a mesh's triangles to each of (q, 3)
    points. Candidates come from a k-d tree of sample points on every triangle (_samples, at the median side
    length); where the `candidates` nearest samples might not hold the nearest triangle (the farthest of them is
    closer than the best distance found + the spacing), every triangle with a sample within that reach is tried."""
    corners = mesh.corners
    sides = np.linalg.norm(corners - np.roll(corners, -1, axis=1), axis=2)
    spacing = max(float(np.median(sides)), 1e-9)
    pts, owner = _samples(corners, spacing)
    tree = cKDTree(pts)
    k = min(candidates, len(pts))
    reach, idx = tree.query(points, k=k)
    reach, idx = np.asarray(reach).reshape(len(points), k), np.asarray(idx).reshape(len(points), k)
    best_d = np.full(len(points), np.inf)
    best_t = np.zeros(len(points), np.int64)
    best_b = np.zeros((len(points), 3))

    def consider(rows: np.ndarray, tris: np.ndarray) -> None:
        q, bary = _closest_on_triangles(points[rows], corners[tris])
        d = np.linalg.norm(points[rows] - q, axis=1)
        order = np.lexsort((tris, d))[::-1]  # ties: the lowest triangle wins (written last)
        rows, d, tris, bary = rows[order], d[order], tris[order], bary[order]
        better = d < best_d[rows]
        ties = (d == best_d[rows]) & (tris < best_t[rows])
        take = better | ties
        best_d[rows[take]], best_t[rows[take]], best_b[rows[take]] = d[take], tris[take], bary[take]

    for j in range(k):
        consider(np.arange(len(points)), owner[idx[:, j]])
    unsure = np.flatnonzero(reach[:, -1] < best_d + spacing)
    if len(unsure) and k < len(pts):
        lists = tree.query_ball_point(points[unsure], best_d[unsure] + spacing)
        rows = np.repeat(unsure, [len(x) for x in lists])
        if len(rows):
            consider(rows, owner[np.concatenate([np.asarray(x, np.int64) for x in lists])])
    return best_d, best_t, best_b


def _closest_on_triangles(p: np.ndarray, tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((q, 3) nearest points, (q, 3) their barycentric coordinates) of (q, 3) points on (q, 3, 3) triangles
    (Ericson's region tests, vectorised)."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = (ab * ap).sum(1), (ac * ap).sum(1)
    bp = p - b
    d3, d4 = (ab * bp).sum(1), (ac * bp).sum(1)
    cp = p - c
    d5, d6 = (ab * cp).sum(1), (ac * cp).sum(1)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = va + vb + vc
        v_in, w_in = vb / denom, vc / denom
        t_ab = d1 / (d1 - d3)
        t_ac = d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
    bary = np.stack([1 - v_in - w_in, v_in, w_in], 1)
    regions = [
        ((d1 <= 0) & (d2 <= 0), np.array([1.0, 0, 0])),
        ((d3 >= 0) & (d4 <= d3), np.array([0, 1.0, 0])),
        ((d6 >= 0) & (d5 <= d6), np.array([0, 0, 1.0])),
    ]
    edge_ab = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
    edge_ac = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
    edge_bc = (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0)
    bary = np.where(edge_bc[:, None], np.stack([np.zeros_like(t_bc), 1 - t_bc, t_bc], 1), bary)
    bary = np.where(edge_ac[:, None], np.stack([1 - t_ac, np.zeros_like(t_ac), t_ac], 1), bary)
    bary = np.where(edge_ab[:, None], np.stack([1 - t_ab, t_ab, np.zeros_like(t_ab)], 1), bary)
    for mask, corner in reversed(regions):
        bary = np.where(mask[:, None], corner, bary)
    bary = np.nan_to_num(bary, nan=1 / 3)
    return np.einsum("qk,qkd->qd", bary, tri), bary


@dataclass(frozen=True)
class Remeshed:
    """The re-meshed surface and, per new node (in order, after the input's nodes), how far it lies from the point
    of its input triangle with the same barycentric coordinates (mm): the limit surface's offset from the facets."""

    mesh: Mesh
    moved: np.ndarray


def remesh_to_edge(surface: LimitSurface, max_edge: float, max_triangles: int,
                   progress: ProgressFn | None = None) -> Remeshed:
    """The coarse mesh bisected (longest edge first, with closure) until no edge is longer than max_edge (mm), new
    nodes on the limit surface; output_too_large when that would exceed max_triangles."""
    if not max_edge > 0:
        raise AmprepError(ErrorCode.INVALID_PARAMETER, f"max_edge must be > 0, got {max_edge}")
    prog = Progress(progress)
    v = np.asarray(surface.coarse.vertices, float)
    t = np.asarray(surface.coarse.triangles, np.int64)
    root = np.arange(len(t))
    bary = np.broadcast_to(np.eye(3), (len(t), 3, 3)).copy()  # corner c of triangle i in its root triangle
    area = 0.5 * norms(triangle_normals(v[t])).sum()
    estimate = len(t) + 4 * area / (np.sqrt(3) / 4 * max_edge**2)
    if estimate > max_triangles:
        raise AmprepError(ErrorCode.OUTPUT_TOO_LARGE, f"splitting every edge down to {max_edge:g} mm needs about "
                          f"{estimate:,.0f} triangles, over the limit of {max_triangles:,}")
    moved: list[np.ndarray] = []
    for rnd in range(MAX_ROUNDS):
        prog("re-meshing on the limit surface", min(rnd / 12, 0.95))
        v, t, root, bary, split = _bisect_round(surface, v, t, root, bary, max_edge, moved)
        if not split:
            return Remeshed(Mesh.from_arrays(v, t), np.concatenate(moved) if moved else np.zeros(0))
        if len(t) > max_triangles:
            raise AmprepError(ErrorCode.OUTPUT_TOO_LARGE, f"re-meshing to {max_edge:g} mm went over "
                              f"{max_triangles:,} triangles")
    raise AmprepError(ErrorCode.MESHING_FAILED, f"edges still over {max_edge:g} mm after {MAX_ROUNDS} rounds")


def _bisect_round(surface: LimitSurface, v: np.ndarray, t: np.ndarray, root: np.ndarray, bary: np.ndarray,
                  max_edge: float, moved: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """One round: mark edges over max_edge, close the marks (a triangle with a marked side has its longest marked),
    split; returns the new arrays and how many edges were split, and appends the new nodes' offsets to `moved`."""
    inc = edge_incidence(t)
    e = inc.edges
    length = np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1)
    mark = length > max_edge
    if not mark.any():
        return v, t, root, bary, 0
    side_len = length[inc.edge_of]  # (m, 3)
    longest = np.argmax(side_len, axis=1)  # ties: the lowest side
    long_edge = inc.edge_of[np.arange(len(t)), longest]
    while True:
        need = mark[inc.edge_of].any(axis=1) & ~mark[long_edge]
        if not need.any():
            break
        mark[long_edge[need]] = True
    # one new node per marked edge, from a triangle that has it: side k joins corners k and k+1
    split = np.flatnonzero(mark)
    first = np.full(len(e), -1, np.int64)
    flat = inc.edge_of.reshape(-1)
    first[flat[::-1]] = np.arange(len(flat))[::-1]
    h = first[split]
    ti, k = h // 3, h % 3
    mid_bary = 0.5 * (bary[ti, k] + bary[ti, (k + 1) % 3])
    new_pts = surface.evaluate(root[ti], mid_bary)
    coarse = surface.coarse.vertices[surface.coarse.triangles[root[ti]]]  # (s, 3, 3)
    moved.append(np.linalg.norm(new_pts - np.einsum("sk,skd->sd", mid_bary, coarse), axis=1))
    node = np.full(len(e), -1, np.int64)
    node[split] = len(v) + np.arange(len(split))
    v = np.concatenate([v, new_pts])
    t, root, bary = _split(t, root, bary, node[inc.edge_of], longest)
    return v, t, root, bary, len(split)


def _split(t: np.ndarray, root: np.ndarray, bary: np.ndarray, mid: np.ndarray, longest: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split each triangle by its marked sides (mid (m, 3): new node on side k, or -1; the longest side is marked
    whenever any is): rotate so the longest is side 0 (c0 c1), halve there, then halve each half whose other side
    (c1 c2, c2 c0) is marked. Children keep their parent's root triangle and carry barycentric corners."""
    r = np.arange(len(t))
    rot = (longest[:, None] + np.arange(3)) % 3
    c = t[r[:, None], rot]
    cb = bary[r[:, None], rot]  # (m, 3, 3)
    m = mid[r[:, None], rot]  # side j of the rotated triangle joins c_j and c_{j+1}
    any_ = m[:, 0] >= 0
    keep = ~any_
    out_t, out_r, out_b = [t[keep]], [root[keep]], [bary[keep]]
    i = np.flatnonzero(any_)
    c0, c1, c2 = c[i, 0], c[i, 1], c[i, 2]
    b0, b1, b2 = cb[i, 0], cb[i, 1], cb[i, 2]
    m0, m1, m2 = m[i, 0], m[i, 1], m[i, 2]
    bm0, bm1, bm2 = 0.5 * (b0 + b1), 0.5 * (b1 + b2), 0.5 * (b2 + b0)
    s1, s2 = m1 >= 0, m2 >= 0

    def add(mask: np.ndarray, verts: list[np.ndarray], barys: list[np.ndarray]) -> None:
        out_t.append(np.stack([x[mask] for x in verts], 1))
        out_r.append(root[i][mask])
        out_b.append(np.stack([x[mask] for x in barys], 1))

    # the half (c0, m0, c2): whole, or split at m2 on c2 c0
    add(~s2, [c0, m0, c2], [b0, bm0, b2])
    add(s2, [c0, m0, m2], [b0, bm0, bm2])
    add(s2, [m0, c2, m2], [bm0, b2, bm2])
    # the half (m0, c1, c2): whole, or split at m1 on c1 c2
    add(~s1, [m0, c1, c2], [bm0, b1, b2])
    add(s1, [m0, c1, m1], [bm0, b1, bm1])
    add(s1, [m0, m1, c2], [bm0, bm1, b2])
    return np.concatenate(out_t), np.concatenate(out_r), np.concatenate(out_b)
