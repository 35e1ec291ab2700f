"""Bring a meshed face within tolerance by re-triangulating only the neighbourhood of the triangles that exceed it
(constrained Delaunay in scaled (u,v), new points inserted), keeping the rest of the mesh and every boundary node:
each round costs what it adds, not the face's size. Mends OCCT's mesh of a face and refines the fallback's; flat
triangles next to an apex are flipped away; the quality mesher's curved faces are finished by flips and smoothing
measured on the surface."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from amprep.errors import AmprepError
from amprep.geometry.cad.surfaces import Surface, project_points
from amprep.geometry.core.edges import distinct_corners, edge_codes, edge_incidence
from amprep.geometry.core.progress import checkpoint, within_budget
from amprep.geometry.core.vectors import cross, dot, norms, turn
from amprep.geometry.measure.angles import flip_candidates, min_angles_at, unit_normals_at
from amprep.geometry.measure.chordal import exact_over, triangle_chordal_error
from amprep.geometry.meshing.occt_read import FacePatch
from amprep.geometry.meshing.uv_cdt import (
    MAX_ROUNDS,
    apart,
    in_sorted,
    insertion_points,
    metric_scale,
    min_spacing,
    recall_errors,
    surface_tangents,
    triangle_codes,
    triangulate_pslg,
)

#: a re-triangulated region must cover the (u,v) area it replaced to this relative precision
AREA_RTOL = 1e-9


def _signed_area2(pts: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """(t,) twice the signed (u,v) area of each triangle (> 0: counter-clockwise)."""
    return turn(pts[tris[:, 0]], pts[tris[:, 1]], pts[tris[:, 2]])


def _retriangulate(pts: np.ndarray, region: np.ndarray, outside_seeds: np.ndarray,
                   new: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """CDT of a region of triangles (r, 3) over pts (n, 2) with `new` (k, 2) points inside it, its boundary edges
    kept as segments; returns (nodes (m,) global ids of its old nodes, triangles (r + 2k, 3) over
    [pts[nodes]; new]) counter-clockwise, or None when Triangle's result does not tile the region exactly."""
    nodes, local = np.unique(region, return_inverse=True)
    local = local.reshape(region.shape)
    code = edge_codes(local, len(nodes) + 1).ravel()
    uniq, first, count = np.unique(code, return_index=True, return_counts=True)
    once = first[count == 1]
    a, b = local.ravel(), np.roll(local, -1, axis=1).ravel()
    segments = np.stack([a[once], b[once]], axis=1)
    vertices = np.concatenate([pts[nodes], new])
    try:
        tris = triangulate_pslg(vertices, segments, outside_seeds)
    except AmprepError:
        return None
    if len(tris) != len(region) + 2 * len(new):
        return None
    area_old = np.abs(_signed_area2(pts, region)).sum()
    area_new = _signed_area2(vertices, tris)
    if (area_new <= 0).any() or abs(area_new.sum() - area_old) > AREA_RTOL * area_old:
        return None
    return nodes, tris


