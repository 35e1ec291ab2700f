"""Cusp height (stair-step error) for a layer thickness t and a build direction b: two methods.

approximate (Choi & Samavedam): c = t·|n̂·b̂| per triangle, horizontal triangles excluded.
bounding_box (thesis 3.1): slice, two boxes per slice segment, rays from the point cloud to the box walls.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from amprep.geometry.core import vectors
from amprep.geometry.core.progress import ProgressFn, checkpoint

HORIZONTAL_COS = 1.0 - 1e-9  # |n̂·b̂| above this: a horizontal facet, printed flat, no stair step


def unit_normals(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((m, 3) unit normals (0 for zero-area), (m,) areas) of (m, 3, 3) corners (vectors.unit_normals)."""
    unit, length = vectors.unit_normals(corners)
    return unit, 0.5 * length


def approximate(corners: np.ndarray, layer: float, build_dir: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((m,) c = t·|n̂·b̂| per triangle, (m,) bool counted): horizontal and zero-area triangles are not counted."""
    b = np.asarray(build_dir, float) / np.linalg.norm(build_dir)
    unit, area = unit_normals(corners)
    cos = np.abs(unit @ b)
    counted = (area > 0) & (cos < HORIZONTAL_COS)
    return layer * cos, counted


def approximate_summary(corners: np.ndarray, layer: float, build_dir: np.ndarray) -> dict[str, float]:
    """{mean: area-weighted mean of t·|n̂·b̂| over counted triangles, max}."""
    c, counted = approximate(corners, layer, build_dir)
    _, area = unit_normals(corners)
    w = area * counted
    if w.sum() == 0:
        return {"mean": 0.0, "max": 0.0}
    return {"mean": float((c * w).sum() / w.sum()), "max": float(c[counted].max())}


def _basis(b: np.ndarray) -> np.ndarray:
    """(3, 3) rows e1, e2, b̂: a right-handed frame whose third axis is the build direction."""
    b = b / np.linalg.norm(b)
    helper = np.eye(3)[np.argmin(np.abs(b))]
    e1 = vectors.cross(helper, b)
    e1 /= np.linalg.norm(e1)
    return np.stack([e1, vectors.cross(b, e1), b])


def point_cloud(corners: np.ndarray, density: float, max_points: int = 2_000_000,
                rng: np.random.Generator | None = None) -> tuple[np.ndarray, np.ndarray, float]:
    """Step 1: ((p, 3) points spread evenly over the triangles at `density` per mm², (p,) triangle of each
    point, the density used); each triangle gets round(area·density) points at least ... in proportion to area,
    by stratified random barycentric sampling. The density is lowered when it would exceed max_points."""
    rng = rng or np.random.default_rng(0)
    _, area = unit_normals(corners)
    total = float(area.sum())
    if total == 0:
        return np.zeros((0, 3)), np.zeros(0, np.int64), density
    density = min(density, max_points / total)
    expected = area * density
    count = np.floor(expected).astype(np.int64)
    count += rng.random(len(area)) < (expected - count)
    tri = np.repeat(np.arange(len(area)), count)
    r1, r2 = rng.random(len(tri)), rng.random(len(tri))
    s = np.sqrt(r1)
    w = np.stack([1 - s, s * (1 - r2), s * r2], axis=1)
    pts = np.einsum("pk,pkd->pd", w, corners[tri])
    return pts, tri, density


@dataclass(frozen=True)
class SliceSegments:
    """Step 2: (s,) slice index, (s, 3) P1, (s, 3) P2 of every triangle ∩ plane z_k = z_0 + k·t (build frame)."""

    slice_index: np.ndarray
    p1: np.ndarray
    p2: np.ndarray
    z0: float
    heights: np.ndarray = field(default_factory=lambda: np.zeros(0))


def slice_segments(corners: np.ndarray, layer: float, build_dir: np.ndarray) -> SliceSegments:
    """Cut every triangle by the planes z_k = z_min + (k + ½)·t, k ≥ 0, along b (half a layer up, so no plane
    passes through the part's lowest or highest flat face); (P1, P2) per cut, in world coordinates."""
    from amprep.geometry.measure._cusp_kernel import slice_kernel

    frame = _basis(np.asarray(build_dir, float))
    z = corners @ frame[2]  # (m, 3)
    z0 = float(z.min()) + 0.5 * layer
    n_slices = int(np.floor((float(z.max()) - z0) / layer)) + 1
    lo = np.ceil((z.min(axis=1) - z0) / layer).astype(np.int64)
    hi = np.floor((z.max(axis=1) - z0) / layer).astype(np.int64)
    lo, hi = np.maximum(lo, 0), np.minimum(hi, n_slices - 1)
    n = np.maximum(hi - lo + 1, 0)
    offset = np.cumsum(n) - n
    total = int(n.sum())
    k, p1, p2 = np.empty(total, np.int64), np.empty((total, 3)), np.empty((total, 3))
    valid = np.empty(total, bool)
    slice_kernel(np.ascontiguousarray(corners, dtype=np.float64), np.ascontiguousarray(z), z0, float(layer), lo, n,
                 offset, k, p1, p2, valid)
    keep = valid
    heights = z0 + np.arange(n_slices) * layer
    return SliceSegments(k[keep], p1[keep], p2[keep], z0, heights)


@dataclass(frozen=True)
class BoxCusp:
    """Per box (two per segment): slice index, cusp height (nan when no cloud point lies in it)."""

    slice_index: np.ndarray
    height: np.ndarray
    slice_heights: np.ndarray
    points: int
    density: float

    def summary(self) -> dict[str, object]:
        filled = np.isfinite(self.height)
        n = len(self.slice_heights)
        k, h = self.slice_index[filled], self.height[filled]
        count = np.bincount(k, minlength=n)
        total = np.bincount(k, weights=h, minlength=n)
        top = np.full(n, -np.inf)
        np.maximum.at(top, k, h)
        per_slice = [{"z": float(z), "max": float(top[i]) if count[i] else None,
                      "mean": float(total[i] / count[i]) if count[i] else None, "boxes": int(count[i])}
                     for i, z in enumerate(self.slice_heights)]
        return {"mean": float(h.mean()) if len(h) else None, "max": float(h.max()) if len(h) else None,
                "boxes": int(len(self.height)), "non_empty_boxes": int(filled.sum()), "points": self.points,
                "density": self.density, "per_slice": per_slice}


#: slice segments per call of the box kernel; cancel and the time limit are checked between calls (progress)
SEGMENTS_PER_CALL = 20_000


def bounding_box(corners: np.ndarray, layer: float, build_dir: np.ndarray, density: float | None = None,
                 cloud: tuple[np.ndarray, np.ndarray] | None = None, progress: ProgressFn | None = None) -> BoxCusp:
    """Thesis 3.1: (1) cloud with facet normals; (2) slice segments P1P2; (3) for each, the rectangles P1 P2 Pm P3 on
    both sides (|P2Pm| = t, ⟂ P1P2, in the slice plane) extruded by t along b: two boxes; (4) for each cloud point in
    a box (found with KD-trees), the ray along its normal, reversed when the normal points away from the wall P1P2
    (Fig. 12 cases 2, 4), to the box boundary; box cusp = the largest such distance.
    The ray is taken in the box's cross-section (the normal projected on the plane ⟂ P1P2), so it leaves through the
    wall, the top or the bottom: cusp height is a deviation across the layer, and a long box's end caps would
    otherwise measure the segment's length; points whose normal is parallel to the wall (n̂·d = 0: horizontal
    facets, walls at right angles) are not counted, as the approximate method skips horizontal facets. density: points per mm² (default (4/t)², at most 2 M points);
    cloud: (points (p, 3), triangle of each (p,)) instead of sampling; progress: called between blocks of segments."""
    b = np.asarray(build_dir, float) / np.linalg.norm(build_dir)
    unit, _ = unit_normals(corners)
    if cloud is None:
        pts, tri, used = point_cloud(corners, density if density else (4.0 / layer) ** 2)
    else:
        (pts, tri), used = cloud, float("nan")
    normals = unit[tri]
    seg = slice_segments(corners, layer, b)
    ns = len(seg.slice_index)
    if ns == 0 or len(pts) == 0:
        return BoxCusp(np.zeros(0, np.int64), np.zeros(0), seg.heights, len(pts), used)
    e = seg.p2 - seg.p1
    e -= np.outer(e @ b, b)
    length = np.linalg.norm(e, axis=1)
    e /= length[:, None]
    side = vectors.cross(b, e)  # horizontal, ⟂ P1P2
    # two boxes per segment: box j < ns on the +side, j ≥ ns on the −side; local axes (e, ±side, b), origin P1
    # A point in layer k (z_k ≤ z < z_k + t) can only lie in boxes of slice k: the points are hashed by (layer, 2D
    # cell of the slice plane) and each segment visits the cells its two boxes cover (compiled kernel).
    from amprep.geometry.measure._cusp_kernel import box_cusp_kernel

    frame = _basis(b)
    p2d = pts @ frame[:2].T
    layer_of = np.floor((pts @ b - seg.z0) / layer).astype(np.int64)
    cell = max(layer, 1.0 / np.sqrt(max(len(pts) / max(float(unit_normals(corners)[1].sum()), 1e-300), 1e-300)))
    origin2 = p2d.min(axis=0) - cell
    nx, ny = (np.floor((p2d.max(axis=0) + cell - origin2) / cell).astype(np.int64) + 1).tolist()
    cxy = np.floor((p2d - origin2) / cell).astype(np.int64)
    ok = (layer_of >= 0) & (layer_of < len(seg.heights))
    keys = (layer_of * ny + cxy[:, 1]) * nx + cxy[:, 0]
    order = np.flatnonzero(ok)[np.argsort(keys[ok], kind="stable")]
    cell_keys, cell_start, counts = np.unique(keys[order], return_index=True, return_counts=True)
    height = np.full(2 * ns, -np.inf)
    sorted_pts, sorted_normals = np.ascontiguousarray(pts[order]), np.ascontiguousarray(normals[order])
    for s in range(0, ns, SEGMENTS_PER_CALL):  # in blocks, so that a cancel or a time limit is seen between them
        checkpoint()
        sl = slice(s, min(s + SEGMENTS_PER_CALL, ns))
        h = np.full(2 * (sl.stop - s), -np.inf)
        box_cusp_kernel(seg.slice_index[sl], seg.p1[sl], e[sl], side[sl], length[sl], b,
                        np.ascontiguousarray(frame[:2]), float(layer), float(cell), origin2, nx, ny, cell_keys,
                        cell_start, cell_start + counts, sorted_pts, sorted_normals, h)
        height[sl], height[ns + s:ns + sl.stop] = h[:sl.stop - s], h[sl.stop - s:]
        if progress:
            progress("cusp height", sl.stop / ns)
    height[~np.isfinite(height)] = np.nan
    return BoxCusp(np.concatenate([seg.slice_index, seg.slice_index]), height, seg.heights, len(pts), used)
