"""Join face patches into one Mesh by topology: a node on a B-rep vertex is that vertex, a node on a B-rep
edge is (edge, parameter); tessellated-only faces (no surface) share nodes with identical coordinates,
which is how their file shares its coordinate list.

Before the tolerance is measured, boundary nodes are seated where the weld will put them (seat_boundaries): each
B-rep vertex and each (B-rep edge, parameter) one point, where its faces meet, and each face's (u,v) of a node that
moved its projection on that face. A face's error is then measured on the triangles it will have in the output:
where the B-rep's faces miss their shared edge (a gap, or an edge that is not same-parameter: its pcurves reach a
point away from the 3D curve's at one parameter) the difference is counted."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from amprep.geometry.cad.surfaces import Surface, project_points, surface_normals
from amprep.geometry.core.checks import degenerate_mask, shell_labels, signed_volume, triangle_areas
from amprep.geometry.core.edges import distinct_corners, edge_codes, edge_incidence
from amprep.geometry.core.mesh import IN_FACE, ON_BREP_EDGE, ON_BREP_VERTEX, FaceInfo, Mesh
from amprep.geometry.core.vectors import cross, group_rows
from amprep.geometry.meshing.occt_read import FacePatch

#: a key's nodes are seated anew when one lies farther than this × the tolerance from their mean
SEAT_REL = 1e-4
#: a seated point stays within this × the farthest of its nodes from their mean of that mean: where the faces meet
#: far from their edge (surfaces near tangent there, their gap across it) the edge is not moved to where they do
SEAT_REACH = 2.0
#: keys whose nodes lie within this × the tolerance of their mean are seated at the mean, with no iteration
NEWTON_REL = 1e-3
#: rounds of seat's iteration at most: each point moved to the least-squares point of its faces' tangent planes
SEAT_ROUNDS = 4


def node_keys(patch: FacePatch, nodes: np.ndarray, vertex_roots: np.ndarray | None) -> np.ndarray:
    """(b, 3) int64 key rows of a patch's boundary nodes (b,) (each on a B-rep vertex or edge): (0, vertex, 0) on a
    vertex (its root after collapses), (1, edge, parameter's bits) on an edge; the weld's identity of such nodes."""
    vert = patch.node_vertex[nodes]
    if vertex_roots is not None and len(vertex_roots):
        vert = np.where(vert >= 0, vertex_roots[np.maximum(vert, 0)], -1)
    on_v = vert >= 0
    bits = np.ascontiguousarray(patch.node_param[nodes] + 0.0).view(np.int64)  # + 0.0: −0.0 and 0.0 one key
    return np.stack([np.where(on_v, 0, 1), np.where(on_v, vert, patch.node_edge[nodes]), np.where(on_v, 0, bits)],
                    axis=1).astype(np.int64)


@dataclass
class BrepGaps:
    """The B-rep's gap: a seated node's distance from a face it bounds, after projection; the largest seen in any round,
    per face and per B-rep edge (mm); and `moved`, the farthest a face's boundary node was moved to the point its
    faces share (mm): where their pcurves disagree along the surfaces, the gap is nil and this is not."""

    face: dict[int, float] = field(default_factory=dict)
    edge: dict[int, float] = field(default_factory=dict)
    moved: float = 0.0

    def record(self, face: int, edges: np.ndarray, gap: np.ndarray) -> None:
        """Keep the largest of the gaps (n,) of a face's nodes, for the face and for each node's edge (n,) (−1: a
        vertex, no edge)."""
        self.face[face] = max(self.face.get(face, 0.0), float(gap.max(initial=0.0)))
        for e, g in zip(*_max_by(edges[edges >= 0], gap[edges >= 0]), strict=True):
            self.edge[e] = max(self.edge.get(e, 0.0), g)


def seat_boundaries(patches: list[FacePatch | None], surfaces: list[Surface | None], vertex_roots: np.ndarray | None,
                    tol: float, gaps: BrepGaps) -> dict[int, np.ndarray]:
    """Give every boundary node of `patches` (F,) (updated in place) one point per key (node_keys): where the nodes
    of a key spread farther than SEAT_REL × tol from their mean, the point nearest all its faces' surfaces (seat's
    iteration: where the faces meet, if they do near there), each such node's (u,v) its projection on its face (not
    at a pole: a patch with several nodes on one vertex keeps their (u,v)); else the first patch's node (the point
    the weld keeps, bit for bit). Returns {face: (k,) bool its nodes moved farther than SEAT_REL × tol}; each such
    node's distance from its face after projection goes into `gaps`, and how far it moved into gaps.moved."""
    moved_nodes: dict[int, np.ndarray] = {}
    idx = [i for i, p in enumerate(patches) if p is not None and len(p.nodes)]
    on = [np.flatnonzero((patches[i].node_vertex >= 0) | (patches[i].node_edge >= 0)) for i in idx]  # type: ignore[union-attr]
    if not sum(len(b) for b in on):
        return moved_nodes
    keys = [node_keys(patches[i], b, vertex_roots) for i, b in zip(idx, on, strict=True)]  # type: ignore[arg-type]
    nodes = np.concatenate([patches[i].nodes[b] for i, b in zip(idx, on, strict=True)])  # type: ignore[union-attr]
    group, first = group_rows(np.concatenate(keys))
    mean = _group_mean(group, nodes)
    off = np.linalg.norm(mean[group] - nodes, axis=1)
    reach = np.zeros(len(mean))
    np.maximum.at(reach, group, SEAT_REACH * off)
    spread = reach > SEAT_REACH * SEAT_REL * tol
    far = spread[group]
    offsets = np.cumsum([0] + [len(b) for b in on])
    movable = np.zeros(len(nodes), bool)  # a node whose (u,v) is projected: on a surface, not at a pole
    uv = np.full((len(nodes), 2), np.nan)
    for j, (i, k, b) in enumerate(zip(idx, keys, on, strict=True)):
        p = patches[i]
        local = np.flatnonzero(far[offsets[j]:offsets[j + 1]])
        if not len(local) or surfaces[i] is None or p.uv is None or p.meshed_by == "stored":  # type: ignore[union-attr]
            continue
        vertex, uses = np.unique(k[k[:, 0] == 0, 1], return_counts=True)
        local = local[~((k[local, 0] == 0) & np.isin(k[local, 1], vertex[uses > 1]))]
        movable[offsets[j] + local] = True
        uv[offsets[j] + local] = p.uv[b[local]]  # type: ignore[union-attr]
    point = np.where(spread[:, None], mean, nodes[first])
    active = reach > SEAT_REACH * NEWTON_REL * tol  # keys whose faces' meeting point is worth the iteration
    for _ in range(SEAT_ROUNDS):
        if not active.any():
            break
        on_face, normal, _d = _project(point[group], uv, movable & active[group], nodes, offsets, idx, surfaces)
        step = np.where(active[:, None], _nearest_step(group, point[group], on_face, normal, len(point)), 0.0)
        again = _within(point + step, mean, reach)
        active &= np.linalg.norm(again - point, axis=1) > SEAT_REL * tol
        point = again
    # the (u,v) of the point kept: a step or two from where the last projection (or the node's own) left it
    _, _, dist = _project(point[group], uv, movable, nodes, offsets, idx, surfaces, iterations=2, normals=False)
    target = point[group]
    for j, (i, b) in enumerate(zip(idx, on, strict=True)):
        here = slice(offsets[j], offsets[j + 1])
        if not (target[here] != nodes[here]).any():
            continue
        p = patches[i]
        seated = p.nodes.copy()  # type: ignore[union-attr]
        seated[b] = target[here]
        new_uv = p.uv  # type: ignore[union-attr]
        sel = movable[here]
        if sel.any():
            new_uv = new_uv.copy()  # type: ignore[union-attr]
            new_uv[b[sel]] = uv[here][sel]
        patches[i] = replace(p, nodes=seated, uv=new_uv)  # type: ignore[arg-type]
        moved = far[here]
        if not moved.any():
            continue
        moved_nodes[i] = np.zeros(len(seated), bool)
        moved_nodes[i][b[moved]] = True
        gaps.record(i, p.node_edge[b[moved]], dist[here][moved])  # type: ignore[union-attr]
        move = np.linalg.norm(target[here][moved] - nodes[here][moved], axis=1)
        gaps.moved = max(gaps.moved, float(move.max(initial=0.0)))
    return moved_nodes