def refine_patch(patch: FacePatch, error: np.ndarray, surface: Surface, tolerance: float, order: int = 6,
                 rounds: int = MAX_ROUNDS, scale: np.ndarray | None = None) -> FacePatch | None:
    """The patch with every triangle whose chordal error `error` (t,) exceeds the tolerance replaced, with the
    triangles sharing a node with it, by a CDT of that region plus one point per such triangle (midpoint of its
    longest inner edge, else centroid), until none exceeds it; boundary nodes and all other triangles are kept
    (`error` of the result is set). None when a region cannot be re-triangulated (a fold in the face's (u,v)).
    Regions are re-triangulated in (u,v) · `scale` (2,), the space the patch was triangulated in (default:
    metric_scale's, where OCCT's meshes are near-Delaunay); elsewhere a region's re-triangulation flips its
    neighbours' diagonals and the bad triangles move instead of going. Triangles with a corner over the tolerance
    off the surface (corner_bound) are left as they are."""
    assert patch.uv is not None
    tris, err = patch.tris, np.asarray(error, float)
    length_scale = metric_scale(surface, patch.uv)
    scale = length_scale if scale is None else np.asarray(scale, float)
    spacing = min_spacing(tolerance, scale, length_scale)
    pts = patch.uv * scale
    xyz, uv = patch.nodes, patch.uv
    sign = 1.0 if _signed_area2(pts, tris).sum() >= 0 else -1.0
    codes, count = np.unique(edge_codes(tris, len(pts) + 1), return_counts=True)
    boundary_pairs = np.stack(np.divmod(codes[count == 1], len(pts) + 1), axis=1)  # the face's boundary: kept
    off = np.zeros(0)
    for _ in range(rounds):
        checkpoint()
        bad = err > tolerance
        bound, off = corner_bound(xyz, uv, tris, bad, surface, tolerance, off)
        bad[bound] = False  # no point inside brings them within
        if not bad.any():
            break
        base = len(pts) + 1
        boundary = boundary_pairs[:, 0] * base + boundary_pairs[:, 1]
        marked = np.zeros(len(pts), bool)
        marked[tris[bad]] = True
        in_region = marked[tris[:, 0]] | marked[tris[:, 1]] | marked[tris[:, 2]]
        region = tris[in_region]
        new = insertion_points(pts, tris[bad], boundary, base)
        new = apart(new, pts[np.unique(region)], spacing)
        if not len(new):
            break
        within_budget(len(tris) + 2 * len(new))
        # a hole seed in every kept triangle across an inner edge of the region's border: Triangle must not fill
        # what the region surrounds (candidates: kept triangles with two nodes in the region)
        in_nodes = np.zeros(len(pts), bool)
        in_nodes[region] = True
        a, b, c = in_nodes[tris[:, 0]], in_nodes[tris[:, 1]], in_nodes[tris[:, 2]]
        near = np.flatnonzero(~in_region & ((a & b) | (a & c) | (b & c)))  # two nodes or more in the region
        rim_codes = np.unique(edge_codes(region, base))
        rim_codes = rim_codes[~in_sorted(rim_codes, boundary)]
        rim = near[in_sorted(edge_codes(tris[near], base), rim_codes).any(axis=1)]
        seeds = pts[tris[rim]].mean(axis=1)
        done = _retriangulate(pts, region, seeds, new)
        if done is None:
            return None
        nodes, local = done
        ids = np.concatenate([nodes, len(pts) + np.arange(len(new))])
        fresh = ids[local]
        if sign < 0:
            fresh = fresh[:, [0, 2, 1]]
        pts = np.concatenate([pts, new])
        uv = np.concatenate([uv, new / scale])
        xyz = np.concatenate([xyz, surface.evaluate(uv[-len(new):])])
        seen, fresh_err = recall_errors(len(fresh), triangle_codes(fresh, len(pts)), triangle_codes(region, len(pts)),
                                        err[in_region])
        fresh_err[~seen] = triangle_chordal_error(xyz[fresh[~seen]], uv[fresh[~seen]], surface, order,
                                                  affine=surface.affine, stop=tolerance)
        tris = np.concatenate([tris[~in_region], fresh])
        err = np.concatenate([err[~in_region], fresh_err])
    k = len(pts) - len(patch.uv)
    err = exact_over(err, tolerance, xyz, uv, tris, surface, order)
    return replace(patch, nodes=xyz, uv=uv, tris=tris,
                   node_vertex=np.concatenate([patch.node_vertex, np.full(k, -1, np.int64)]),
                   node_edge=np.concatenate([patch.node_edge, np.full(k, -1, np.int64)]),
                   node_param=np.concatenate([patch.node_param, np.full(k, np.nan)]),
                   meshed_by="refined" if patch.meshed_by == "occt" else patch.meshed_by, error=err)


