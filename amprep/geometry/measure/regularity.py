"""Triangle regularity (source 000, Table 2): angle, area and edge measures, 1 equilateral, 0 degenerate."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from amprep.geometry.core.vectors import cross, dot, norms

#: The source table's bins: [0, 0.005), [0.005, 0.4), [0.4, 0.8), [0.8, 1.0].
BIN_EDGES = np.array([0.0, 0.005, 0.4, 0.8])
MEASURES = ("angle", "area", "edge")


def min_angles(corners: np.ndarray) -> np.ndarray:
    """(m,) smallest angle (radians) of each triangle of (m, 3, 3) corners, the one opposite its shortest side, as
    atan2(|a × b|, a · b) of the two sides at that corner (exact for slivers too); 0 for one with a zero-length side."""
    c0, c1, c2 = corners[:, 0], corners[:, 1], corners[:, 2]
    sides = np.stack([c1 - c0, c2 - c1, c0 - c2], axis=1)  # side k runs from corner k to k+1, opposite corner k+2
    return _smallest_angles(sides, dot(sides, sides))


def _smallest_angles(sides: np.ndarray, sq: np.ndarray) -> np.ndarray:
    """(m,) min_angles of triangles given by their sides (m, 3, 3), side k from corner k to k+1, and the sides' squared
    lengths sq (m, 3)."""
    k = sq.argmin(axis=1)
    rows = np.arange(len(sides))
    a, b = sides[rows, (k + 2) % 3], -sides[rows, (k + 1) % 3]  # from corner k+2 to corners k and k+1
    return angles_from(norms(cross(a, b)), dot(a, b), sq[rows, k] > 0)


def angles_from(y: np.ndarray, x: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """(m,) arctan2(y, x) where ok (m,) and it is finite, else 0: min_angles' last step, the compiled kernel's too."""
    angle = np.arctan2(y, x)
    return np.where(ok & np.isfinite(angle), angle, 0.0)


def regularity(corners: np.ndarray) -> dict[str, np.ndarray]:
    """Per triangle of (m, 3, 3) corners: angle q_a = α_min / 60°; area q_A = 4√3·A / (l₁² + l₂² + l₃²);
    edge q_e = l_min / l_max. Each (m,) in [0, 1] (regularity_at, the corners their own nodes)."""
    return regularity_at(corners.reshape(-1, 3), np.arange(3 * len(corners)).reshape(-1, 3))


#: triangles regularity_at measures at a time: its temporaries stay under ~0.3 GB whatever the mesh's size
CHUNK = 1_000_000


def regularity_at(xyz: np.ndarray, tris: np.ndarray) -> dict[str, np.ndarray]:
    """regularity of the triangles tris (m, 3) over nodes xyz (n, 3), with no (m, 3, 3) gather, each side made once
    for all three measures (min_angles' corner opposite the shortest side); CHUNK triangles at a time."""
    if len(tris) <= CHUNK:
        return _measures_at(xyz, tris)
    parts = [_measures_at(xyz, tris[k:k + CHUNK]) for k in range(0, len(tris), CHUNK)]
    return {name: np.concatenate([q[name] for q in parts]) for name in MEASURES}


def _measures_at(xyz: np.ndarray, tris: np.ndarray) -> dict[str, np.ndarray]:
    """regularity_at of one chunk of triangles."""
    p0, p1, p2 = xyz[tris[:, 0]], xyz[tris[:, 1]], xyz[tris[:, 2]]
    sides = np.empty((len(tris), 3, 3), np.result_type(xyz.dtype, np.float32))  # float32 nodes stay float32
    np.subtract(p1, p0, out=sides[:, 0])
    np.subtract(p2, p1, out=sides[:, 1])
    np.subtract(p0, p2, out=sides[:, 2])
    sq_side = dot(sides, sides)
    lengths = np.sqrt(sq_side)
    sq = (lengths**2).sum(axis=1)
    area = 0.5 * norms(cross(sides[:, 0], p2 - p0))
    with np.errstate(invalid="ignore", divide="ignore"):
        q_area = np.where(sq > 0, 4 * np.sqrt(3) * area / sq, 0.0)
        lmax = lengths.max(axis=1)
        q_edge = np.where(lmax > 0, lengths.min(axis=1) / lmax, 0.0)
    q_angle = np.degrees(_smallest_angles(sides, sq_side)) / 60.0
    return {"angle": np.clip(q_angle, 0, 1), "area": np.clip(q_area, 0, 1), "edge": np.clip(q_edge, 0, 1)}


@dataclass(frozen=True)
class RegularitySummary:
    """Mean and the four bin counts of each measure."""

    mean: dict[str, float]
    bins: dict[str, list[int]]

    def as_dict(self) -> dict[str, dict]:  # type: ignore[type-arg]
        return {k: {"mean": self.mean[k], "bins": self.bins[k]} for k in MEASURES}


def bin_counts(q: np.ndarray) -> list[int]:
    """Counts of q in [0, 0.005), [0.005, 0.4), [0.4, 0.8), [0.8, 1.0]."""
    idx = np.searchsorted(BIN_EDGES, q, side="right") - 1
    return [int(c) for c in np.bincount(np.clip(idx, 0, 3), minlength=4)]


def summarize(q: dict[str, np.ndarray]) -> RegularitySummary:
    """Means and bin counts of the per-triangle measures of `regularity`."""
    mean = {k: float(q[k].mean()) if len(q[k]) else float("nan") for k in MEASURES}
    return RegularitySummary(mean, {k: bin_counts(q[k]) for k in MEASURES})
