"""What an STL's edges and nodes are, for the Butterfly refinement (butterfly.py): feature curves (by dihedral angle,
at non-manifold and open edges, and where a flat face meets a curved one at a tangent), surface / curve / vertex
nodes, flat regions, and the half-edge walk around a node."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from amprep.geometry.core import vectors
from amprep.geometry.core.edges import edge_incidence

SURFACE, CURVE, VERTEX = 0, 1, 2
#: adjacent triangles whose normals differ by less than this (rad) are coplanar
COPLANAR = 1e-4
#: a bend whose flat side (a coplanar pair or more) is this many times higher over it than its other side bounds a
#: flat face
HEIGHT_RATIO = 3.0


def normals_and_areas(v: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((m, 3) unit normals (0 for a degenerate triangle), (m,) doubled areas |(v1 − v0) × (v2 − v0)|)."""
    return vectors.unit_normals(v[t])


def unit_normals(v: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(m, 3) unit normals of the triangles (0 for a degenerate one)."""
    return normals_and_areas(v, t)[0]


@dataclass(frozen=True)
class Halfedges:
    """Half-edge h = 3t + k runs T[t,k] → T[t,k+1]; `twin` (3m,) the opposite half-edge or −1; `edge` (3m,) its
    undirected edge; `inc` the edge table."""

    twin: np.ndarray
    edge: np.ndarray
    count: np.ndarray
    edges: np.ndarray

    @cached_property
    def next_out(self) -> np.ndarray:
        """(3m,) succ of every half-edge: the twin of the half-edge before it in its triangle (−1 at a hole)."""
        h = np.arange(len(self.twin))
        return self.twin[3 * (h // 3) + (h % 3 + 2) % 3]

    @classmethod
    def of(cls, t: np.ndarray) -> Halfedges:
        inc = edge_incidence(t, with_order=True)
        edge = inc.edge_of.reshape(-1)
        order = inc.order  # the sides sorted by edge, stably: twins are neighbours
        twin = np.full(len(edge), -1, np.int64)
        pair = inc.count[edge[order]] == 2
        first = order[pair][0::2]
        second = order[pair][1::2]
        twin[first], twin[second] = second, first
        return cls(twin, edge, inc.count, inc.edges)


def succ(he: Halfedges, h: np.ndarray) -> np.ndarray:
    """The next outgoing half-edge around its start vertex (the vertex after h's target in the ring), −1 at a hole."""
    return he.next_out[h]


def classify(v: np.ndarray, t: np.ndarray, feature_angle: float, flat_faces: bool = True,
             he: Halfedges | None = None, normals: np.ndarray | None = None) -> np.ndarray:
    """(E,) bool feature flag of the edges of edge_incidence(t) (the module's docstring); he: Halfedges.of(t),
    normals: unit_normals(v, t)."""
    he = he or Halfedges.of(t)
    normals = unit_normals(v, t) if normals is None else normals
    n_e = len(he.count)
    feature = he.count != 2
    side = np.arange(3 * len(t))
    has_twin = he.twin >= 0
    h1 = side[has_twin & (side < np.where(has_twin, he.twin, -1))]
    t1, t2 = h1 // 3, he.twin[h1] // 3
    e = he.edge[h1]
    cosang = np.clip(np.einsum("ij,ij->i", normals[t1], normals[t2]), -1.0, 1.0)
    theta = np.arccos(cosang)
    feature[e[theta > math.radians(feature_angle)]] = True
    if not flat_faces:
        return feature
    coplanar = theta < COPLANAR
    # coplanar patches: components over coplanar edges; ≥ 3 triangles make a flat face
    m = len(t)
    graph = coo_matrix((np.ones(int(coplanar.sum())), (t1[coplanar], t2[coplanar])), shape=(m, m))
    _, patch = connected_components(graph, directed=False)
    size = np.bincount(patch)
    flat = size[patch] >= 3
    bends = ~coplanar & (theta <= math.radians(feature_angle))
    feature[e[bends & (flat[t1] != flat[t2])]] = True
    feature[e[bends & flat[t1] & flat[t2] & (patch[t1] != patch[t2])]] = True
    # a tangent junction of a flat face: the flat side's triangle is far higher over the edge than the curved
    # side's (a facet of a curved face is as wide as the tessellation tolerance allows, a flat face is not)
    a, b = he.edges[e, 0], he.edges[e, 1]
    length = np.maximum(np.linalg.norm(v[b] - v[a], axis=1), 1e-300)
    area = 0.5 * vectors.norms(vectors.triangle_normals(v[t]))
    h1, h2 = 2 * area[t1] / length, 2 * area[t2] / length
    big = np.where(h1 >= h2, t1, t2)
    ratio = np.maximum(h1, h2) / np.maximum(np.minimum(h1, h2), 1e-300)
    feature[e[bends & (size[patch[big]] >= 2) & (ratio > HEIGHT_RATIO)]] = True
    assert len(feature) == n_e
    return feature


def node_class(n: int, edges: np.ndarray, feature: np.ndarray, he: Halfedges, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((n,) SURFACE | CURVE | VERTEX, (n,) valence): by incident feature edges; a surface node whose triangles are
    not one closed fan (an open or pinched ring) is a vertex node."""
    fe = edges[feature]
    nf = np.bincount(fe.ravel(), minlength=n)
    valence = np.bincount(edges.ravel(), minlength=n)
    cls = np.where(nf == 0, SURFACE, np.where(nf == 2, CURVE, VERTEX))
    start = np.full(n, -1, np.int64)
    start[t.reshape(-1)] = np.arange(3 * len(t))  # one outgoing half-edge per vertex
    surf = np.flatnonzero((cls == SURFACE) & (start >= 0))
    h = start[surf]
    steps = np.zeros(len(surf), np.int64)
    back = np.zeros(len(surf), bool)
    for j in range(1, int(valence[surf].max(initial=0)) + 1):
        h = np.where(h >= 0, succ(he, np.maximum(h, 0)), -1)
        hit = ~back & (h == start[surf])
        steps[hit] = j
        back |= hit
    closed_fan = back & (steps == valence[surf])
    cls[surf[~closed_fan]] = VERTEX
    cls[valence == 0] = VERTEX
    return cls, valence


def sharp_turns(v: np.ndarray, feature_edges: np.ndarray, feature_angle: float) -> np.ndarray:
    """(n,) True at nodes with exactly two feature edges that turn by more than the feature angle (a corner of an
    outline): vertex nodes, which the curve masks do not round off."""
    n = len(v)
    ends = np.concatenate([feature_edges, feature_edges[:, ::-1]])
    ends = ends[np.argsort(ends[:, 0], kind="stable")]
    count = np.bincount(ends[:, 0], minlength=n)
    out = np.zeros(n, bool)
    two = np.flatnonzero(count == 2)
    if len(two) == 0:
        return out
    first = np.searchsorted(ends[:, 0], two)
    p, q = ends[first, 1], ends[first + 1, 1]
    u, w = v[two] - v[p], v[q] - v[two]
    cos = np.einsum("ij,ij->i", u, w) / np.maximum(np.linalg.norm(u, axis=1) * np.linalg.norm(w, axis=1), 1e-300)
    out[two[cos < math.cos(math.radians(feature_angle))]] = True
    return out


def flat_triangles(v: np.ndarray, t: np.ndarray, feature: np.ndarray, he: Halfedges | None = None,
                   normals: np.ndarray | None = None) -> np.ndarray:
    """(m,) True for triangles of a smooth region (joined across non-feature edges) whose triangles are coplanar;
    he: Halfedges.of(t), normals: unit_normals(v, t)."""
    he = he or Halfedges.of(t)
    side = np.arange(3 * len(t))
    h1 = side[(he.twin >= 0) & (side < he.twin)]
    keep = ~feature[he.edge[h1]]
    m = len(t)
    graph = coo_matrix((np.ones(int(keep.sum())), (h1[keep] // 3, he.twin[h1[keep]] // 3)), shape=(m, m))
    _, region = connected_components(graph, directed=False)
    normals = unit_normals(v, t) if normals is None else normals
    ref = np.zeros((region.max() + 1, 3))
    ref[region] = normals  # any one normal per region
    ok = np.einsum("ij,ij->i", normals, ref[region]) > math.cos(10 * COPLANAR)
    bad = np.zeros(region.max() + 1, bool)
    bad[region[~ok]] = True
    return ~bad[region]