def corner_bound(nodes: np.ndarray, uv: np.ndarray, tris: np.ndarray, over: np.ndarray, surface: Surface,
                 tolerance: float, known: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """((k,) ids of the triangles `over` (t,) bool of tris (t, 3) on nodes (n, 3) with (u,v) (n, 2) that have a corner
    off the surface by more than the tolerance, (n,) each node's distance from the face's surface (NaN: not needed)):
    the distance by surfaces.project_points from the node's (u,v), in the face's bounds, taken from `known` (m ≤ n,)
    (an earlier call's, NaN where not measured) where it holds it. Such a corner is a boundary node off its face by a
    B-rep gap over the tolerance: the chordal measure counts the corners, so no point inserted inside brings them
    within it. Refined regardless, each such node's fan grew round after round (CTC-02 at 0.001 mm: one face's 2,222
    triangles over became 20,311 of 590,628 after 40 rounds). A corner on the surface whose (u,v) is off (its pcurve
    a way from its 3D curve along the surface) is refined: as the triangles round it shrink their planes take in its
    offset and they come within (OCCT's hammer.brep at 0.1 mm: judged by its offset from S(u,v) along the triangles'
    normals, four faces were left over, their edges split to the gap, 24 % more triangles)."""
    off = np.full(len(nodes), np.nan)
    if known is not None and len(known):
        off[:len(known)] = known
    idx = np.flatnonzero(over)
    if not len(idx):
        return idx, off
    node = np.unique(tris[idx])
    node = node[np.isnan(off[node])]
    if len(node):
        off[node] = project_points(surface, nodes[node], uv[node], within=True)[1]
    return idx[(off[tris[idx]] > tolerance).any(axis=1)], off


#: a triangle is a needle when its area ≤ this × (longest edge)²
NEEDLE_REL_AREA = 1e-10


def flat_triangles(patch: FacePatch, min_area: float = 0.0, rel_eps: float = NEEDLE_REL_AREA) -> np.ndarray:
    """(t,) bool: triangles the weld keeps (three distinct nodes, not two on one B-rep vertex) whose area is
    ≤ rel_eps · (longest edge)² (a needle) or ≤ min_area (thinner than the output's degenerate check allows)."""
    c = patch.nodes[patch.tris]
    t = patch.tris
    v = patch.node_vertex[t]
    same_vertex = (((v[:, 0] == v[:, 1]) & (v[:, 0] >= 0)) | ((v[:, 1] == v[:, 2]) & (v[:, 1] >= 0))
                   | ((v[:, 0] == v[:, 2]) & (v[:, 0] >= 0)))
    distinct = distinct_corners(t) & ~same_vertex
    e1, e2 = c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]
    normal = cross(e1, e2)
    area2_sq = np.einsum("ij,ij->i", normal, normal)  # (2·area)², compared squared: no square roots
    e3 = e2 - e1
    longest_sq = np.maximum(np.maximum(np.einsum("ij,ij->i", e1, e1), np.einsum("ij,ij->i", e2, e2)),
                            np.einsum("ij,ij->i", e3, e3))
    thin = (area2_sq <= (2 * rel_eps) ** 2 * longest_sq**2) | (area2_sq <= (2 * min_area) ** 2)
    return distinct & thin & (longest_sq > 0)


def flip_flat_triangles(patch: FacePatch, surface: Surface, tolerance: float, order: int = 6,
                        min_area: float = 0.0) -> FacePatch:
    """The patch with each flat triangle (flat_triangles) swapped with its neighbour across its longest edge for the
    other diagonal of their quad, where both new triangles keep the patch's (u,v) orientation, are not flat and are
    within the tolerance: next to a pole or apex, where a line of (u,v) is one point, a Delaunay triangulation in
    (u,v) joins three points that are collinear in space. Flat triangles with no such flip are left (the caller
    sees them with flat_triangles)."""
    flat = np.flatnonzero(flat_triangles(patch, min_area))
    if not len(flat) or patch.uv is None or patch.error is None:
        return patch
    tris, err = patch.tris.copy(), patch.error.copy()
    sign = 1.0 if _signed_area2(patch.uv, tris).sum() >= 0 else -1.0
    for t in flat:
        c = patch.nodes[tris[t]]
        k = int(np.argmax(np.linalg.norm(c - np.roll(c, -1, axis=0), axis=1)))  # side k joins corners k, k+1
        a, b, opposite = tris[t, k], tris[t, (k + 1) % 3], tris[t, (k + 2) % 3]
        across = np.flatnonzero(((tris == b) | (tris == a)).sum(axis=1) == 2)
        across = across[across != t]
        if len(across) != 1:
            continue  # the longest side is on the face's boundary: no flip
        n = across[0]
        d = int(tris[n][(tris[n] != a) & (tris[n] != b)][0])
        new = np.array([[a, d, opposite], [d, b, opposite]])
        trial = replace(patch, tris=new, error=None)
        if (sign * _signed_area2(patch.uv, new) <= 0).any() or flat_triangles(trial, min_area).any():
            continue
        e = triangle_chordal_error(patch.nodes[new], patch.uv[new], surface, order, affine=surface.affine)
        if e.max() > tolerance:
            continue
        tris[t], tris[n] = new
        err[t], err[n] = e
    return replace(patch, tris=tris, error=err)


