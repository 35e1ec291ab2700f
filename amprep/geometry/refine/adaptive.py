"""Error-driven adaptive refinement (beyond SMA, ALGORITHMS.md): only triangles whose chordal error exceeds the
target are split, each at the (u,v) midpoint of its longest splittable edge, and every split is propagated to the
neighbour across that edge (longest-edge closure), so no T-junction is ever made. A contour edge (shared with another
face) is split on both sides, at the mid parameter of its B-rep edge, or not at all; the other face's triangle is
only bisected there. A closed mesh stays closed."""

from __future__ import annotations

import numpy as np

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.cad.edge_curves import EdgeCurves
from amprep.geometry.cad.surfaces import Surface, nearest_copy, tangents
from amprep.geometry.core.edges import edge_codes, face_edge_table
from amprep.geometry.core.mesh import IN_FACE, NO_TOPOLOGY, ON_BREP_EDGE, ON_BREP_VERTEX, Mesh
from amprep.geometry.measure.chordal import triangle_chordal_error
from amprep.geometry.refine.face_domain import FaceDomains
from amprep.geometry.refine.sma import Refinement


def _errors(verts: np.ndarray, tris: np.ndarray, uvs: np.ndarray, fids: np.ndarray, faces: np.ndarray,
            surfaces: dict[int, Surface], order: int, known: np.ndarray | None = None) -> np.ndarray:
    """(m,) chordal error of the triangles of `faces` (0 elsewhere); where `known` (m,) is not nan, its value (a
    triangle kept whole since it was measured: each triangle's error is its own, whatever else is measured with it)."""
    err = np.zeros(len(tris)) if known is None else np.nan_to_num(known, nan=0.0)
    todo = np.ones(len(tris), bool) if known is None else np.isnan(known)
    for f in faces:
        t = np.flatnonzero((fids == f) & todo)
        if len(t):
            err[t] = triangle_chordal_error(verts[tris[t]], uvs[t], surfaces[int(f)], order)
    return err


def pole_vertices(verts: np.ndarray, tris: np.ndarray, uvs: np.ndarray, fids: np.ndarray, vdim: np.ndarray,
                  surfaces: dict[int, Surface], faces: np.ndarray) -> dict[tuple[int, int], int]:
    """{(vertex, face): free (u,v) coordinate} of the poles among the B-rep vertices of `faces` (any vertex of a mesh
    with no B-rep topology: a user's STL placed on its CAD): a vertex whose corners in the face differ in one
    coordinate only, and whose surface point halfway between two of them is the vertex itself (a cone's apex, a
    sphere's pole; on a seam the point halfway is elsewhere)."""
    r, c = np.nonzero(np.isin(vdim[tris], (ON_BREP_VERTEX, NO_TOPOLOGY)) & np.isin(fids, faces)[:, None])
    if not len(r):
        return {}
    key = tris[r, c].astype(np.int64) * (int(fids.max()) + 1) + fids[r]  # one group per (vertex, face)
    order = np.argsort(key, kind="stable")
    start = np.flatnonzero(np.r_[True, np.diff(key[order]) != 0])
    uv = uvs[r, c][order]
    lo, hi = np.minimum.reduceat(uv, start, axis=0), np.maximum.reduceat(uv, start, axis=0)
    one_way = ((hi - lo) > 1e-9).sum(axis=1) == 1
    v, f = tris[r, c][order][start][one_way], fids[r][order][start][one_way]
    half = np.empty((len(v), 3))
    for face in np.unique(f):
        sel = f == face
        half[sel] = surfaces[int(face)].evaluate(0.5 * (lo + hi)[one_way][sel])
    at_vertex = np.linalg.norm(half - verts[v], axis=1) <= 1e-6 * (1.0 + np.abs(verts[v]).max(axis=1))
    free = np.argmax((hi - lo)[one_way], axis=1)
    found = {(int(a), int(b)): int(k) for a, b, k in zip(v[at_vertex], f[at_vertex], free[at_vertex], strict=True)}
    same = ((hi - lo) > 1e-9).sum(axis=1) == 0  # one (u,v) in every corner (a projected STL vertex): S_u or S_v ≈ 0
    v, f = tris[r, c][order][start][same], fids[r][order][start][same]
    for face in np.unique(f):
        sel = np.flatnonzero(f == face)
        free = _degenerate_direction(surfaces[int(face)], lo[same][sel])
        found.update(((int(v[i]), int(face)), int(k)) for i, k in zip(sel[free >= 0], free[free >= 0], strict=True))
    return found