def _project(points: np.ndarray, uv: np.ndarray, movable: np.ndarray, nodes: np.ndarray, offsets: np.ndarray,
             idx: list[int], surfaces: list[Surface | None], iterations: int = 12,
             normals: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each movable row's point (n, 3) projected on its patch's surface (at most `iterations` Gauss–Newton steps), its
    (u,v) in `uv` (n, 2) updated from where it was: ((n, 3) the projection, the row's own node elsewhere; (n, 3) the
    unit surface normal there (0 where S_u ∥ S_v), nan elsewhere; (n,) the point's distance from it, 0 elsewhere); with `normals` False
    only `uv` and the distances."""
    on_face, normal, dist = nodes.copy(), np.full((len(nodes), 3), np.nan), np.zeros(len(nodes))
    for j in np.unique(np.searchsorted(offsets, np.flatnonzero(movable), side="right") - 1).tolist():
        rows = offsets[j] + np.flatnonzero(movable[offsets[j]:offsets[j + 1]])
        surface = surfaces[idx[j]]
        uv[rows], dist[rows] = project_points(surface, points[rows], uv[rows], iterations)  # type: ignore[arg-type]
        if not normals:
            continue
        on_face[rows] = surface.evaluate(uv[rows])  # type: ignore[union-attr]
        normal[rows] = surface_normals(surface, uv[rows])  # type: ignore[arg-type]
    return on_face, normal, dist


def _nearest_step(group: np.ndarray, x: np.ndarray, on_face: np.ndarray, normal: np.ndarray, n_groups: int) -> np.ndarray:
    """(g, 3) the step that takes each group's point (x (n, 3), one per row, equal in a group) to the least-squares
    point of its rows' tangent planes (point on_face, unit normal; a row with no normal (nan) holds it at its own
    point in every direction, a zero normal, at an apex, adds nothing): solve (Σ n nᵀ + λI) s = Σ n (n·(p − x)), λ small, so a direction no plane fixes (along
    the edge) gets no step. Newton on Σ distance²: where the faces meet, the point where they do."""
    free = np.isnan(normal[:, 0])
    nn = np.where(free[:, None, None], np.eye(3)[None], normal[:, :, None] * normal[:, None, :])
    d = on_face - x
    rhs = np.where(free[:, None], d, normal * (normal * d).sum(axis=1, keepdims=True))
    a = np.stack([np.bincount(group, weights=nn[:, i, j], minlength=n_groups) for i in range(3) for j in range(3)],
                 axis=1).reshape(-1, 3, 3)
    b = np.stack([np.bincount(group, weights=rhs[:, i], minlength=n_groups) for i in range(3)], axis=1)
    return np.linalg.solve(a + 1e-6 * np.eye(3)[None], b[:, :, None])[:, :, 0]


def _within(points: np.ndarray, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """(g, 3) each point pulled back onto its ball (centre (g, 3), radius (g,)) when outside it."""
    d = points - centres
    r = np.linalg.norm(d, axis=1)
    scale = np.where(r > radii, radii / np.maximum(r, 1e-300), 1.0)
    return centres + d * scale[:, None]


def _group_mean(group: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(g, 3) mean of the points (n, 3) of each group (n,)."""
    count = np.bincount(group)
    return np.stack([np.bincount(group, weights=points[:, k], minlength=len(count)) for k in range(3)], axis=1) \
        / count[:, None]


def _max_by(keys: np.ndarray, values: np.ndarray) -> tuple[list[int], list[float]]:
    """(distinct keys, the largest value of each) of keys (n,) int and values (n,)."""
    if not len(keys):
        return [], []
    order = np.lexsort((values, keys))
    last = np.r_[keys[order][1:] != keys[order][:-1], True]
    return keys[order][last].tolist(), values[order][last].tolist()


def weld(patches: list[FacePatch], faces: tuple[FaceInfo, ...], vertex_roots: np.ndarray | None = None) -> Mesh:
    """One Mesh from per-face patches; triangles that collapse onto one vertex (poles, apexes, edges the mesher
    collapsed) are dropped, and so are fins (fins: two triangles on the same three vertices, wound both ways). vertex_roots (n_brep_vertices,) maps B-rep vertices identified by collapsed edges."""
    if not patches:
        return Mesh.from_arrays(np.zeros((0, 3)), np.zeros((0, 3), np.int64)).with_arrays(faces=faces)
    nodes = np.concatenate([p.nodes for p in patches])
    vert = np.concatenate([p.node_vertex for p in patches])
    if vertex_roots is not None and len(vertex_roots):
        vert = np.where(vert >= 0, vertex_roots[np.maximum(vert, 0)], -1)
    edge = np.concatenate([p.node_edge for p in patches])
    param = np.concatenate([p.node_param for p in patches])
    stored = np.concatenate([np.full(len(p.nodes), p.meshed_by == "stored") for p in patches])
    offsets = np.cumsum([0] + [len(p.nodes) for p in patches[:-1]])

    n = len(nodes)
    dim = np.full(n, IN_FACE, np.int8)
    entity = np.concatenate([np.full(len(p.nodes), p.face_id, np.int64) for p in patches])
    on_v = vert >= 0
    on_e = (~on_v) & (edge >= 0)
    free_stored = (~on_v) & (~on_e) & stored
    interior = (~on_v) & (~on_e) & (~stored)
    dim[on_v], entity[on_v] = ON_BREP_VERTEX, vert[on_v]
    dim[on_e], entity[on_e] = ON_BREP_EDGE, edge[on_e]
    # one mesh vertex per B-rep vertex, per (B-rep edge, parameter), per stored coordinate, per interior node
    gid = np.empty(n, np.int64)
    firsts: list[np.ndarray] = []
    base = 0
    for mask, key in ((on_v, vert[:, None]), (on_e, np.stack([edge, param], axis=1)), (free_stored, nodes),
                      (interior, None)):
        idx = np.flatnonzero(mask)
        if key is None:
            gid[idx] = base + np.arange(len(idx))
            firsts.append(idx)
            base += len(idx)
            continue
        _, f, inv = np.unique(key[idx], axis=0, return_index=True, return_inverse=True)
        gid[idx] = base + inv.reshape(-1)
        firsts.append(idx[f])
        base += len(f)
    first = np.concatenate(firsts)

    tris = np.concatenate([gid[p.tris + o] for p, o in zip(patches, offsets, strict=False)])
    face_ids = np.concatenate([np.full(len(p.tris), p.face_id, np.int32) for p in patches])
    uv = np.concatenate([
        p.uv[p.tris] if p.uv is not None else np.full((len(p.tris), 3, 2), np.nan) for p in patches
    ])
    keep = distinct_corners(tris)
    keep[keep] = ~fins(tris[keep], face_ids[keep], (dim[first] != IN_FACE)[tris[keep]].all(axis=1))
    tris, face_ids, uv = tris[keep], face_ids[keep], uv[keep]
    used = np.flatnonzero(np.bincount(tris.reshape(-1), minlength=len(first)))
    remap = np.full(len(first), -1, np.int64)
    remap[used] = np.arange(len(used))
    src = first[used]
    return Mesh(
        vertices=nodes[src], triangles=remap[tris], face_ids=face_ids, uv=uv,
        vertex_dim=dim[src], vertex_entity=entity[src].astype(np.int32),
        vertex_param=np.where(dim[src] == ON_BREP_EDGE, param[src], np.nan), faces=faces,
    )


def folded_pairs(tris: np.ndarray, face_ids: np.ndarray) -> np.ndarray:
    """(t,) bool: triangles (t, 3) of a pair in one face (face_ids (t,)) on the same three vertices, wound opposite ways:
    a fin of zero volume, made where a face's (u,v) triangles on either side of a line meet at a pole (two pole
    nodes, one vertex); dropping both leaves each of its sides with the uses it had without the fin."""
    if len(tris) < 2:
        return np.zeros(len(tris), bool)
    rows = np.concatenate([np.sort(tris, axis=1), face_ids[:, None]], axis=1).astype(np.int64)
    out = np.zeros(len(tris), bool)
    cand = _repeated_rows(rows)  # the exact grouping below only on rows whose hash repeats: few, where t is large
    if len(cand) == 0:
        return out
    t = tris[cand]
    odd = ((t[:, 0] > t[:, 1]).astype(np.int8) + (t[:, 0] > t[:, 2]) + (t[:, 1] > t[:, 2])) % 2
    _, inv, count = np.unique(rows[cand], axis=0, return_inverse=True, return_counts=True)
    inv = inv.reshape(-1)
    odd_in_group = np.bincount(inv, weights=odd, minlength=len(count))
    out[cand] = (count[inv] == 2) & (odd_in_group[inv] == 1)
    return out


def _repeated_rows(rows: np.ndarray) -> np.ndarray:
    """Sorted indices of the rows (t, k) int64 whose 64-bit hash Σ rows[:, j]·c_j (wrapping) another row shares: every
    row that has an identical row, and rarely a collision, which the caller's exact test sorts out."""
    mult = np.array([0x9E3779B97F4A7C15, 0xC2B2AE3D27D4EB4F, 0x165667B19E3779F9, 0x27D4EB2F165667C5], np.uint64)
    h = np.zeros(len(rows), np.uint64)
    for j in range(rows.shape[1]):
        h += rows[:, j].astype(np.uint64) * mult[j % len(mult)] + np.uint64(j)
    hs = np.sort(h)
    dup = hs[1:][hs[1:] == hs[:-1]]
    return np.flatnonzero(np.isin(h, dup))


def fins(tris: np.ndarray, face_ids: np.ndarray, on_boundary: np.ndarray) -> np.ndarray:
    """(t,) bool: the triangles (t, 3) of fins: folded_pairs within a face (face_ids (t,)), and across two faces where
    all three corners lie on B-rep edges or vertices (on_boundary (t,)): two faces meeting along two edges at a
    narrow corner each close it with the same triangle of boundary nodes (FreeCAD's SOT23 IDF part at 0.1 mm)."""
    out = folded_pairs(tris, face_ids)
    rest = np.flatnonzero(on_boundary & ~out)
    out[rest[folded_pairs(tris[rest], np.zeros(len(rest), np.int64))]] = True
    return out


def pole_folds(patch: FacePatch) -> bool:
    """True when a face's triangles, its nodes on one B-rep vertex made one (a pole), fold: a side used by more than
    two of them, or a folded pair (folded_pairs) that the weld would have to drop."""
    key = np.where(patch.node_vertex >= 0, patch.node_vertex, patch.node_vertex.max(initial=0) + 1
                   + np.arange(len(patch.node_vertex)))
    tris = key[patch.tris]
    tris = tris[distinct_corners(tris)]
    if len(tris) == 0:
        return False
    _, tris = np.unique(tris, return_inverse=True)
    tris = tris.reshape(-1, 3)
    return bool(edge_incidence(tris).count.max() > 2 or folded_pairs(tris, np.zeros(len(tris), np.int64)).any())


def agree_face_orientations(mesh: Mesh, certain: np.ndarray) -> Mesh:
    """The mesh with whole faces reversed where neighbours run the same way along a shared edge: faces joined by
    shared edges split into two classes of relative orientation (a doubled graph, two nodes a face), and in each
    group whose classes are consistent the class with less area on faces whose winding is `certain` ((F,) bool: not
    placed by a mirror, topology.winds_inward), then less area, is reversed. Unchanged where no two faces disagree,
    and unlooked at when every face's winding is certain."""
    tris = mesh.triangles
    if certain.all() or not len(tris):
        return mesh
    inc = edge_incidence(tris, with_order=True)
    twice = np.flatnonzero(inc.count == 2)
    if (inc.forward[twice] == 1).all():
        return mesh
    first = (np.cumsum(inc.count) - inc.count)[twice]
    f1, f2 = mesh.face_ids[inc.order[first] // 3], mesh.face_ids[inc.order[first + 1] // 3]  # type: ignore[index]
    pair = (f1 != f2) & (f1 >= 0) & (f2 >= 0)
    f1, f2, odd = f1[pair], f2[pair], (inc.forward[twice] != 1)[pair].astype(np.int64)
    n = len(mesh.faces)
    rows = np.concatenate([2 * f1, 2 * f1 + 1])
    cols = np.concatenate([2 * f2 + odd, 2 * f2 + 1 - odd])
    _, label = connected_components(coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(2 * n, 2 * n)),
                                     directed=False)
    cls, partner = label[0::2], label[1::2]
    fine = cls != partner  # a face in both classes: its group cannot be oriented, left as it is
    on_face = mesh.face_ids >= 0
    area = np.bincount(mesh.face_ids[on_face], triangle_areas(mesh.corners[on_face]), minlength=n)
    sure = np.bincount(cls[fine], (area * certain)[fine], minlength=2 * n)
    total = np.bincount(cls[fine], area[fine], minlength=2 * n)
    flip = fine & ((sure[cls] < sure[partner]) | ((sure[cls] == sure[partner]) & (total[cls] < total[partner])))
    if not flip.any():
        return mesh
    sel = on_face & flip[np.maximum(mesh.face_ids, 0)]
    tris = tris.copy()
    tris[sel] = tris[sel][:, [0, 2, 1]]
    uv = None if mesh.uv is None else mesh.uv.copy()
    if uv is not None:
        uv[sel] = uv[sel][:, [0, 2, 1]]
    return mesh.with_arrays(triangles=tris, uv=uv)


def orient_stored_shells(mesh: Mesh) -> Mesh:
    """Reverse every closed shell made only of stored (tessellated-only) faces whose signed volume is negative:
    with no surface to orient them, a closed shell's own volume says which side is out."""
    stored = np.array([f.meshed_by == "stored" for f in mesh.faces], bool)
    if mesh.n_triangles == 0 or not stored.any():
        return mesh
    n, label = shell_labels(mesh)
    inc = edge_incidence(mesh.triangles)
    open_tri = (inc.count[inc.edge_of] != 2).any(axis=1)
    tris = mesh.triangles.copy()
    uv = None if mesh.uv is None else mesh.uv.copy()
    flipped = False
    for s in range(n):
        sel = label == s
        if open_tri[sel].any() or not stored[mesh.face_ids[sel]].all():
            continue
        if signed_volume(mesh.corners[sel]) < 0:
            tris[sel] = tris[sel][:, [0, 2, 1]]
            if uv is not None:
                uv[sel] = uv[sel][:, [0, 2, 1]]
            flipped = True
    return mesh.with_arrays(triangles=tris, uv=uv) if flipped else mesh


def split_caps(mesh: Mesh) -> Mesh:
    """The mesh with each cap folded into the neighbour across its longest side, in the same face: a degenerate
    triangle (checks.degenerate_mask) (a, c, b) whose corner b lies between a and c (three nodes of one straight
    edge, an ear a face's (u,v) Delaunay keeps where the edge is curved in (u,v); flat once welded) and the
    neighbour (c, a, d) become (c, b, d) and (b, a, d), which split the neighbour at b: the same surface, the cap's
    two other sides kept with their directions, so the mesh stays closed and oriented; a cap whose neighbour is
    missing, in another face, another cap's or flat itself is left."""
    caps = np.flatnonzero(degenerate_mask(mesh))
    if not len(caps) or mesh.n_triangles < 2:
        return mesh
    tris, uv, v = mesh.triangles.copy(), None if mesh.uv is None else mesh.uv.copy(), mesh.vertices
    n = np.int64(mesh.n_vertices)
    directed = (tris.astype(np.int64) * n + np.roll(tris, -1, axis=1)).ravel()  # side k of t: t·3 + k, corner k → k+1
    order = np.argsort(directed, kind="stable")
    used: set[int] = set()
    for t in caps.tolist():
        c = v[tris[t]]
        k = int(np.argmax(np.linalg.norm(np.roll(c, -1, axis=0) - c, axis=1)))  # the longest side: corners k, k+1
        a, cc, b = (int(tris[t, (k + j) % 3]) for j in range(3))
        along = float(np.dot(v[b] - v[a], v[cc] - v[a]) / max(float(np.dot(v[cc] - v[a], v[cc] - v[a])), 1e-300))
        i = np.searchsorted(directed[order], cc * n + a)
        if not (0 < along < 1) or i >= len(order) or directed[order[i]] != cc * n + a or t in used:
            continue
        nb, j = divmod(int(order[i]), 3)  # the neighbour's side j runs c → a; its corner j + 2 is d
        d = int(tris[nb, (j + 2) % 3])
        new = np.array([[cc, b, d], [b, a, d]])
        area = np.linalg.norm(cross(v[new[:, 1]] - v[new[:, 0]], v[new[:, 2]] - v[new[:, 0]]), axis=1)
        if (nb in used or mesh.face_ids[nb] != mesh.face_ids[t] or d in (a, b, cc)
                or not (area > 1e-9 * float(np.dot(v[cc] - v[a], v[cc] - v[a]))).all()):
            continue
        used.update((t, nb))
        tris[t], tris[nb] = new
        if uv is not None:
            uc, ua, ub, ud = uv[nb, j], uv[nb, (j + 1) % 3], uv[t, (k + 2) % 3], uv[nb, (j + 2) % 3]
            uv[t], uv[nb] = np.stack([uc, ub, ud]), np.stack([ub, ua, ud])
    return mesh.with_arrays(triangles=tris, uv=uv) if used else mesh


def pinch_double_sheets(mesh: Mesh) -> Mesh:
    """The mesh with each double sheet pinched: two faces thinner apart than the tolerance (a sliver between a chamfer
    and a fillet that share both long edges: KiCad's Molex PicoBlade at 0.1 mm), each meshed within it as a strip
    straight across, share inner edges (each used twice by both faces: four triangles on one edge). The triangles of
    those two faces whose three corners all lie on such shared edges cover the same strip both ways: both sets are
    dropped, kept only where every edge they leave is then used by no triangle or by two running opposite ways (the
    sheet closed, of zero thickness within the tolerance). Only triangles with every corner on a B-rep edge or vertex
    are searched (a strip straight across has no inner node)."""
    if mesh.n_triangles < 4 or mesh.vertex_dim is None:
        return mesh
    rim = np.flatnonzero((mesh.vertex_dim != IN_FACE)[mesh.triangles].all(axis=1))
    if len(rim) < 3:
        return mesh
    inc = edge_incidence(mesh.triangles[rim])
    n = np.int64(mesh.n_vertices)
    suspects = np.sort(inc.edges[inc.count >= 3, 0] * n + inc.edges[inc.count >= 3, 1])  # a shared rung: 3 or 4 here
    if not len(suspects):
        return mesh
    codes = edge_codes(mesh.triangles, n).ravel()  # side k of triangle t at 3t + k, corner k → k + 1
    at = np.flatnonzero(np.isin(codes, suspects))
    pairs: dict[tuple[int, int], list[int]] = {}
    for code in suspects.tolist():  # a few edges: two triangles from each of two faces
        faces, uses = np.unique(mesh.face_ids[at[codes[at] == code] // 3], return_counts=True)
        if len(faces) == 2 and (uses == 2).all() and faces.min() >= 0:
            pairs.setdefault((int(faces[0]), int(faces[1])), []).append(code)
    if not pairs:
        return mesh
    forward = (mesh.triangles < np.roll(mesh.triangles, -1, axis=1)).ravel()
    drop = np.zeros(mesh.n_triangles, bool)
    for (fa, fb), edges in pairs.items():
        ends = np.unique(np.concatenate(np.divmod(np.array(edges, np.int64), n)))
        cand = np.zeros(mesh.n_triangles, bool)
        cand[rim] = np.isin(mesh.face_ids[rim], (fa, fb)) & np.isin(mesh.triangles[rim], ends).all(axis=1)
        cand &= ~drop
        touched = np.unique(codes[np.repeat(cand, 3)])
        kept = np.isin(codes, touched) & np.repeat(~(drop | cand), 3)  # the sides left on those edges
        k = np.searchsorted(touched, codes[kept])
        left = np.bincount(k, minlength=len(touched))
        ahead = np.bincount(k, weights=forward[kept], minlength=len(touched))
        if cand.any() and ((left == 0) | ((left == 2) & (ahead == 1))).all():  # closed and oriented
            drop |= cand
    if not drop.any():
        return mesh
    keep = ~drop
    tris = mesh.triangles[keep]
    used = np.flatnonzero(np.bincount(tris.ravel(), minlength=mesh.n_vertices))
    remap = np.full(mesh.n_vertices, -1, np.int64)
    remap[used] = np.arange(len(used))
    pick = (lambda a: None if a is None else a[used])  # noqa: E731
    return mesh.with_arrays(vertices=mesh.vertices[used], triangles=remap[tris], face_ids=mesh.face_ids[keep],
                            uv=None if mesh.uv is None else mesh.uv[keep], vertex_dim=pick(mesh.vertex_dim),
                            vertex_entity=pick(mesh.vertex_entity), vertex_param=pick(mesh.vertex_param))