#: the quality mesher's flips: passes, and the least gain (radians) of the pair's smallest angle that a flip needs
FLIP_PASSES = 8
FLIP_GAIN = 1e-3
#: two triangles sharing a side are folded when their normals' cosine is under this (over 120° apart: a cylinder's
#: neighbours are that far apart only on a radius under twice the tolerance); triangles right in (u,v) fold in space
#: where the parametrisation shears across them (the DTMB hull: 97 such pairs at 0.34 mm, 39 crossing pairs)
FOLD_COS = -0.5
#: rounds of smooth_on_surface at most, and the share of the way to its neighbours' mean a node moves in one
SMOOTH_ROUNDS = 4
SMOOTH_RELAX = 0.8
#: the rounds stop once one raises the face's mean smallest angle by less than this (radians, 0.6°, a mean angle
#: regularity of 0.01): on the DTMB hull the rounds gain 0.098, 0.016, 0.005, 0.003 at 0.34 mm, 0.061, 0.009, ... at
#: 0.01 mm, where the last two rounds took 3 s of 11
SMOOTH_GAIN = np.pi / 3 * 0.01
#: and at most this many sets of nodes that share no side, each moved at once, per round
SMOOTH_SETS = 64
#: a node whose move is under this × its shortest side stays where it is, its star not measured (the DTMB hull at
#: 0.01 mm: 14 % less meshing time for a mean angle regularity 0.0004 lower; the tenth percentile of its moves is
#: 0.3–0.7 % of that side)
SMOOTH_MIN_MOVE = 0.05


