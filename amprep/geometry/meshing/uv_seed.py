"""Interior points for meshing a curved face from scratch, sized by its curvature: a chord of (u,v) step (a, b)
deviates from the surface by ≈ |L a² + 2M ab + N b²| / 8 (L, M, N: the second fundamental form in (u,v)), so the
face's (u,v) box is cut into cells whose sides and diagonals keep that under the target, and the cells' corners
are the points. Delaunay in plain metric-scaled (u,v) joins such points across rows where the cells are long in
one direction, so the points come with the space to triangulate them in: (u,v) stretched to make the typical cell
square, the cells no longer than twice their width there."""

from __future__ import annotations

import weakref
from functools import lru_cache

import numpy as np
from scipy.spatial import cKDTree

from amprep.geometry.cad.surfaces import Surface
from amprep.geometry.core.progress import checkpoint, within_budget
from amprep.geometry.core.vectors import cross
from amprep.geometry.measure.chordal import barycentric_grid
from amprep.geometry.meshing.uv_cdt import inside_loops, surface_speeds

#: a cell that needs at most this many parts per direction is cut into them; one that needs more into about
#: their square root, its children then judged at their own centres
EXACT_SPLIT = 16
#: a cell needing up to this much more than a whole number of parts gets that number (refinement mends the few
#: triangles over): a full extra part would cut the error to well under the target (≈ 2× the points); the quality
#: mesher keeps it only for whether a cell is cut at all (a face of even curvature needs the same fraction over in
#: every cell, so all its triangles would come out over and refinement would multiply them)
SLACK = 0.1
MAX_SPLIT = 64
MAX_LEVELS = 16
#: the seeding gives up (None) past this many cells: the caller meshes without seeds and refines
MAX_CELLS = 4_000_000
#: cells at most this many times longer than wide in the triangulation space
MAX_ASPECT = 2.0
#: the quality mesher's cells: at most this many times longer than wide on the surface
QUALITY_ASPECT = 2.0
#: corners nearer the boundary than this × the cell's shorter side are dropped (no slivers along the boundary)
KEEP_OFF = 0.25
#: the quality mesher's corners nearer each other than this × the smaller of their cells' shorter sides are one (cells
#: cut differently meet along a side: their corners there interleave, and a near pair makes needles)
SEED_APART = 0.5
#: the nearest corners looked at for that (two grids meeting along a line put at most a few within half a cell)
SEED_NEIGHBOURS = 6
#: the boundary is sampled in at most this many points to find how near it the corners lie
MAX_BOUNDARY_SAMPLES = 200_000
#: a face with no single scale (curvature_seeds' `local`): the surface's speeds are taken as at least this × their
#: median, and its boundary is followed in space through this many pieces per side
LOCAL_FLOOR = 1 / 16
LOOP_PARTS = 8
#: second derivatives by central differences with this step × the face's (u,v) extent
DIFF_STEP = 1e-4
#: a pole's line in (u,v) gets a row of points this × the boundary segments leaving it off, spaced alike, and no other
#: point within POLE_CLEAR × that distance of it
POLE_ROW = 0.8
POLE_CLEAR = 1.5
#: a surface's typical speeds (median_speeds) are the median over this many² points
SPEED_GRID = 5

_OFFSETS = np.array([[0, 0], [1, 0], [-1, 0], [0, 1], [0, -1], [1, 1], [1, -1], [-1, 1], [-1, -1]], float)
_CORNERS = np.array([[-1, -1], [1, -1], [-1, 1], [1, 1]], float) * 0.5


