"""Constrained Delaunay in a face's metric-scaled (u,v) and the point insertion the meshers share: Triangle called
safely, insertion points for triangles over tolerance, new points kept apart from old ones."""

from __future__ import annotations

import numpy as np
import triangle as tr
from scipy.spatial import ConvexHull, QhullError, cKDTree

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.cad.surfaces import Surface
from amprep.geometry.cad.wire_crossings import overlapping_boxes
from amprep.geometry.core.vectors import turn

MAX_ROUNDS = 40
#: points are inserted no closer than this × tolerance (in metric-scaled (u,v) ≈ mm) to another
MIN_SPACING = 0.01


def difference_step(uv: np.ndarray) -> float:
    """The forward-difference step of surface_speeds and surface_tangents: 1e-6 × the extent of uv (n, 2)."""
    return 1e-6 * max(float(np.ptp(uv[:, 0])), float(np.ptp(uv[:, 1])), 1e-9)


def surface_speeds(surface: Surface, sample: np.ndarray, uv: np.ndarray,
                   step: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(|∂S/∂u|, |∂S/∂v|) each (k,) at sample (k, 2), by forward differences of 1e-6 × the extent of uv (n, 2), or of
    `step` (k,), one per sample."""
    h = np.asarray(difference_step(uv) if step is None else step, float)
    p = surface.evaluate(sample)
    du = np.linalg.norm(surface.evaluate(sample + h[..., None] * [1.0, 0.0]) - p, axis=1) / h
    dv = np.linalg.norm(surface.evaluate(sample + h[..., None] * [0.0, 1.0]) - p, axis=1) / h
    return du, dv


def surface_tangents(surface: Surface, sample: np.ndarray, at: np.ndarray,
                     uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(∂S/∂u, ∂S/∂v) each (k, 3) at sample (k, 2) whose points S(sample) are `at` (k, 3), by the same forward
    differences as surface_speeds."""
    h = difference_step(uv)
    return (surface.evaluate(sample + [h, 0]) - at) / h, (surface.evaluate(sample + [0, h]) - at) / h


def metric_scale(surface: Surface, uv: np.ndarray) -> np.ndarray:
    """(2,) mean |∂S/∂u|, |∂S/∂v| over the boundary points, so that CDT in scaled (u,v) sees near-true lengths."""
    du, dv = surface_speeds(surface, uv[:: max(1, len(uv) // 64)], uv)
    s = np.array([du.mean(), dv.mean()])
    return np.where(s > 1e-12, s, 1.0)


def metric_uniform(surface: Surface, uv: np.ndarray, spread: float = 4.0) -> bool:
    """True when |∂S/∂u| and |∂S/∂v| each vary by at most `spread`× over a face's points uv (n, 2) (its boundary
    and a 5 × 5 grid of its box): one scale then maps (u,v) to the surface's lengths everywhere on it."""
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    g = np.stack(np.meshgrid(np.linspace(0, 1, 5), np.linspace(0, 1, 5)), -1).reshape(-1, 2) * (hi - lo) + lo
    du, dv = surface_speeds(surface, np.concatenate([uv[:: max(1, len(uv) // 32)], g]), uv)
    return bool(du.min() > 0 and dv.min() > 0 and du.max() <= spread * du.min() and dv.max() <= spread * dv.min())


def min_spacing(tolerance: float, scale: np.ndarray, length_scale: np.ndarray) -> float:
    """MIN_SPACING × tolerance in mm, as a distance in (u,v) · scale (2,) that keeps points at least that far apart
    in the metric-scaled (u,v) · length_scale (2,) (≈ mm)."""
    return MIN_SPACING * tolerance * float(np.max(np.asarray(scale) / length_scale))


def _triangle(data: dict, switches: str) -> dict:  # type: ignore[type-arg]
    """Triangle's triangulate; its internal errors (segments that meet where the input says they do not) raise
    meshing_failed."""
    try:
        return tr.triangulate(data, switches)
    except RuntimeError as exc:
        raise AmprepError(ErrorCode.MESHING_FAILED, f"the face's boundary in (u,v) meets itself ({exc})") from exc


def triangulate_pslg(pts: np.ndarray, segments: np.ndarray, holes: np.ndarray | None = None) -> np.ndarray:
    """(t, 3) constrained Delaunay triangles of points (n, 2) and segments (s, 2), nothing added on a segment, the
    parts holding a hole point (h, 2) and outside the segments removed. Triangle crashes the process on two equal
    points or a hole point outside the convex hull: equal or non-finite points raise meshing_failed, hole points
    outside are dropped (the outside is removed anyway); segments crossing or fewer than three points raise
    meshing_failed."""
    if len(pts) < 3:
        raise AmprepError(ErrorCode.MESHING_FAILED, f"a face's (u,v) boundary has {len(pts)} point(s)")
    if not np.isfinite(pts).all():
        raise AmprepError(ErrorCode.MESHING_FAILED, "a face's (u,v) boundary has non-finite points")
    if len(unique_points(pts)) != len(pts):
        raise AmprepError(ErrorCode.MESHING_FAILED, "a face's boundary touches itself in (u,v)")
    data = dict(vertices=pts, segments=segments)
    if holes is not None and len(holes) and len(pts) >= 3:
        try:
            eq = ConvexHull(pts).equations
        except QhullError:  # all points on a line: nothing to triangulate, nothing to hole
            eq = None
        if eq is not None:
            size = float(np.ptp(pts, axis=0).max())
            inside = holes[(holes @ eq[:, :2].T + eq[:, 2] < -1e-9 * size).all(axis=1)]
            if len(inside):
                data["holes"] = inside
    out = _triangle(data, "pYQ")
    if len(out.get("vertices", [])) != len(pts):
        raise AmprepError(ErrorCode.MESHING_FAILED, "the face's boundary in (u,v) self-intersects")
    return out.get("triangles", np.zeros((0, 3), np.int64)).astype(np.int64)


#: the quality mesher's smallest angle (degrees) in a plane's triangles, Triangle's -q (it terminates up to ~34°)
MIN_ANGLE = 30.0


def quality_pslg(pts: np.ndarray, segments: np.ndarray, holes: np.ndarray | None, min_angle: float = MIN_ANGLE,
                 max_points: int = 1_000_000) -> tuple[np.ndarray, np.ndarray]:
    """(points (n + k, 2), triangles (t, 3)): the constrained Delaunay triangulation of points (n, 2) and segments
    refined by Triangle (Ruppert) until no angle is under `min_angle` where that can be had without a point on a
    segment (-YY: the segments are shared edges, discretised once); its new points follow the n given ones, and
    their spacing grades from the segments' lengths. Past max_points new points the plain CDT is returned."""
    data = dict(vertices=pts, segments=segments)
    if holes is not None and len(holes):
        data["holes"] = holes
    try:
        out = _triangle(data, f"pq{min_angle:g}YYQ")
    except AmprepError:  # its refinement met segments that touch (a face pinched to a point): the plain CDT decides
        return pts, triangulate_pslg(pts, segments, holes)
    verts = out.get("vertices", pts)
    if len(verts) < len(pts) or not np.array_equal(verts[:len(pts)], pts) or len(verts) - len(pts) > max_points:
        return pts, triangulate_pslg(pts, segments, holes)
    return np.asarray(verts, float), out.get("triangles", np.zeros((0, 3), np.int64)).astype(np.int64)


_CODE_BASE = 1 << 20


def triangle_codes(tris: np.ndarray, n_points: int) -> np.ndarray | None:
    """(t,) int64 code of each triangle's sorted vertex triple (a·B² + b·B + c), None past 2^20 points."""
    if n_points >= _CODE_BASE:
        return None
    s = np.sort(tris, axis=1).astype(np.int64)
    return (s[:, 0] * _CODE_BASE + s[:, 1]) * _CODE_BASE + s[:, 2]


def recall_errors(n: int, codes: np.ndarray | None, old_codes: np.ndarray | None,
                  old_err: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(seen (n,) bool, err (n,)) for n triangles with triangle_codes `codes`: which were measured before, err[seen]
    their earlier error (old_codes (s,) with old_err (s,), any order); err is unset where not seen, and nothing is
    seen when either side has no codes."""
    seen, err = np.zeros(n, bool), np.empty(n)
    if codes is None or old_codes is None or not len(old_codes):
        return seen, err
    order = np.argsort(old_codes)
    known = old_codes[order]
    pos = np.minimum(np.searchsorted(known, codes), len(known) - 1)
    seen = known[pos] == codes
    err[seen] = old_err[order][pos[seen]]
    return seen, err


def apart(new: np.ndarray, pts: np.ndarray, eps: float) -> np.ndarray:
    """The new (k, 2) points farther than eps from every existing point and from each other (the first kept): two
    nodes closer than that gain nothing and may round to one vertex in a float32 STL (a degenerate triangle)."""
    if not len(new):
        return new
    far = cKDTree(pts).query(new, distance_upper_bound=eps)[0] > eps
    new = new[far]
    if len(new) > 1:
        pairs = cKDTree(new).query_pairs(eps, output_type="ndarray")
        if len(pairs):
            drop = np.zeros(len(new), bool)
            for i, j in pairs[np.argsort(pairs[:, 1])]:  # keep the lower index of each close pair
                if not drop[i]:
                    drop[j] = True
            new = new[~drop]
    return new


def in_sorted(values: np.ndarray, sorted_codes: np.ndarray) -> np.ndarray:
    """values (any shape) bool: which occur in the sorted 1-D array (np.isin without its sort)."""
    if not len(sorted_codes):
        return np.zeros(values.shape, bool)
    pos = np.minimum(np.searchsorted(sorted_codes, values), len(sorted_codes) - 1)
    return sorted_codes[pos] == values


def unique_points(pts: np.ndarray) -> np.ndarray:
    """(k, 2) the distinct rows of (n, 2) float points, sorted by (x, y) (a row read as one complex number)."""
    z = np.unique(np.ascontiguousarray(pts, dtype=np.float64).view(np.complex128).ravel())
    return z.view(np.float64).reshape(-1, 2)


def insertion_points(pts: np.ndarray, bad: np.ndarray, seg_code: np.ndarray, base: int) -> np.ndarray:
    """(k, 2) one new point per bad triangle (k, 3): midpoint of its longest edge that is not a boundary
    segment, else its centroid; seg_code: sorted codes lo·base + hi of the boundary segments."""
    a, b = bad, np.roll(bad, -1, axis=1)
    code = np.minimum(a, b).astype(np.int64) * base + np.maximum(a, b)
    d = pts[a] - pts[b]
    length = np.einsum("ijk,ijk->ij", d, d)
    length[in_sorted(code, seg_code)] = -1.0
    k = length.argmax(axis=1)
    rows = np.arange(len(bad))
    mid = 0.5 * (pts[a[rows, k]] + pts[b[rows, k]])
    centroid = pts[bad].mean(axis=1)
    return unique_points(np.where((length[rows, k] > 0)[:, None], mid, centroid))


#: point-segment pairs tested at once by inside_loops (memory: ~40 bytes each)
PAIRS_PER_BLOCK = 2_000_000


def inside_loops(points: np.ndarray, loops: list[np.ndarray]) -> np.ndarray:
    """(N,) bool even-odd point-in-polygon over all loops (closed polygons (n, 2)): a point is inside when a ray to +x
    crosses the segments an odd number of times, a segment counting where min(y_a, y_b) ≤ y < max(y_a, y_b) and
    x < its x at y. Only the pairs whose y ranges meet are formed (points sorted by y, each segment's run of them
    found by bisection), in blocks of PAIRS_PER_BLOCK: O(N log N + pairs), not N × segments."""
    inside = np.zeros(len(points), bool)
    if not len(points) or not loops:
        return inside
    a = np.concatenate(loops)
    b = np.concatenate([np.roll(poly, -1, axis=0) for poly in loops])
    order = np.argsort(points[:, 1], kind="stable")
    ys = points[order, 1]
    lo = np.searchsorted(ys, np.minimum(a[:, 1], b[:, 1]), side="left")
    hi = np.searchsorted(ys, np.maximum(a[:, 1], b[:, 1]), side="left")
    span = hi - lo
    keep = np.flatnonzero(span > 0)
    if not len(keep):
        return inside
    ends = np.cumsum(span[keep])
    crossings = np.zeros(len(points), np.int64)
    start = 0
    while start < len(keep):  # blocks of whole segments, each ~PAIRS_PER_BLOCK pairs (at least one segment)
        before = ends[start - 1] if start else 0
        stop = max(int(np.searchsorted(ends, before + PAIRS_PER_BLOCK, side="right")), start + 1)
        seg = keep[start:stop]
        count = span[seg]
        which = np.repeat(seg, count)
        first = np.repeat(np.cumsum(count) - count, count)
        p = order[lo[which] + np.arange(len(which)) - first]
        x, y = points[p, 0], points[p, 1]
        ax, ay, bx, by = a[which, 0], a[which, 1], b[which, 0], b[which, 1]
        xint = ax + (y - ay) * (bx - ax) / (by - ay)
        crossings += np.bincount(p[x < xint], minlength=len(points))
        start = stop
    return crossings % 2 == 1


def crossing_segments(loops: list[np.ndarray]) -> np.ndarray:
    """(k, 2) pairs of indices of the loops' segments (node i to the next, each loop (n, 2) closed, the loops'
    segments taken in turn) that cross or touch with no end point shared: what makes a boundary polygon
    self-intersect (two edges discretised coarsely where they meet at a small angle)."""
    a = np.concatenate(loops)
    b = np.concatenate([np.roll(lp, -1, axis=0) for lp in loops])
    pairs = np.array(overlapping_boxes(np.concatenate([np.minimum(a, b), np.maximum(a, b)], axis=1)),
                     np.int64).reshape(-1, 2)
    i, j = pairs[:, 0], pairs[:, 1]
    shared = ((a[i] == a[j]).all(1) | (a[i] == b[j]).all(1) | (b[i] == a[j]).all(1) | (b[i] == b[j]).all(1))
    i, j = i[~shared], j[~shared]
    hit = ((np.sign(turn(a[i], b[i], a[j])) * np.sign(turn(a[i], b[i], b[j])) <= 0)
           & (np.sign(turn(a[j], b[j], a[i])) * np.sign(turn(a[j], b[j], b[i])) <= 0))
    return np.sort(np.stack([i[hit], j[hit]], axis=1), axis=1)