def _shared_sides(tris: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t1, k1, t2, k2): triangle t1's side k1 (corners k1, k1+1) is triangle t2's side k2, for every shared side."""
    packed = _packed_sides(tris, n)
    if packed is not None:
        return _pairs(packed, 3 * len(tris))
    code = edge_codes(tris, n).ravel()
    order = np.argsort(code, kind="stable")
    return _consecutive(order, code[order])


def _packed_sides(tris: np.ndarray, n: int) -> np.ndarray | None:
    """(3t,) sorted code·3t + row of every side (row t·3 + k: side k of triangle t; code edge_codes'): the side table
    in one int64 sort; None where code·3t would overflow."""
    m = 3 * len(tris)
    if not m or n * n * m >= 2**62:
        return None
    return np.sort(edge_codes(tris, n).ravel() * m + np.arange(m))


def _pairs(packed: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """_shared_sides' (t1, k1, t2, k2) from _packed_sides' array (m = 3t)."""
    return _consecutive(packed % m, packed // m)


def _consecutive(order: np.ndarray, ordered: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t1, k1, t2, k2) of consecutive rows `order` (3t,) whose codes `ordered` (3t,), sorted, are equal."""
    pair = np.flatnonzero(ordered[1:] == ordered[:-1])
    first, second = order[pair], order[pair + 1]
    return first // 3, first % 3, second // 3, second % 3


def _repacked(packed: np.ndarray, tris: np.ndarray, changed: np.ndarray, n: int) -> np.ndarray:
    """_packed_sides of `tris` from the array of before `changed` (k,) triangles were rewritten: their rows' old entries
    dropped and their new ones merged in, in linear passes (no sort of the whole)."""
    m = 3 * len(tris)
    rows = (3 * changed[:, None] + np.arange(3)).ravel()
    stale = np.zeros(m, bool)
    stale[rows] = True
    kept = packed[~stale[packed % m]]
    fresh = np.sort(edge_codes(tris[changed], n).ravel() * m + rows)
    return np.insert(kept, np.searchsorted(kept, fresh), fresh)


def flip_for_angles(patch: FacePatch, surface: Surface, tolerance: float, order: int = 6,
                    angles: bool = True) -> FacePatch:
    """The quality mesher's finish of a curved face: shared sides flipped (Lawson, on the surface rather than in
    (u,v), where a single scale cannot make the two agree) wherever the two triangles' smallest angle in space
    grows by FLIP_GAIN, both keep their (u,v) orientation and both stay within the tolerance; each pass flips a set
    of sides no two of which share a triangle (the best claim on each), for FLIP_PASSES passes. A pair folded in
    space (FOLD_COS) is flipped first where that unfolds it, and no flip folds a pair; with `angles` False only
    folded pairs are flipped (any mesher's finish: unfold)."""
    if patch.uv is None or patch.error is None:
        return patch
    tris, err, xyz, uv = patch.tris.copy(), patch.error.copy(), patch.nodes, patch.uv
    sign = 1.0 if _signed_area2(uv, tris).sum() >= 0 else -1.0
    angle = min_angles_at(xyz, tris)
    normals = unit_normals_at(xyz, tris)
    active = np.ones(len(tris), bool)  # a pair of triangles neither of which changed has nothing new to offer
    packed = _packed_sides(tris, len(xyz))
    for _ in range(FLIP_PASSES):
        checkpoint()
        t1, k1, t2, k2 = _shared_sides(tris, len(xyz)) if packed is None else _pairs(packed, 3 * len(tris))
        look = active[t1] | active[t2]
        t1, k1, t2, k2 = t1[look], k1[look], t2[look], k2[look]
        f = flip_candidates(xyz, uv, tris, normals, t1, k1, t2, k2)
        gain = np.minimum(f.angle1, f.angle2) - np.minimum(angle[t1], angle[t2])
        # a pair folded against each other in space is unfolded first, whatever the angles; no flip folds a pair
        repair = (f.fold_old < FOLD_COS) & (f.fold_new > f.fold_old)
        gain = np.where(repair, np.pi + f.fold_new - f.fold_old, gain if angles else -1.0)
        ok = np.flatnonzero((gain > FLIP_GAIN) & (f.fold_new >= np.minimum(f.fold_old, FOLD_COS))
                            & (sign * f.area1 > 0) & (sign * f.area2 > 0))
        if not len(ok):
            break
        rank = np.empty(len(ok), np.int64)
        rank[np.argsort(-gain[ok], kind="stable")] = np.arange(len(ok))
        best = np.full(len(tris), len(ok), np.int64)
        np.minimum.at(best, t1[ok], rank)
        np.minimum.at(best, t2[ok], rank)
        pick = ok[(best[t1[ok]] == rank) & (best[t2[ok]] == rank)]
        both = np.concatenate([f.new1[pick], f.new2[pick]])
        e = triangle_chordal_error(xyz[both], uv[both], surface, order, affine=surface.affine, stop=tolerance)
        keep = (e[:len(pick)] <= tolerance) & (e[len(pick):] <= tolerance)
        if not keep.any():
            break
        p = pick[keep]
        tris[t1[p]], tris[t2[p]] = f.new1[p], f.new2[p]
        if packed is not None:
            packed = _repacked(packed, tris, np.concatenate([t1[p], t2[p]]), len(xyz))
        err[t1[p]], err[t2[p]] = e[:len(pick)][keep], e[len(pick):][keep]
        angle[t1[p]], angle[t2[p]] = f.angle1[p], f.angle2[p]
        normals[t1[p]], normals[t2[p]] = f.normal1[p], f.normal2[p]
        active[:] = False
        active[t1[p]] = active[t2[p]] = True
    return replace(patch, tris=tris, error=err)


def unfold(patch: FacePatch, surface: Surface, tolerance: float, order: int = 6) -> FacePatch:
    """The patch with its pairs of triangles folded against each other in space (FOLD_COS) flipped apart where a flip
    keeps the (u,v) orientation and the tolerance (flip_for_angles with angles off); unchanged when none is."""
    if patch.uv is None or patch.error is None or not len(patch.tris):
        return patch
    t1, _, t2, _ = _shared_sides(patch.tris, len(patch.nodes))
    n = unit_normals_at(patch.nodes, patch.tris)
    if not (dot(n[t1], n[t2]) < FOLD_COS).any():
        return patch
    return flip_for_angles(patch, surface, tolerance, order, angles=False)


def _ring_members(idx: np.ndarray, ring: tuple[np.ndarray, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(count (k,), owner (r,), pick (r,)): each node idx (k,)'s number of neighbours, and its neighbours (ring: _rings'
    (start (n+1,), neighbour) of each node) one per row, pick[j] a neighbour of node idx[owner[j]]."""
    start, neighbour = ring
    count = start[idx + 1] - start[idx]
    return count, np.repeat(np.arange(len(idx)), count), neighbour[_ranges(start[idx], start[idx + 1])]


def _toward_neighbours(surface: Surface, uv: np.ndarray, xyz: np.ndarray, idx: np.ndarray,
                       members: tuple[np.ndarray, ...], extent: np.ndarray) -> np.ndarray:
    """(k, 2) the (u,v) of nodes idx (k,) moved SMOOTH_RELAX of the way to the mean of their neighbours in space
    (members: _ring_members' of idx), the move d (3,) taken into (u,v) by least squares on the tangent plane: J δ = d
    with J = [S_u S_v] (uv_cdt.surface_tangents, steps from the (u,v) `extent` (m, 2)); a node where J is singular
    stays."""
    count, owner, pick = members
    total = np.stack([np.bincount(owner, xyz[pick, j], len(idx)) for j in range(3)], axis=1)
    su, sv = surface_tangents(surface, uv[idx], xyz[idx], extent)
    d = total / np.maximum(count, 1)[:, None] - xyz[idx]
    a11, a12, a22 = (su * su).sum(1), (su * sv).sum(1), (sv * sv).sum(1)
    b1, b2 = (su * d).sum(1), (sv * d).sum(1)
    det = a11 * a22 - a12 * a12
    ok = det > 1e-12 * np.maximum(a11 * a22, 1e-300)
    step = np.stack([a22 * b1 - a12 * b2, a11 * b2 - a12 * b1], 1) / np.where(ok, det, 1)[:, None]
    return uv[idx] + SMOOTH_RELAX * np.where(ok[:, None], step, 0.0)


def _shortest_side(xyz: np.ndarray, idx: np.ndarray, members: tuple[np.ndarray, ...]) -> np.ndarray:
    """(k,) the shortest side in space from each node idx (k,) to its neighbours (members: _ring_members' of idx)."""
    _, owner, pick = members
    shortest = np.full(len(idx), np.inf)
    np.minimum.at(shortest, owner, norms(xyz[pick] - xyz[idx][owner]))
    return shortest


def _rings(sides: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(start (n+1,), neighbour): node i's neighbours along sides (e, 2) are neighbour[start[i]:start[i+1]]."""
    a = np.concatenate([sides[:, 0], sides[:, 1]])
    b = np.concatenate([sides[:, 1], sides[:, 0]])
    order = np.argsort(a, kind="stable")
    return np.searchsorted(a[order], np.arange(n + 1)), b[order]


def _independent(candidates: np.ndarray, sides: np.ndarray, priority: np.ndarray) -> np.ndarray:
    """(n,) bool: the candidates (n,) of lower `priority` than every candidate neighbour along sides (e, 2): no two of
    them share a side, so no triangle holds two."""
    a, b = sides[:, 0], sides[:, 1]
    both = candidates[a] & candidates[b]
    blocked = np.zeros(len(candidates), bool)
    blocked[a[both & (priority[b] < priority[a])]] = True
    blocked[b[both & (priority[a] < priority[b])]] = True
    return candidates & ~blocked


def _ranges(start: np.ndarray, stop: np.ndarray) -> np.ndarray:
    """The integers of the ranges [start_i, stop_i) (k,) each, concatenated."""
    count = stop - start
    offset = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)
    return np.repeat(start, count) + offset


def smooth_on_surface(patch: FacePatch, surface: Surface, tolerance: float, order: int = 6) -> FacePatch:
    """The quality mesher's finish of a face with no single scale to its (u,v) lengths: up to SMOOTH_ROUNDS rounds
    (until one gains under SMOOTH_GAIN in the mean smallest angle) in which every interior node, in sets no two of
    which share a side (_independent), is moved toward its neighbours' mean in space (_toward_neighbours), unless that
    move is under SMOOTH_MIN_MOVE × its shortest side; a move is kept only where none of the node's triangles turns
    over in (u,v) or goes over the tolerance and their smallest angle in space does not fall. Each node's triangles
    hold no other moving node, so every decision is exact and final: no fold is made and every triangle stays within
    the tolerance."""
    if patch.uv is None or patch.error is None:
        return patch
    tris, uv, xyz, err = patch.tris, patch.uv.copy(), patch.nodes.copy(), patch.error.copy()
    free = (patch.node_vertex < 0) & (patch.node_edge < 0)
    if not free.any():
        return patch
    n = len(uv)
    sides = edge_incidence(tris).edges
    ring = _rings(sides, n)
    sign = np.sign(_signed_area2(uv, tris))
    angle = min_angles_at(xyz, tris)
    priority = (np.arange(n, dtype=np.uint64) * np.uint64(2654435761)) % np.uint64(2**32)  # a fixed scatter
    corner_order = np.argsort(tris.ravel(), kind="stable")  # each node's triangles, node by node
    first = np.searchsorted(tris.ravel()[corner_order], np.arange(n + 1))
    trial_uv, trial_xyz = uv.copy(), xyz.copy()  # the state with this set's movers moved; equal to it between sets
    held = np.zeros(len(tris), bool)
    for _ in range(SMOOTH_ROUNDS):
        before = angle.mean()
        candidates = free.copy()
        for _ in range(SMOOTH_SETS):
            checkpoint()
            movers = _independent(candidates, sides, priority)
            if not movers.any():
                break
            candidates &= ~movers
            idx = np.flatnonzero(movers)
            members = _ring_members(idx, ring)
            to_uv = _toward_neighbours(surface, uv, xyz, idx, members, patch.uv)
            to_xyz = surface.evaluate(to_uv)
            far = norms(to_xyz - xyz[idx]) >= SMOOTH_MIN_MOVE * _shortest_side(xyz, idx, members)
            movers[idx[~far]] = False  # a move this small gains nothing a measure of its star would pay for
            idx, to_uv, to_xyz = idx[far], to_uv[far], to_xyz[far]
            if not len(idx):
                continue
            trial_uv[idx], trial_xyz[idx] = to_uv, to_xyz
            held[corner_order[_ranges(first[idx], first[idx + 1])] // 3] = True  # triangles holding a mover
            star = np.flatnonzero(held)  # sorted, each once: np.unique's, without its hash of every corner
            held[star] = False
            t = tris[star]
            owner = t[np.arange(len(t)), movers[t].argmax(axis=1)]  # the one moving node of each
            new_angle = min_angles_at(trial_xyz, t)
            old_min, new_min = np.full(n, np.inf), np.full(n, np.inf)
            np.minimum.at(old_min, owner, angle[star])
            np.minimum.at(new_min, owner, new_angle)
            keep = movers & (new_min >= old_min)
            keep[owner[np.sign(_signed_area2(trial_uv, t)) != sign[star]]] = False
            new_err = err[star].copy()  # measured only where the move may still be kept
            check = np.flatnonzero(keep[owner])
            new_err[check] = triangle_chordal_error(trial_xyz[t[check]], trial_uv[t[check]], surface, order,
                                                    affine=surface.affine, stop=tolerance)
            keep[owner[new_err > tolerance]] = False
            uv[keep], xyz[keep] = trial_uv[keep], trial_xyz[keep]
            back = idx[~keep[idx]]
            trial_uv[back], trial_xyz[back] = uv[back], xyz[back]
            took = keep[owner]
            angle[star[took]], err[star[took]] = new_angle[took], new_err[took]
        if angle.mean() - before < SMOOTH_GAIN:
            break
    return replace(patch, nodes=xyz, uv=uv, error=err)