def _forms(surface: Surface, uv: np.ndarray, step: np.ndarray) -> tuple[np.ndarray, ...]:
    """(S_u, S_v, n̂ (n, 3), |n| (n,), L, M, N (n,)) at uv (n, 2) by central differences with steps (2,) or (n, 2):
    n = (S(u + h) − S(u − h)) × (S(v + h) − S(v − h)) (n̂ = 0 where |n| = 0), L, M, N = n̂·S_uu, n̂·S_uv, n̂·S_vv."""
    step = np.broadcast_to(np.asarray(step, float), uv.shape)
    hu, hv = step[:, :1], step[:, 1:]
    p = surface.evaluate((uv[:, None, :] + _OFFSETS[None] * step[:, None, :]).reshape(-1, 2)).reshape(len(uv), 9, 3)
    normal = cross(p[:, 1] - p[:, 2], p[:, 3] - p[:, 4])
    length = np.linalg.norm(normal, axis=1)
    normal /= np.where(length > 0, length, 1.0)[:, None]
    s_uu = (p[:, 1] - 2 * p[:, 0] + p[:, 2]) / hu**2
    s_vv = (p[:, 3] - 2 * p[:, 0] + p[:, 4]) / hv**2
    s_uv = (p[:, 5] - p[:, 6] - p[:, 7] + p[:, 8]) / (4 * hu * hv)
    L, M, N = (np.einsum("ij,ij->i", normal, d) for d in (s_uu, s_uv, s_vv))
    return (p[:, 1] - p[:, 2]) / (2 * hu), (p[:, 3] - p[:, 4]) / (2 * hv), normal, length, L, M, N


def second_form(surface: Surface, uv: np.ndarray, step: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(L, M, N) each (n,): n·S_uu, n·S_uv, n·S_vv at uv (n, 2) by central differences with steps (2,) (0 where
    the normal is undefined, as at a pole)."""
    return tuple(np.nan_to_num(x) for x in _forms(surface, uv, step)[4:])  # type: ignore[return-value]


def _quadratic_terms(p: np.ndarray) -> np.ndarray:
    """(3, n) ½x_a², x_a·x_c, ½x_c² at points p (n, 2)."""
    return np.stack([p[:, 0] ** 2 / 2, p[:, 0] * p[:, 1], p[:, 1] ** 2 / 2])


@lru_cache(maxsize=8)
def _reference_terms(apex: float, order: int = 6) -> np.ndarray:
    """(3, 2k) the interpolation error of ½x_a², x_a·x_c, ½x_c² at the order-k barycentric grid (k points,
    measure.chordal.barycentric_grid) of the triangles (−½, 0), (½, 0), (0, ±apex) (a unit segment along a, its apex
    across it on either side)."""
    lam = barycentric_grid(order)
    out = []
    for side in (1.0, -1.0):
        corners = np.array([[-0.5, 0.0], [0.5, 0.0], [0.0, side * apex]])
        out.append(_quadratic_terms(corners) @ lam.T - _quadratic_terms(lam @ corners))
    terms = np.concatenate(out, axis=1)
    terms.flags.writeable = False
    return terms


def standing_error(surface: Surface, uv: np.ndarray, step: np.ndarray, floor: np.ndarray, along: np.ndarray,
                   apex: float) -> np.ndarray:
    """(n,) the chordal error (mm per mm²) of a triangle standing on a unit segment along `along` (n, 3) at uv
    (n, 2), its apex `apex` across it, on either side: the largest |Σλᵢ q(Pᵢ) − q(Σλᵢ Pᵢ)| over the order-6 grid,
    q the surface's second form q(x) = ½ xᵀ H x in the tangent frame (a along the segment, c = n̂ × a; H from
    II(d) = L du² + 2M du dv + N dv², (du, dv) solving the first form for d); a segment s long gives s² times it.
    Both forms by central differences with steps (n, 2) (a secant curvature at that scale: a fold far smaller than
    it is not seen), E and G at least floor² speeds ((2,) or (n, 2); where a parametrisation's speed vanishes along
    a side the ratio of the two forms is noise); 0 where the tangents are parallel (a pole)."""
    su, sv, normal, size, L, M, N = _forms(surface, uv, step)
    floor = np.broadcast_to(np.asarray(floor, float), uv.shape)
    E, F, G = (su * su).sum(1) + floor[:, 0] ** 2, (su * sv).sum(1), (sv * sv).sum(1) + floor[:, 1] ** 2
    W = E * G - F * F
    ok = (W > 1e-12 * E * G) & (size > 0)
    W = np.where(ok, W, 1.0)

    def second(d: np.ndarray) -> np.ndarray:
        x, y = np.einsum("ij,ij->i", su, d), np.einsum("ij,ij->i", sv, d)
        du, dv = (G * x - F * y) / W, (E * y - F * x) / W
        return L * du * du + 2 * M * du * dv + N * dv * dv

    a = along - np.einsum("ij,ij->i", along, normal)[:, None] * normal
    a /= np.maximum(np.linalg.norm(a, axis=1, keepdims=True), 1e-300)
    c = cross(normal, a)
    h_aa, h_cc, h_ac = second(a), second(c), (second(a + c) - second(a - c)) / 4
    error = np.stack([h_aa, h_ac, h_cc], axis=1) @ _reference_terms(apex)
    return np.where(ok, np.abs(error).max(axis=1), 0.0)


def _ranks(counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(owner, rank) each (Σ counts,): item i of `counts` (n,) repeated counts[i] times, and 0 … counts[i] − 1."""
    owner = np.repeat(np.arange(len(counts)), counts)
    return owner, np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)