def _degenerate_direction(surface: Surface, uv: np.ndarray) -> np.ndarray:
    """(n,) 0 where S_u ≈ 0 at (n, 2) uv (u free: an apex, a pole), 1 where S_v ≈ 0, −1 elsewhere (surfaces.tangents),
    ≈ 0 meaning under 1e-6 of the other direction's."""
    su, sv = (np.linalg.norm(t, axis=1) for t in tangents(surface, uv))
    return np.where(su <= 1e-6 * sv, 0, np.where(sv <= 1e-6 * su, 1, -1))


PoleCorners = tuple[np.ndarray, np.ndarray, np.ndarray]


def _pole_corners(tris: np.ndarray, fids: np.ndarray, poles: dict[tuple[int, int], int],
                  n_faces: int) -> PoleCorners:
    """(rows, cols, free coordinate) of the triangle corners that are poles of their triangle's face."""
    if not poles:
        empty = np.zeros(0, np.int64)
        return empty, empty, empty
    keys = np.array([v * n_faces + f for v, f in poles], np.int64)
    free = np.array(list(poles.values()), np.int64)
    order = np.argsort(keys)
    keys, free = keys[order], free[order]
    corner = tris.astype(np.int64) * n_faces + fids[:, None]
    at = np.minimum(np.searchsorted(keys, corner), len(keys) - 1)
    r, c = np.nonzero(keys[at] == corner)
    return r, c, free[at[r, c]]


def _centre_poles(uvs: np.ndarray, pole: PoleCorners) -> np.ndarray:
    """(m, 3, 2) the corners' (u,v) with each pole corner (`pole`: _pole_corners) given, in its free coordinate, the
    mean of the triangle's two other corners' (where the triangle leaves the pole), so the (u,v) triangle maps onto
    the 3D one without a fold."""
    out = uvs.copy()
    r, c, k = pole
    out[r, c, k] = 0.5 * (uvs[r, (c + 1) % 3, k] + uvs[r, (c + 2) % 3, k])
    return out


def _mid_uv(uvs: np.ndarray, pole: PoleCorners) -> np.ndarray:
    """(m, 3, 2) (u,v) midpoint of each edge (corner s → s+1); at a pole corner (`pole`: _pole_corners), its free
    coordinate is taken from the edge's other end, so the midpoint lies on the line from that end to the pole (a
    cone's ruling, a sphere's meridian) instead of wherever the pole's corner happens to sit."""
    ends = uvs.copy()
    nxt = np.roll(uvs, -1, axis=1)
    r, c, k = pole
    ends[r, c, k] = nxt[r, c, k]  # the pole as the first end of edge c
    prev = (c + 2) % 3
    nxt[r, prev, k] = uvs[r, prev, k]  # and as the second end of edge c − 1
    return 0.5 * (ends + nxt)


def _edge_sagitta(corners: np.ndarray, mid_uv: np.ndarray, fids: np.ndarray, chosen: np.ndarray,
                  surfaces: dict[int, Surface]) -> np.ndarray:
    """(m, 3) |S(uv midpoint) − chord midpoint| of each edge (corner s → s+1) of the chosen triangles (0 elsewhere)."""
    out = np.zeros((len(corners), 3))
    chord = 0.5 * (corners + np.roll(corners, -1, axis=1))
    for f in np.unique(fids[chosen]):
        t = np.flatnonzero(chosen & (fids == f))
        pts = surfaces[int(f)].evaluate(mid_uv[t].reshape(-1, 2)).reshape(-1, 3, 3)
        out[t] = np.linalg.norm(pts - chord[t], axis=2)
    return out


def _contour_sagitta(corners: np.ndarray, uvs: np.ndarray, fids: np.ndarray, contour: np.ndarray,
                     surfaces: dict[int, Surface]) -> np.ndarray:
    """(m,) the largest |S(uv midpoint) − chord midpoint| over each triangle's contour edges (0 without one): the
    error its unsplittable edges leave, which splitting the triangle inside cannot remove."""
    out = np.zeros(len(corners))
    r, c = np.nonzero(contour)
    if len(r) == 0:
        return out
    mid_uv = 0.5 * (uvs[r, c] + uvs[r, (c + 1) % 3])
    chord = 0.5 * (corners[r, c] + corners[r, (c + 1) % 3])
    sag = np.zeros(len(r))
    for f in np.unique(fids[r]):
        sel = fids[r] == f
        sag[sel] = np.linalg.norm(surfaces[int(f)].evaluate(mid_uv[sel]) - chord[sel], axis=1)
    np.maximum.at(out, r, sag)
    return out


