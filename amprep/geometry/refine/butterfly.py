"""Refinement of an STL alone by the modified Butterfly scheme (sources 002 and 001; ALGORITHMS.md, "STL-only
refinement"): every triangle split in four, the old nodes kept, each new node on an edge placed by a mask chosen
from the classification of the edge's end nodes.

Classification (once, on the input): an edge is a feature curve when its dihedral angle exceeds the feature angle,
when it is not shared by exactly two triangles, or where a flat face meets a curved one at a tangent (the edge
bounds a patch of ≥ 3 coplanar triangles, or the triangle on its flat side — one of ≥ 2 coplanar ones — is over 3×
higher over it than the other: a facet of a curved face is as wide as the tessellation tolerance allows, a flat face
is not). A node is a surface node with no feature edge, a curve node
with two, a vertex node otherwise (a corner, a curve's end, or a node whose triangles are not one fan). Children of
a feature edge are feature edges at the next level; the edges joining new nodes never are.

Masks (Zorin, Schröder and Sweldens' modified Butterfly, as 002 lists its seven rules):
- a surface node c of valence k, neighbours q_j counted from the edge's other end: 3/4·c + Σ s_j q_j with
  s_j = (1/4 + cos(2πj/k) + cos(4πj/k)/2)/k for k ≥ 5, (5/12, −1/12, −1/12) for k = 3, (3/8, 0, −1/8, 0) for k = 4;
- both ends regular surface nodes (valence 6): the 10-point stencil ½(a+b) + ⅛(c+d) − 1/16(four tails);
- both surface, not both regular: the two ends' masks averaged; one surface end: its mask;
- both ends non-surface (002's two rules for the high-aspect triangles of STL files): with a surface node among the
  two opposite nodes, the masks above on the temporarily swapped edge (rule I; the swap never reaches the output's
  connectivity); with none, 0.75 × the ends' average + 0.25 × the opposite nodes' average (rule II), plus — our
  addition, for strips spanning between two curves, which 002 shows slimming (its Fig. 12) — the mean bulge (new
  node − midpoint) of the feature edges of the edge's two triangles;
- feature curves: the 4-point mask (−1, 9, 9, −1)/16 between two curve nodes, the 3-point (3/8, 3/4, −1/8) next to
  a vertex node, the midpoint between two vertex nodes; a curve node where its curve turns by more than the feature
  angle (an outline's corner) is a vertex node.
Every mask is an affine combination of nodes of one smooth region or one curve, so a planar region bounded by
feature curves stays in its plane and a straight curve stays straight.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.core.mesh import Mesh
from amprep.geometry.core.progress import Progress, ProgressFn
from amprep.geometry.core.vectors import cross
from amprep.geometry.refine.stl_features import (
    CURVE,
    SURFACE,
    VERTEX,
    Halfedges,
    classify,
    flat_triangles,
    node_class,
    normals_and_areas,
    sharp_turns,
    succ,
)

#: a surface edge's new node moves at most this × the lower of its triangles' heights over the edge (_clamp)
CLAMP = 0.25
#: rounds of halving the displacement of a folding triangle's new nodes before they are dropped (_unfold)
UNFOLD_ROUNDS = 6


@dataclass(frozen=True)
class ButterflyParams:
    """levels of 1-to-4 splitting (each ×4 the triangles), feature angle in degrees; flat_faces: edges where a flat
    face meets a curved one at a tangent become feature curves (a part's STL); off, the pure scheme of 002."""

    levels: int = 1
    feature_angle: float = 30.0
    flat_faces: bool = True

    def validate(self) -> None:
        if not (1 <= self.levels <= 6):
            raise AmprepError(ErrorCode.INVALID_PARAMETER, f"levels must be 1..6, got {self.levels}")
        if not (0 < self.feature_angle < 180):
            raise AmprepError(ErrorCode.INVALID_PARAMETER, f"feature angle must be in (0, 180) degrees, got "
                              f"{self.feature_angle}")


@dataclass
class ButterflyResult:
    """The refined mesh and what was done: node counts by class, triangles by region, how far new nodes moved off
    their edge's midpoint (mm)."""

    mesh: Mesh
    levels: int
    nodes: dict[str, int]
    triangles_in: dict[str, int]
    feature_edges: int
    moved_max: float
    moved_mean: float
    per_level: list[dict[str, float]] = field(default_factory=list)

    def to_json(self) -> dict[str, object]:
        return {"method": "butterfly", "levels": self.levels, "nodes": self.nodes, "triangles_in": self.triangles_in,
                "feature_edges": self.feature_edges, "triangles_out": self.mesh.n_triangles,
                "moved": {"max": self.moved_max, "mean": self.moved_mean}, "per_level": self.per_level}


def _weight_table(k_max: int) -> np.ndarray:
    """(k_max + 1, k_max) s_j(k) of the irregular surface mask for every valence k ≤ k_max and j (0 where j ≥ k)."""
    k = np.arange(k_max + 1)[:, None]
    kf = np.maximum(k, 1).astype(float)
    j = np.arange(max(k_max, 1))[None, :]
    s = (0.25 + np.cos(2 * np.pi * j / kf) + 0.5 * np.cos(4 * np.pi * j / kf)) / kf
    s = np.where(k == 3, np.where(j < 3, np.array([5 / 12, -1 / 12, -1 / 12, 0.0])[np.minimum(j, 3)], 0.0), s)
    s = np.where(k == 4, np.where(j < 4, np.array([3 / 8, 0.0, -1 / 8, 0.0])[np.minimum(j, 3)], 0.0), s)
    return np.where(j < k, s, 0.0)


def _ring_masks(v: np.ndarray, tgt: np.ndarray, he: Halfedges, centre: np.ndarray, first: np.ndarray,
                h0: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(irregular mask position, ring[2], ring[k−2]) of requests (r,): a centre with ring q_0 = first, then
    q_j = target of succ^(j−1)(h0) for j = 1..k−1 (_ring_kernel.ring_walk)."""
    from amprep.geometry.refine._ring_kernel import ring_walk

    table = _weight_table(int(k.max(initial=1)))
    i64 = np.int64
    pts = np.ascontiguousarray(v, float).view()
    pts.flags.writeable = False  # one signature (numba types a read-only array apart), the one warm_ring_kernel's
    return ring_walk(pts, tgt.astype(i64), he.next_out.astype(i64), centre.astype(i64),
                     first.astype(i64), h0.astype(i64), k.astype(i64), table)


def warm_ring_kernel() -> None:
    """ring_walk dispatched once on a triangle with the types of real calls (numba compiles it, or loads its cache)."""
    t = np.array([[0, 1, 2]])
    he = Halfedges.of(t)
    one = np.array([0])
    _ring_masks(np.eye(3), t[:, [1, 2, 0]].reshape(-1), he, one, one + 1, one, one + 1)


def _level(v: np.ndarray, t: np.ndarray, feature_keys: np.ndarray, flat: np.ndarray, corner: np.ndarray,
           he: Halfedges | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, int]]:
    """One level: (vertices, triangles, child feature keys, (E,) new-node displacement off the midpoint, node
    counts by class). feature_keys: sorted lo·n+hi codes of the feature edges; flat (m,): triangles of a flat
    region, whose inner edges are split at their midpoints (a flat region keeps its triangles' shapes); corner (n,):
    nodes held as vertex nodes (where a curve turns sharply)."""
    n = len(v)
    he = he or Halfedges.of(t)
    edges = he.edges
    keys = edges[:, 0] * n + edges[:, 1]
    feature = np.isin(keys, feature_keys)
    cls, valence = node_class(n, edges, feature, he, t)
    cls[corner[:n]] = VERTEX
    tgt = t[:, [1, 2, 0]].reshape(-1)  # target vertex of each half-edge
    n_e = len(edges)
    # one half-edge a→b per edge (the first use), its twin b→a
    first_use = np.full(n_e, -1, np.int64)
    first_use[he.edge[::-1]] = np.arange(3 * len(t))[::-1]
    h_ab = first_use
    a, b = t.reshape(-1)[h_ab], tgt[h_ab]
    h_ba = he.twin[h_ab]
    mid = 0.5 * (v[a] + v[b])
    new = mid.copy()
    ca, cb = cls[a], cls[b]
    surface_edge = ~feature & (h_ba >= 0)
    # opposite (wing) vertices: c in a→b's triangle, d in b→a's
    c = t.reshape(-1)[3 * (h_ab // 3) + (h_ab % 3 + 2) % 3]
    d = np.where(h_ba >= 0, t.reshape(-1)[3 * (np.maximum(h_ba, 0) // 3) + (np.maximum(h_ba, 0) % 3 + 2) % 3], -1)
    inner_flat = surface_edge & flat[h_ab // 3] & flat[np.maximum(h_ba, 0) // 3]  # split at the midpoint
    _curve_masks(v, new, feature, edges, a, b, ca, cb)
    _surface_masks(v, tgt, he, new, surface_edge & ~inner_flat, a, b, c, d, h_ab, h_ba, cls, valence, np.where(
        feature[:, None], new - mid, np.nan))
    normals, area2 = normals_and_areas(v, t)
    _clamp(v, t, area2, new, mid, surface_edge | feature, h_ab, h_ba)
    _unfold(v, t, normals, area2, he.edge.reshape(-1, 3), new, mid)
    moved = np.linalg.norm(new - mid, axis=1)
    # split: corner k of each triangle, and the new nodes on its sides k (k→k+1)
    mids = n + he.edge.reshape(-1, 3)
    t0, t1_, t2 = t[:, 0], t[:, 1], t[:, 2]
    m01, m12, m20 = mids[:, 0], mids[:, 1], mids[:, 2]
    tris = np.concatenate([np.stack([t0, m01, m20], 1), np.stack([t1_, m12, m01], 1), np.stack([t2, m20, m12], 1),
                           np.stack([m01, m12, m20], 1)])
    fe = np.flatnonzero(feature)
    n2 = n + n_e
    halves = np.concatenate([np.stack([edges[fe, 0], n + fe], 1), np.stack([n + fe, edges[fe, 1]], 1)])
    lo, hi = halves.min(axis=1), halves.max(axis=1)
    counts = {"surface": int((cls == SURFACE).sum()), "curve": int((cls == CURVE).sum()),
              "vertex": int((cls == VERTEX).sum())}
    return np.concatenate([v, new]), tris, np.sort(lo * n2 + hi), moved, counts


def _surface_masks(v: np.ndarray, tgt: np.ndarray, he: Halfedges, new: np.ndarray, surface_edge: np.ndarray,
                   a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray, h_ab: np.ndarray, h_ba: np.ndarray,
                   cls: np.ndarray, valence: np.ndarray, bulge: np.ndarray) -> None:
    """New nodes of surface edges (rules 1–4, with 002's rules I and II), written into `new` (E, 3); `bulge` (E, 3)
    each feature edge's new node minus its midpoint (nan elsewhere), for rule II."""
    sa, sb = cls[a] == SURFACE, cls[b] == SURFACE
    e_a = np.flatnonzero(surface_edge & sa)
    e_b = np.flatnonzero(surface_edge & sb)
    pos_a, a2, am2 = _ring_masks(v, tgt, he, a[e_a], b[e_a], succ(he, h_ab[e_a]), valence[a[e_a]])
    pos_b, b2, bm2 = _ring_masks(v, tgt, he, b[e_b], a[e_b], succ(he, h_ba[e_b]), valence[b[e_b]])
    acc = np.zeros_like(new)
    cnt = np.zeros(len(new))
    acc[e_a] += pos_a
    cnt[e_a] += 1
    acc[e_b] += pos_b
    cnt[e_b] += 1
    done = cnt > 0
    new[done] = acc[done] / cnt[done, None]
    # both regular: the 10-point stencil
    ra = np.zeros(len(new), np.int64) - 1
    rb = np.zeros(len(new), np.int64) - 1
    ram, rbm = ra.copy(), rb.copy()
    ra[e_a], ram[e_a] = a2, am2
    rb[e_b], rbm[e_b] = b2, bm2
    reg = surface_edge & sa & sb & (valence[a] == 6) & (valence[b] == 6) & (ra >= 0) & (ram >= 0) & (rb >= 0) & (rbm >= 0)
    r = np.flatnonzero(reg)
    new[r] = (0.5 * (v[a[r]] + v[b[r]]) + 0.125 * (v[c[r]] + v[d[r]])
              - 0.0625 * (v[ra[r]] + v[ram[r]] + v[rb[r]] + v[rbm[r]]))
    # both ends non-surface: rule I (a surface node across: the swapped edge c–d) or rule II
    both = surface_edge & ~sa & ~sb
    sc = both & (cls[c] == SURFACE)
    sd = both & (cls[np.maximum(d, 0)] == SURFACE) & (d >= 0)
    rule2 = np.flatnonzero(both & ~sc & ~sd)
    new[rule2] = (0.375 * (v[a[rule2]] + v[b[rule2]]) + 0.125 * (v[c[rule2]] + v[d[rule2]])
                  + _side_bulge(he, h_ab[rule2], h_ba[rule2], bulge))
    swap = np.zeros_like(new)
    nswap = np.zeros(len(new))
    ec = np.flatnonzero(sc)
    if len(ec):  # centre c, ring [d, b, …, a]: starts with c→b (the twin of b→c)
        h_bc = 3 * (h_ab[ec] // 3) + (h_ab[ec] % 3 + 1) % 3
        h_cb = he.twin[h_bc]
        ok = h_cb >= 0
        pos, _, _ = _ring_masks(v, tgt, he, c[ec], d[ec], np.maximum(h_cb, 0), np.where(ok, valence[c[ec]] + 1, 0))
        swap[ec[ok]] += pos[ok]
        nswap[ec[ok]] += 1
    ed = np.flatnonzero(sd)
    if len(ed):  # centre d, ring [c, a, …, b]: starts with d→a (the twin of a→d)
        hb = h_ba[ed]
        h_ad = 3 * (hb // 3) + (hb % 3 + 1) % 3
        h_da = he.twin[h_ad]
        ok = h_da >= 0
        pos, _, _ = _ring_masks(v, tgt, he, d[ed], c[ed], np.maximum(h_da, 0), np.where(ok, valence[d[ed]] + 1, 0))
        swap[ed[ok]] += pos[ok]
        nswap[ed[ok]] += 1
    sw = nswap > 0
    new[sw] = swap[sw] / nswap[sw, None]


def _clamp(v: np.ndarray, t: np.ndarray, area2: np.ndarray, new: np.ndarray, mid: np.ndarray, edges_in: np.ndarray,
           h_ab: np.ndarray, h_ba: np.ndarray) -> None:
    """Limit the new node of each edge in `edges_in` (E,) bool to CLAMP × the lower of its triangles' heights over
    the edge from its midpoint: next to the slivers STL files are full of (a loft's long triangles, a plane's fan), a
    mask's pull can exceed the sliver's width and fold the surface onto itself (a child triangle turns over when
    its edge's node moves past half the height); on well-shaped triangles the limit is never reached. area2 (m,):
    the triangles' doubled areas."""
    e = np.flatnonzero(edges_in)
    if len(e) == 0:
        return
    ab = v[t.reshape(-1)[h_ab[e]]] - v[t[:, [1, 2, 0]].reshape(-1)[h_ab[e]]]
    length = np.maximum(np.linalg.norm(ab, axis=1), 1e-300)

    def height(h: np.ndarray) -> np.ndarray:
        return area2[h // 3] / length

    other = h_ba[e]
    limit = CLAMP * np.where(other >= 0, np.minimum(height(h_ab[e]), height(np.maximum(other, 0))), height(h_ab[e]))
    off = new[e] - mid[e]
    dist = np.linalg.norm(off, axis=1)
    scale = np.where(dist > limit, limit / np.maximum(dist, 1e-300), 1.0)
    new[e] = mid[e] + off * scale[:, None]


def _child_crosses(v: np.ndarray, new: np.ndarray, t: np.ndarray, sides: np.ndarray) -> np.ndarray:
    """(4, m, 3) (b − a) × (c − a) of each triangle's four children (corner k's, then the middle one): corners from
    v, the new nodes of the sides (edge indices, side k joins corners k and k+1) from new."""
    c = [v[t[:, k]] for k in range(3)]
    m = [new[sides[:, k]] for k in range(3)]
    kids = ((c[0], m[0], m[2]), (c[1], m[1], m[0]), (c[2], m[2], m[1]), (m[0], m[1], m[2]))
    return np.stack([cross(b - a, cc - a) for a, b, cc in kids])


def _unfold(v: np.ndarray, t: np.ndarray, parent: np.ndarray, area2: np.ndarray, edge_of: np.ndarray, new: np.ndarray,
            mid: np.ndarray) -> None:
    """Where a triangle's child would turn more than ~72° from the triangle (a fold: the new nodes of its sides
    moved past its narrow width), halve those sides' displacements, up to UNFOLD_ROUNDS times, then drop them:
    the plain split never folds. After the first round only the triangles beside a changed side are looked at.
    parent (m, 3), area2 (m,): the triangles' unit normals and doubled areas."""
    # only a triangle whose sides' nodes moved by a tenth of its lowest height can fold: the others are not looked at
    moved = np.linalg.norm(new - mid, axis=1)[edge_of].max(axis=1)
    c = v[t]
    longest = np.linalg.norm(c - np.roll(c, -1, axis=1), axis=2).max(axis=1)
    active = np.flatnonzero(moved > 0.1 * area2 / np.maximum(longest, 1e-300))
    for round_ in range(UNFOLD_ROUNDS + 1):
        if len(active) == 0:
            return
        tt, eo = t[active], edge_of[active]
        normals = _child_crosses(v, new, tt, eo)
        norm = np.linalg.norm(normals, axis=2)
        cos = np.einsum("kmj,mj->km", normals, parent[active]) / np.maximum(norm, 1e-300)
        bad = ((cos < 0.3) & (norm > 0)).any(axis=0) & (np.linalg.norm(parent[active], axis=1) > 0)
        if not bad.any():
            return
        sides = np.unique(eo[bad])
        factor = 0.5 if round_ < UNFOLD_ROUNDS else 0.0
        new[sides] = mid[sides] + factor * (new[sides] - mid[sides])
        changed = np.zeros(len(new), bool)
        changed[sides] = True
        active = np.flatnonzero(changed[edge_of].any(axis=1))


def _side_bulge(he: Halfedges, h_ab: np.ndarray, h_ba: np.ndarray, bulge: np.ndarray) -> np.ndarray:
    """(r, 3) mean bulge of the feature edges among the other sides of an edge's two triangles (0 when none): an
    edge spanning between curves (a cylinder's strip, a fillet's) follows their curvature, so the strip does not
    slim (002's Fig. 12) — our addition to rule II; in a plane the bulges lie in the plane."""
    sides = np.stack([3 * (h // 3) + (h % 3 + s) % 3 for h in (h_ab, h_ba) for s in (1, 2)], axis=1)
    b = bulge[he.edge[sides]]  # (r, 4, 3), nan where not a feature edge
    have = ~np.isnan(b[:, :, 0])
    total = np.where(have[:, :, None], b, 0.0).sum(axis=1)
    return total / np.maximum(have.sum(axis=1), 1)[:, None]


def _curve_masks(v: np.ndarray, new: np.ndarray, feature: np.ndarray, edges: np.ndarray, a: np.ndarray,
                 b: np.ndarray, ca: np.ndarray, cb: np.ndarray) -> None:
    """New nodes of feature edges (rules 5–7), written into `new`."""
    n = len(v)
    fe = edges[feature]
    # each curve node's two curve neighbours
    ends = np.concatenate([fe, fe[:, ::-1]])
    order = np.argsort(ends[:, 0], kind="stable")
    ends = ends[order]
    start = np.searchsorted(ends[:, 0], np.arange(n))
    cnt = np.bincount(ends[:, 0], minlength=n)
    nb0 = np.where(cnt >= 1, ends[np.minimum(start, len(ends) - 1), 1], -1) if len(ends) else np.full(n, -1)
    nb1 = np.where(cnt >= 2, ends[np.minimum(start + 1, len(ends) - 1), 1], -1) if len(ends) else np.full(n, -1)

    def other(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return np.where(nb0[x] == y, nb1[x], nb0[x])

    f = np.flatnonzero(feature)
    fa, fb = a[f], b[f]
    ka, kb = ca[f], cb[f]
    oa, ob = other(fa, fb), other(fb, fa)
    four = (ka == CURVE) & (kb == CURVE) & (oa >= 0) & (ob >= 0)
    i = f[four]
    new[i] = (9 * (v[fa[four]] + v[fb[four]]) - v[oa[four]] - v[ob[four]]) / 16
    three_a = (ka == VERTEX) & (kb == CURVE) & (ob >= 0)  # vertex a, curve b
    i = f[three_a]
    new[i] = 0.375 * v[fa[three_a]] + 0.75 * v[fb[three_a]] - 0.125 * v[ob[three_a]]
    three_b = (kb == VERTEX) & (ka == CURVE) & (oa >= 0)
    i = f[three_b]
    new[i] = 0.375 * v[fb[three_b]] + 0.75 * v[fa[three_b]] - 0.125 * v[oa[three_b]]
    # two vertex nodes: the midpoint, already there


def butterfly_refine(mesh: Mesh, params: ButterflyParams = ButterflyParams(),
                     progress: ProgressFn | None = None) -> ButterflyResult:
    """The mesh refined `levels` times by the modified Butterfly scheme (the module's docstring): (4^levels · m,)
    triangles, the input's vertices first and unmoved."""
    params.validate()
    prog = Progress(progress)
    v = np.asarray(mesh.vertices, float)
    t = np.asarray(mesh.triangles, np.int64)
    if len(t) == 0:
        raise AmprepError(ErrorCode.EMPTY_MODEL, "the STL has no triangles")
    he = Halfedges.of(t)  # the input's edge table, shared by the classification and the first level
    normals = normals_and_areas(v, t)[0]
    feature = classify(v, t, params.feature_angle, params.flat_faces, he, normals)
    edges = he.edges
    n = len(v)
    keys = np.sort(edges[feature, 0] * n + edges[feature, 1])
    planar = flat_triangles(v, t, feature, he, normals)
    on_curve = feature[he.edge.reshape(-1, 3)].any(axis=1)
    triangles_in = {"planar": int(planar.sum()), "curved": int((~planar).sum()),
                    "on_feature_curves": int(on_curve.sum())}  # a side on a feature curve (of either kind above)
    moved_all, per_level, counts0 = [], [], {}
    planar_now = planar
    corner = sharp_turns(v, edges[feature], params.feature_angle)
    for level in range(params.levels):
        prog("refining", level / params.levels)
        v, t, keys, moved, counts = _level(v, t, keys, planar_now, corner, he if level == 0 else None)
        corner = np.concatenate([corner, np.zeros(len(v) - len(corner), bool)])
        planar_now = np.tile(planar_now, 4)  # child j of a level's triangle p is p + k·m (k = 0..3)
        counts0 = counts0 or counts
        moved_all.append(moved)
        per_level.append({"triangles": len(t), "moved_max": float(moved.max(initial=0.0)),
                          "moved_mean": float(moved.mean()) if len(moved) else 0.0})
    prog("refining", 1.0)
    moved = np.concatenate(moved_all)
    out = Mesh.from_arrays(v, t)
    return ButterflyResult(out, params.levels, counts0, triangles_in, int(feature.sum()),
                           float(moved.max(initial=0.0)), float(moved.mean()) if len(moved) else 0.0, per_level)