def split_cells(centers: np.ndarray, sizes: np.ndarray, ku: np.ndarray, kv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cells (centers (n, 2), sizes (n, 2)) each cut into ku × kv (n,) equal cells: (centers, sizes) (Σ ku·kv, 2)."""
    parent, j = _ranks(ku * kv)
    k = np.stack([ku[parent], kv[parent]], axis=1)
    child = sizes[parent] / k
    index = np.stack([j % k[:, 0], j // k[:, 0]], axis=1)
    return centers[parent] - sizes[parent] / 2 + child * (index + 0.5), child


def _split_count(parts: np.ndarray, leaf_slack: bool = False) -> np.ndarray:
    """(n,) int cuts of a cell that needs `parts` (n,) parts: all of them up to EXACT_SPLIT (SLACK off them, with
    `leaf_slack` only where fewer than 2 are needed), else about their square root (the children, judged at their
    own centres, cut again), at most MAX_SPLIT."""
    k = np.where(parts < 2, np.ceil(parts - SLACK), np.ceil(parts)) if leaf_slack else np.ceil(parts - SLACK)
    k = np.where(k > EXACT_SPLIT, np.ceil(np.sqrt(k)), k)
    return np.clip(k, 1, MAX_SPLIT).astype(np.int64)


def polygon_area(poly: np.ndarray) -> float:
    """Signed area of a closed polygon (n, 2) by the shoelace formula, counter-clockwise positive."""
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def size_cells(surface: Surface, b_uv: np.ndarray, target: float, share: float = 1.0,
               leaf_slack: bool = False) -> tuple[np.ndarray, np.ndarray] | None:
    """Leaf cells (centers (n, 2), sizes (n, 2)) of the boundary's (u,v) box cut until, by the second form at each
    cell's centre, the deviation of its sides (|L| a²/8, |N| b²/8) and diagonals (|L a² ± 2M ab + N b²|/8) is at
    most `target`; None past MAX_CELLS. `share` of the cells (the part of the box the face covers) is held to the
    triangle budget (core.progress.within_budget), two triangles a cell; `leaf_slack`: _split_count's."""
    lo, hi = b_uv.min(axis=0), b_uv.max(axis=0)
    span = np.maximum(hi - lo, 1e-12)
    step = DIFF_STEP * span
    centers, sizes = ((lo + hi) / 2)[None], span[None].copy()
    leaf_c, leaf_s = [], []
    bound = 8 * target
    for _ in range(MAX_LEVELS):
        checkpoint()
        L, M, N = second_form(surface, centers, step)
        du, dv = sizes[:, 0], sizes[:, 1]
        with np.errstate(divide="ignore"):
            a = np.minimum(np.sqrt(bound / np.abs(L)), du)  # the longest sides each direction allows
            b = np.minimum(np.sqrt(bound / np.abs(N)), dv)
        diagonal = np.maximum(np.abs(L * a * a + 2 * M * a * b + N * b * b), np.abs(L * a * a - 2 * M * a * b + N * b * b))
        shrink = np.sqrt(np.minimum(bound / np.maximum(diagonal, 1e-300), 1.0))
        ku, kv = _split_count(du / (a * shrink), leaf_slack), _split_count(dv / (b * shrink), leaf_slack)
        leaf = (ku == 1) & (kv == 1)
        leaf_c.append(centers[leaf])
        leaf_s.append(sizes[leaf])
        centers, sizes, ku, kv = centers[~leaf], sizes[~leaf], ku[~leaf], kv[~leaf]
        if not len(centers):
            break
        cells = int((ku * kv).sum()) + sum(map(len, leaf_c))
        within_budget(int(2 * cells * share))
        if cells > MAX_CELLS:
            return None
        centers, sizes = split_cells(centers, sizes, ku, kv)
    leaf_c.append(centers)  # cells still over after MAX_LEVELS: refinement finishes them
    leaf_s.append(sizes)
    return np.concatenate(leaf_c), np.concatenate(leaf_s)


def _off_boundary(points: np.ndarray, shorter: np.ndarray, loops: list[np.ndarray], by_segment: bool = False,
                  pieces: int = 1) -> np.ndarray:
    """(n,) bool: points (n, d) farther than KEEP_OFF × shorter (n,) from every boundary polygon (closed, (m, d)),
    all in one space, and with `by_segment` farther than KEEP_OFF × the length of the boundary segment nearest them
    (a point near a long segment would make a sliver with it; `pieces`: each boundary segment was given as this many;
    a run of zero-length segments, a pole, takes the longer of the segments either side of it); the polygons are
    sampled at a quarter of the smallest such distance, in at most MAX_BOUNDARY_SAMPLES points (a cell far smaller
    than the rest then keeps off by a little more)."""
    perimeter = sum(float(np.linalg.norm(np.roll(a, -1, axis=0) - a, axis=1).sum()) for a in loops)
    spacing = max(KEEP_OFF * float(shorter.min()) / 2, perimeter / MAX_BOUNDARY_SAMPLES, 1e-12)
    samples, lengths = [], []
    for a in loops:
        b = np.roll(a, -1, axis=0)
        length = np.linalg.norm(b - a, axis=1)
        if by_segment:
            length = _through_points(length)
        k = np.maximum(np.ceil(length / spacing).astype(np.int64), 1)
        seg, j = _ranks(k)
        t = j / k[seg]
        samples.append(a[seg] + t[:, None] * (b - a)[seg])
        lengths.append(length[seg])
    seg_length = np.concatenate(lengths) * pieces if by_segment else np.zeros(sum(map(len, lengths)))
    reach = KEEP_OFF * shorter + spacing
    # bounded: a point far inside (most of them) costs a walk through the whole tree otherwise (inf: beyond)
    bound = KEEP_OFF * max(float(shorter.max()), float(seg_length.max())) + spacing
    distance, nearest = cKDTree(np.concatenate(samples)).query(points, distance_upper_bound=bound * 1.01)
    near_length = np.where(nearest < len(seg_length), seg_length[np.minimum(nearest, len(seg_length) - 1)], 0.0)
    return distance > np.maximum(reach, KEEP_OFF * near_length)


def curvature_seeds(surface: Surface, loops: list[np.ndarray], target: float, length_scale: np.ndarray,
                    true_metric: bool = False, local: bool = False) -> tuple[np.ndarray, np.ndarray] | None:
    """(points (k, 2) interior (u,v) seeds, scale (2,) of the (u,v) space to triangulate them in) for a face with
    boundary loops (closed (u,v) polygons (m, 2)), chords within `target`; `length_scale` (2,): metric_scale's
    (u,v) → mm. With `true_metric` (the quality mesher) the cells are cut near square in mm and triangulated in mm,
    for triangles near-right-angled on the surface rather than in a stretched space (more of them on a face
    curved one way, as a cylinder); with `local` too, each cell is judged square by the surface's own |S_u|, |S_v|
    at its centre (a face with no single scale to its lengths). None when the face needs more cells than MAX_CELLS
    or its box is degenerate."""
    b_uv = np.concatenate(loops)
    if (np.ptp(b_uv, axis=0) * length_scale <= 1e-9).any():
        return None
    box = float(np.prod(np.ptp(b_uv, axis=0)))
    share = min(abs(sum(polygon_area(lp) for lp in loops)) / box, 1.0) if box > 0 else 1.0
    cells = size_cells(surface, b_uv, target, share, leaf_slack=true_metric)
    if cells is None:
        return None
    centers, sizes = cells
    typical = np.median(sizes * length_scale, axis=0)
    ratio = 1.0 if true_metric else np.sqrt(typical[1] / typical[0])
    scale = length_scale * np.array([ratio, 1 / ratio])
    speeds = _local_speeds(surface, centers, b_uv) if local else scale
    aspect = QUALITY_ASPECT if true_metric else MAX_ASPECT
    side = np.maximum(sizes * speeds, target)  # no cell cut under the tolerance: a sliver face's width is no size
    ku = np.clip(np.ceil(side[:, 0] / (aspect * side[:, 1]) - SLACK), 1, MAX_CELLS).astype(np.int64)
    kv = np.clip(np.ceil(side[:, 1] / (aspect * side[:, 0]) - SLACK), 1, MAX_CELLS).astype(np.int64)
    if (ku * kv).sum() > MAX_CELLS:
        return None
    if local:
        speeds = np.repeat(speeds, ku * kv, axis=0)
    centers, sizes = split_cells(centers, sizes, ku, kv)
    corners = (centers[:, None] + _CORNERS[None] * sizes[:, None]).reshape(-1, 2)
    shorter = np.repeat(np.maximum(sizes * speeds, target).min(axis=1), 4)
    lo, span = b_uv.min(axis=0), np.maximum(np.ptp(b_uv, axis=0), 1e-12)
    key = np.round((corners - lo) / span * 2**30).astype(np.int64)  # cells share corners: one point each
    _, first = np.unique(key[:, 0] * (2**31 + 1) + key[:, 1], return_index=True)
    corners, shorter, cell = corners[first], shorter[first], np.repeat(sizes, 4, axis=0)[first]
    if local:  # how near the boundary a corner is: in space, as no one scale of (u,v) tells
        at = surface.evaluate(corners)
        keep = _off_boundary(at, shorter, [surface.evaluate(lp) for lp in _dense(loops)], by_segment=True,
                             pieces=LOOP_PARTS)
    else:
        at = corners * scale
        keep = _off_boundary(at, shorter, [lp * scale for lp in loops])
    if true_metric:  # judged by the lengths at the corner itself: toward a pole or apex a cell narrows to a point
        near = np.maximum(cell * _local_speeds(surface, corners, b_uv), target).min(axis=1) if local else shorter
        keep &= _apart_from_earlier(at, near)
    return corners[keep], scale


def _apart_from_earlier(points: np.ndarray, shorter: np.ndarray) -> np.ndarray:
    """(n,) bool: False for a point (n, d) nearer than SEED_APART × the smaller of the two shorter (n,) to an earlier one
    among its SEED_NEIGHBOURS nearest."""
    k = min(SEED_NEIGHBOURS + 1, len(points))
    if k < 2:
        return np.ones(len(points), bool)
    distance, nearest = cKDTree(points).query(points, k=k)
    nearest = np.minimum(nearest, len(points) - 1)  # a missing neighbour (k over n) comes as n, at inf distance
    own = np.arange(len(points))[:, None]
    close = (distance < SEED_APART * np.minimum(shorter[:, None], shorter[nearest])) & (nearest < own)
    return ~close.any(axis=1)


def _through_points(length: np.ndarray) -> np.ndarray:
    """(m,) a closed polygon's side lengths with each run of zeros (sides that are one point in space: a pole) set to
    the longer of the nonzero sides before and after it."""
    nonzero = length > 0
    if nonzero.all() or not nonzero.any():
        return length
    idx = np.arange(len(length))
    last = np.maximum.accumulate(np.where(nonzero, idx, -1))
    before = np.where(last >= 0, length[np.maximum(last, 0)], length[np.flatnonzero(nonzero)[-1]])
    nxt = np.minimum.accumulate(np.where(nonzero, idx, len(length))[::-1])[::-1]
    after = np.where(nxt < len(length), length[np.minimum(nxt, len(length) - 1)], length[np.flatnonzero(nonzero)[0]])
    return np.where(nonzero, length, np.maximum(before, after))


def _local_speeds(surface: Surface, centers: np.ndarray, b_uv: np.ndarray) -> np.ndarray:
    """(n, 2) |S_u|, |S_v| at the cells' centers (n, 2), each at least LOCAL_FLOOR × its median (where a
    parametrisation degenerates along a side, |S_u| → 0 would cut its cells without end)."""
    speeds = np.stack(surface_speeds(surface, centers, b_uv), axis=1)
    return np.maximum(speeds, LOCAL_FLOOR * np.median(speeds, axis=0))


def _dense(loops: list[np.ndarray]) -> list[np.ndarray]:
    """The loops (closed (u,v) polygons (m, 2)) with each side cut into LOOP_PARTS pieces, so that its image on the
    surface, not straight in space, is followed."""
    t = np.arange(LOOP_PARTS) / LOOP_PARTS
    return [(lp[:, None] + t[None, :, None] * (np.roll(lp, -1, axis=0) - lp)[:, None]).reshape(-1, 2) for lp in loops]


def clear_poles(seeds: np.ndarray, runs: list[np.ndarray], scale: np.ndarray, loops: list[np.ndarray]) -> np.ndarray:
    """(k', 2) interior (u,v) points: seeds (k, 2) with those near a pole's line (runs: face_mesher.pole_runs', the
    line's nodes with the node before and after) dropped and a row along it added, in the triangulation space (u,v) ×
    scale (2,): the row D = POLE_ROW × the mean of the two boundary segments leaving the pole off the line, its points D
    apart, no seed within POLE_CLEAR × D. Between two rows of points any triangulation joins each point to one run of
    the other's, so no point reaches pole nodes on either side of another (loops: the face's closed (u,v) polygons)."""
    scaled = [lp * scale for lp in loops]
    pts, rows = seeds * scale, []
    for run in runs:
        r = run * scale
        a, b = r[1], r[-2]
        length = float(np.linalg.norm(b - a))
        d = POLE_ROW * 0.5 * float(np.linalg.norm(r[1] - r[0]) + np.linalg.norm(r[-1] - r[-2]))
        if length <= 0 or d <= 0:
            continue
        t = (b - a) / length
        w = np.clip((pts - a) @ t / length, 0, 1)
        pts = pts[np.linalg.norm(pts - a - w[:, None] * length * t, axis=1) > POLE_CLEAR * d]
        normal = np.array([-t[1], t[0]])
        if not inside_loops(((a + b) / 2 + normal * d / 2)[None], scaled)[0]:
            normal = -normal
        m = max(1, int(round(length / d)))
        row = a + np.outer((np.arange(m) + 0.5) / m, b - a) + normal * d
        row = row[inside_loops(row, scaled)]
        rows.append(row[_off_boundary(row, np.full(len(row), 2 * d), scaled)] if len(row) else row)
    return np.concatenate([pts, *rows]) / scale


#: median_speeds over the bounds of each surface that has them, a function of the surface alone: made once per surface
BOUNDED_MEDIANS: weakref.WeakKeyDictionary[Surface, np.ndarray] = weakref.WeakKeyDictionary()


def median_speeds(surface: Surface, box: tuple[float, float, float, float] | None = None) -> np.ndarray:
    """(2,) the median |S_u|, |S_v| over a SPEED_GRID² grid of the (u,v) box (u0, u1, v0, v1); with no box, over the
    surface's bounds, made once per surface (BOUNDED_MEDIANS)."""
    if box is None:
        known = BOUNDED_MEDIANS.get(surface)
        if known is None:
            known = BOUNDED_MEDIANS[surface] = median_speeds(surface, surface.bounds)
        return known
    g = np.linspace(0.05, 0.95, SPEED_GRID)
    u, v = np.meshgrid(box[0] + g * (box[1] - box[0]), box[2] + g * (box[3] - box[2]))
    grid = np.stack([u.ravel(), v.ravel()], axis=1)
    return np.median(np.stack(surface_speeds(surface, grid, grid), axis=1), axis=0)