def _on_both_faces(curves: EdgeCurves, hit: tuple[int, float], rows: np.ndarray, cols: np.ndarray, uvs: np.ndarray,
                   fids: np.ndarray, surfaces: dict[int, Surface], tol: float) -> bool:
    """|S_f(pcurve_f(t)) − C(t)| ≤ tol on the face of each triangle slot (rows, cols) beside the edge: a split there
    puts the same point on both faces (an edge whose pcurve does not follow its 3D curve is left whole)."""
    edge, t = hit
    p = curves.point(edge, t)
    for r, c in zip(rows.tolist(), cols.tolist(), strict=True):
        near = 0.5 * (uvs[r, c] + uvs[r, (c + 1) % 3])
        uv = curves.uv(edge, int(fids[r]), t, near)
        if not np.linalg.norm(surfaces[int(fids[r])].evaluate(uv[None])[0] - p) <= tol:
            return False
    return True


def adaptive_refine(mesh: Mesh, faces: list[int] | np.ndarray, surfaces: dict[int, Surface], target: float,
                    max_triangles: int = 10_000_000, order: int = 6, max_rounds: int = 40,
                    curves: EdgeCurves | None = None, by_sagitta: bool = True,
                    domain: FaceDomains | None = None) -> Refinement:
    """Split the triangles of `faces` whose chordal error exceeds `target` until none does, `max_rounds` pass or the
    next round would exceed max_triangles. With `curves` (the B-rep edges of a CAD tessellation) a contour edge is
    split on both sides, its new vertex on the exact B-rep edge and on each face's pcurve; without, contour edges
    stay whole and a triangle whose error is its contour edge's own sagitta is left as it is. The edge split is
    the one whose midpoint lies farthest from the surface (by_sagitta; the longest in 3D otherwise). With `domain`
    an inner edge whose (u,v) midpoint lies off its face's trimmed domain is never split (its point would be on the
    surface's extension, beyond the face)."""
    if mesh.uv is None:
        raise AmprepError(ErrorCode.INVALID_PARAMETER, "adaptive refinement needs the (u,v) of every triangle corner")
    if not target > 0:
        raise AmprepError(ErrorCode.INVALID_PARAMETER, "the adaptive target must be > 0")
    faces = np.unique(np.asarray(faces, dtype=np.int64))
    verts, tris, fids, uvs = mesh.vertices, mesh.triangles, mesh.face_ids, mesh.uv
    vdim, vent, vpar = _vertex_keys(mesh)
    parent = np.arange(mesh.n_triangles)
    chosen = np.isin(fids, faces)
    unsplittable: set[tuple[int, int]] = set()  # contour edges with no B-rep edge behind them, or whose pcurves miss it
    seen: dict[tuple[int, int], tuple[bytes, tuple[int, float]]] = {}  # contour edges resolved, by vertex pair
    outside: set[int] = set()  # inner edges (pair codes) whose (u,v) midpoint is off their face's trimmed domain
    tol = 0.5 * target  # how far a pcurve's point may lie from the 3D edge's for the split to be taken
    poles = pole_vertices(verts, tris, uvs, fids, vdim, surfaces, faces)
    n_faces = int(fids.max()) + 1 if len(fids) else 1
    known = None
    for _ in range(max_rounds):
        pole = _pole_corners(tris, fids, poles, n_faces)  # the same triangles until this round's bisection
        uvs = _centre_poles(uvs, pole)
        current = Mesh(verts, tris, fids, None, vdim, vent, vpar)
        err = _errors(verts, tris, uvs, fids, faces, surfaces, order, known)
        edge_id, inner = face_edge_table(current)
        corners = verts[tris]
        resolved, on_curve = _splittable_contours(curves, current, chosen, edge_id, inner, uvs, surfaces, tol,
                                                  unsplittable, seen)
        splittable = (inner[edge_id] | on_curve[edge_id]) & chosen[:, None]
        length = np.linalg.norm(np.roll(corners, -1, axis=1) - corners, axis=2)  # edge s: corner s → s+1
        own_mid = _mid_uv(uvs, pole)  # (m, 3, 2)
        weight = _edge_sagitta(corners, own_mid, fids, chosen, surfaces) if by_sagitta else length
        floor = _contour_sagitta(corners, uvs, fids, ~(inner | on_curve)[edge_id] & chosen[:, None], surfaces)
        sides = edge_codes(tris, _PAIR)  # (m, 3) vertex-pair codes, fixed across rounds (outside keeps them)
        while True:  # a triangle with a side whose midpoint leaves its face's trim is not split; choose again
            free = splittable & ~np.isin(sides, np.fromiter(outside, np.int64, len(outside))).any(axis=1)[:, None]
            cand, has_cand, marked, split = _choose(free, weight + 1e-12 * length, length, err,
                                                    np.maximum(target, floor * (1 + 1e-9)), chosen, edge_id, len(inner))
            leaving = _leaving(domain, split & inner, edge_id, sides, own_mid, fids, surfaces) if marked.any() else set()
            if not leaving:
                break
            outside |= leaving
        if not marked.any():
            break
        edge_split = split[edge_id]  # (m, 3)
        n_split = edge_split.sum(axis=1)
        if len(tris) + int(n_split.sum()) > max_triangles:
            break
        # a triangle of another face across a split contour edge bisects that edge only (no propagation into it)
        other = (n_split > 0) & ~has_cand
        cand = np.where(other, np.where(edge_split, length, -1.0).argmax(axis=1), cand)
        # one new vertex per split edge: inner edges at S(uv midpoint) from their first triangle, contour edges on
        # the B-rep edge at the mid parameter
        slot_rows, slot_cols = np.nonzero(edge_split)
        at, new_xyz, new_dim, new_ent, new_par, mid_uv = _new_vertices(edge_id, slot_rows, slot_cols, own_mid, fids,
                                                                      resolved, curves, surfaces)
        vid = np.full((len(tris), 3), -1, np.int64)
        vid[slot_rows, slot_cols] = len(verts) + at
        verts = np.concatenate([verts, new_xyz])
        vdim, vent, vpar = np.concatenate([vdim, new_dim]), np.concatenate([vent, new_ent]), np.concatenate([vpar, new_par])
        tris, uvs, src = _bisect(tris, uvs, vid, mid_uv, cand, n_split)
        known = np.full(len(tris), np.nan)
        known[:int((n_split == 0).sum())] = err[n_split == 0]  # _bisect puts the whole ones first
        fids, chosen, parent = fids[src], chosen[src], parent[src]
    uvs = _centre_poles(uvs, _pole_corners(tris, fids, poles, n_faces))
    order_ = np.argsort(parent, kind="stable")
    refined = Mesh(verts, tris[order_], fids[order_], uvs[order_], vdim if mesh.vertex_dim is not None else None,
                   vent if mesh.vertex_entity is not None else None, vpar if mesh.vertex_param is not None else None,
                   mesh.faces)
    return Refinement(refined, {}, parent[order_])


