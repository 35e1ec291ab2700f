"""Cylindricity by the minimum zone (thesis Table 3): the thinnest shell of two coaxial cylinders holding the points."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from amprep.geometry.core.vectors import cross


@dataclass(frozen=True)
class Cylindricity:
    """zone = r_max − r_min about the best axis (mm); radius = (r_max + r_min)/2; axis point (3,) and unit direction (3,)."""

    zone: float
    radius: float
    axis_point: np.ndarray
    axis_direction: np.ndarray

    def as_dict(self) -> dict[str, object]:
        return {"zone": self.zone, "radius": self.radius,
                "axis": {"point": [float(x) for x in self.axis_point], "direction": [float(x) for x in self.axis_direction]}}


def radial_distances(points: np.ndarray, point: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """(n,) r_i = |(p_i − a) − ((p_i − a)·d̂) d̂| for (n, 3) points and the axis through a along d."""
    d = direction / np.linalg.norm(direction)
    rel = points - point
    along = rel @ d
    return np.sqrt(np.maximum(np.einsum("ij,ij->i", rel, rel) - along * along, 0.0))


def _frame(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.eye(3)[np.argmin(np.abs(d))]
    e1 = cross(d, helper)
    e1 /= np.linalg.norm(e1)
    return e1, cross(d, e1)


def _axis(params: np.ndarray, a0: np.ndarray, d0: np.ndarray, e1: np.ndarray, e2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """4 parameters (two tilts of the direction, two shifts of the point) around a start axis (a0, d0)."""
    d = d0 + params[0] * e1 + params[1] * e2
    d /= np.linalg.norm(d)
    return a0 + params[2] * e1 + params[3] * e2, d


def least_squares_axis(points: np.ndarray, point: np.ndarray, direction: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Axis and radius minimising Σ (r_i − r)², started from a guess of the axis."""
    d0 = direction / np.linalg.norm(direction)
    e1, e2 = _frame(d0)
    r0 = float(np.median(radial_distances(points, point, d0)))

    def resid(x: np.ndarray) -> np.ndarray:
        a, d = _axis(x[:4], point, d0, e1, e2)
        return radial_distances(points, a, d) - x[4]

    fit = least_squares(resid, np.array([0.0, 0.0, 0.0, 0.0, r0]), method="lm")
    a, d = _axis(fit.x[:4], point, d0, e1, e2)
    return a, d, float(fit.x[4])


def minimum_zone(points: np.ndarray, point: np.ndarray | None = None, direction: np.ndarray | None = None) -> Cylindricity:
    """Minimise r_max − r_min over the axis (4 parameters: direction tilt and position), from the least-squares
    axis; (n, 3) points; the start axis (e.g. the CAD cylinder's) or, without one, the principal direction."""
    pts = np.asarray(points, dtype=float)
    if len(pts) < 6:
        raise ValueError("cylindricity needs at least 6 points")
    if direction is None:
        centred = pts - pts.mean(axis=0)
        direction = np.linalg.svd(centred, full_matrices=False)[2][0]
    if point is None:
        point = pts.mean(axis=0)
    a, d, _ = least_squares_axis(pts, np.asarray(point, float), np.asarray(direction, float))
    # project the start point to the middle of the cloud along the axis (well-conditioned tilts)
    a = a + ((pts - a) @ d).mean() * d
    e1, e2 = _frame(d)
    scale = float(np.ptp(pts, axis=0).max()) or 1.0

    from amprep.geometry.measure._zone_kernel import nelder_mead_zone, zone_at

    cpts = np.ascontiguousarray(pts)
    best = np.zeros(4)
    start = zone_at(cpts, a, d, e1, e2, best)
    for step in (1e-2, 1e-4):  # coarse then fine simplex (the max−min objective is not smooth)
        init = np.vstack([best] + [best + step * np.eye(4)[i] * np.array([1, 1, scale, scale])[i] for i in range(4)])
        x, f = nelder_mead_zone(cpts, a, d, e1, e2, init, 1e-10, max(start, 1e-9) * 1e-6, 1200)
        if f <= zone_at(cpts, a, d, e1, e2, best):
            best = x
    aa, dd = _axis(best, a, d, e1, e2)
    r = radial_distances(pts, aa, dd)
    return Cylindricity(float(r.max() - r.min()), float((r.max() + r.min()) / 2), aa, dd)