#: edge_codes' base for vertex pairs kept across rounds (vertex ids grow, codes must not change)
_PAIR = 1 << 31


def _choose(free: np.ndarray, score: np.ndarray, length: np.ndarray, err: np.ndarray, over: np.ndarray,
            chosen: np.ndarray, edge_id: np.ndarray, n_edges: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(cand (m,), has_cand (m,), marked (m,), split (edges,)): each triangle's best splittable side (`free` (m, 3),
    `score` (m, 3)), the chosen triangles over `over` (m,) with one, and the edges split: theirs, closed so that a
    chosen triangle with any split side also splits its own best."""
    score = np.where(free & (length > 0), score, -1.0)
    cand = score.argmax(axis=1)
    has_cand = score.max(axis=1) >= 0
    marked = chosen & (err > over) & has_cand
    rows = np.arange(len(edge_id))
    split = np.zeros(n_edges, bool)
    split[edge_id[rows[marked], cand[marked]]] = True
    while True:
        touched = split[edge_id].any(axis=1) & has_cand
        need = edge_id[rows[touched], cand[touched]]
        if split[need].all():
            break
        split[need] = True
    return cand, has_cand, marked, split


def _leaving(domain: FaceDomains | None, split: np.ndarray, edge_id: np.ndarray, sides: np.ndarray,
             own_mid: np.ndarray, fids: np.ndarray, surfaces: dict[int, Surface]) -> set[int]:
    """The codes (`sides` (m, 3), edge_codes) of the split edges (`split` (edges,) bool) whose (u,v) midpoint, from
    their first triangle, lies off its face's trimmed domain."""
    if domain is None or not split.any():
        return set()
    r, c = np.nonzero(split[edge_id])
    _, first = np.unique(edge_id[r, c], return_index=True)
    r, c = r[first], c[first]
    off = np.zeros(len(r), bool)
    for f in np.unique(fids[r]):
        k = fids[r] == f
        off[k] = ~domain.inside(int(f), own_mid[r[k], c[k]], surfaces[int(f)].periods)
    return set(sides[r[off], c[off]].tolist())


def _vertex_keys(mesh: Mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(dim, entity, param) (n,) of every vertex: the mesh's own, or −1, −1, nan where it has none."""
    return (mesh.vertex_dim if mesh.vertex_dim is not None else np.full(mesh.n_vertices, -1, np.int8),
            mesh.vertex_entity if mesh.vertex_entity is not None else np.full(mesh.n_vertices, -1, np.int32),
            mesh.vertex_param if mesh.vertex_param is not None else np.full(mesh.n_vertices, np.nan))


def _splittable_contours(curves: EdgeCurves | None, current: Mesh, chosen: np.ndarray, edge_id: np.ndarray,
                         inner: np.ndarray, uvs: np.ndarray, surfaces: dict[int, Surface], tol: float,
                         unsplittable: set[tuple[int, int]], seen: dict[tuple[int, int], tuple[bytes, tuple[int, float]]]
                         ) -> tuple[dict[int, tuple[int, float]], np.ndarray]:
    """(_resolve_contours' {edge id: (B-rep edge, mid parameter)}, (edges,) bool: those edges) of the contour edges
    of chosen triangles with two triangles (none without `curves`)."""
    on_curve = np.zeros(len(inner), bool)
    if curves is None:
        return {}, on_curve
    count = np.bincount(edge_id.ravel(), minlength=len(inner))
    contour_slots = ~inner[edge_id] & chosen[:, None] & (count[edge_id] == 2)
    resolved = _resolve_contours(curves, current, contour_slots, edge_id, len(inner), uvs, surfaces, tol,
                                 unsplittable, seen)
    if resolved:
        on_curve[np.fromiter(resolved, np.int64)] = True
    return resolved, on_curve


def _resolve_contours(curves: EdgeCurves, current: Mesh, contour_slots: np.ndarray, edge_id: np.ndarray, n_edges: int,
                      uvs: np.ndarray, surfaces: dict[int, Surface], tol: float, unsplittable: set[tuple[int, int]],
                      seen: dict[tuple[int, int], tuple[bytes, tuple[int, float]]]) -> dict[int, tuple[int, float]]:
    """{edge id: (B-rep edge, mid parameter)} of the contour edges (contour_slots (m, 3)) that can be split on both
    sides: the B-rep edge behind them found and both faces' pcurves within `tol` of it; the others are added to
    `unsplittable` (vertex pairs) and never tried again. `seen` keeps, by vertex pair, each one found with what it was
    found from (its sides' faces and (u,v) ends): an edge left whole in a later round is not resolved again."""
    tris, fids = current.triangles, current.face_ids
    resolved: dict[int, tuple[int, float]] = {}
    r_, c_ = np.nonzero(contour_slots)
    slot_order = np.argsort(edge_id.ravel(), kind="stable")
    slot_start = np.searchsorted(edge_id.ravel()[slot_order], np.arange(n_edges))
    for e, a, b in zip(edge_id[r_, c_].tolist(), tris[r_, c_].tolist(), tris[r_, (c_ + 1) % 3].tolist(), strict=True):
        key = (min(a, b), max(a, b))
        if e in resolved or key in unsplittable:
            continue
        sides = slot_order[slot_start[e]:slot_start[e] + 2]
        rows, cols = sides // 3, sides % 3
        given = b"".join(sorted(fids[r].tobytes() + uvs[r, c].tobytes() + uvs[r, (c + 1) % 3].tobytes()
                                for r, c in zip(rows.tolist(), cols.tolist(), strict=True)))
        if key in seen and seen[key][0] == given:
            resolved[e] = seen[key][1]
            continue
        hit = curves.resolve(current, a, b)
        if hit is None or not _on_both_faces(curves, hit, rows, cols, uvs, fids, surfaces, tol):
            unsplittable.add(key)
        else:
            resolved[e] = hit
            seen[key] = (given, hit)
    return resolved


def _new_vertices(edge_id: np.ndarray, slot_rows: np.ndarray, slot_cols: np.ndarray, own_mid: np.ndarray,
                  fids: np.ndarray, resolved: dict[int, tuple[int, float]], curves: EdgeCurves | None,
                  surfaces: dict[int, Surface]) -> tuple[np.ndarray, ...]:
    """One new vertex per split edge (the slots (s,) given by rows and columns): inner edges at S(uv midpoint) from
    their first triangle, contour edges on the B-rep edge at the mid parameter. (at (s,) each slot's new vertex,
    xyz (n, 3), dim, entity, param (n,), mid_uv (m, 3, 2): each side's (u,v) of its edge's new vertex)."""
    eids = edge_id[slot_rows, slot_cols]
    uniq, first = np.unique(eids, return_index=True)
    canon_uv = own_mid[slot_rows[first], slot_cols[first]]
    canon_face = fids[slot_rows[first]]
    new_xyz = np.empty((len(uniq), 3))
    for f in np.unique(canon_face):
        sel = canon_face == f
        new_xyz[sel] = surfaces[int(f)].evaluate(canon_uv[sel])
    n_new = len(uniq)
    new_dim = np.full(n_new, IN_FACE, np.int8)
    new_ent = canon_face.astype(np.int32)
    new_par = np.full(n_new, np.nan)
    at = np.searchsorted(uniq, eids)
    mid_uv = own_mid.copy()
    for k, e in enumerate(uniq.tolist()):
        if e in resolved:
            edge, t = resolved[e]
            new_xyz[k] = curves.point(edge, t)  # type: ignore[union-attr]
            new_dim[k], new_ent[k], new_par[k] = ON_BREP_EDGE, edge, t
    for j in range(len(slot_rows)):  # each side's (u,v) of a contour vertex, from its own face's pcurve
        e = int(eids[j])
        if e in resolved:
            r, c = slot_rows[j], slot_cols[j]
            mid_uv[r, c] = curves.uv(resolved[e][0], int(fids[r]), resolved[e][1], own_mid[r, c],  # type: ignore[union-attr]
                                      surfaces[int(fids[r])].periods)
    inner_slot = ~np.isin(eids, np.fromiter(resolved, np.int64, len(resolved)))
    for f in np.unique(fids[slot_rows[inner_slot]]):
        sel = inner_slot & (fids[slot_rows] == f)
        r, c = slot_rows[sel], slot_cols[sel]
        mid_uv[r, c] = nearest_copy(canon_uv[at[sel]], own_mid[r, c], surfaces[int(f)].periods)
    return at, new_xyz, new_dim, new_ent, new_par, mid_uv


def _bisect(tris: np.ndarray, uvs: np.ndarray, vid: np.ndarray, mid_uv: np.ndarray, cand: np.ndarray,
            n_split: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split every triangle with split edges (vid ≥ 0 at those slots, the candidate among them): bisect the candidate
    edge 0 (p0 p1, mid m0) towards p2, then the halves by m2 on (p2, p0) and m1 on (p1, p2) when those are split;
    returns (triangles, their (u,v), the source triangle of each)."""
    t = np.flatnonzero(n_split > 0)
    idx = np.arange(len(t))[:, None]
    rot = (cand[t][:, None] + np.arange(3)) % 3
    p, pu = tris[t][idx, rot], uvs[t][idx, rot]
    m, mu = vid[t][idx, rot], mid_uv[t][idx, rot]
    s1, s2 = m[:, 1] >= 0, m[:, 2] >= 0
    p0, p1, p2, m0, m1, m2 = p[:, 0], p[:, 1], p[:, 2], m[:, 0], m[:, 1], m[:, 2]
    u0, u1, u2, w0, w1, w2 = pu[:, 0], pu[:, 1], pu[:, 2], mu[:, 0], mu[:, 1], mu[:, 2]
    pieces = [(~s2, (p0, m0, p2), (u0, w0, u2)), (s2, (p0, m0, m2), (u0, w0, w2)), (s2, (m0, p2, m2), (w0, u2, w2)),
              (~s1, (m0, p1, p2), (w0, u1, u2)), (s1, (m0, p1, m1), (w0, u1, w1)), (s1, (m0, m1, p2), (w0, w1, u2))]
    keep = n_split == 0
    out_t = [tris[keep]] + [np.stack([a[mask] for a in ids], axis=1) for mask, ids, _ in pieces]
    out_uv = [uvs[keep]] + [np.stack([a[mask] for a in uv], axis=1) for mask, _, uv in pieces]
    src = [np.flatnonzero(keep)] + [t[mask] for mask, _, _ in pieces]
    return np.concatenate(out_t), np.concatenate(out_uv), np.concatenate(src)
