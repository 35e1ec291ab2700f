"""The rigid motion that puts a user's STL on its CAD: axis permutations first, then least squares (ICP)."""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.core.progress import checkpoint
from amprep.geometry.core.vectors import cross


@dataclass(frozen=True)
class Alignment:
    """x_cad = R · x_stl + t; rms and max distance (mm) of the STL's points to the CAD after the fit."""

    rotation: np.ndarray
    translation: np.ndarray
    rms: float
    max: float
    permutation: str
    inliers: float = 1.0  # fraction of STL points within the inlier distance of the CAD

    def apply(self, points: np.ndarray) -> np.ndarray:
        """(n, 3) STL-frame points → CAD frame."""
        return points @ self.rotation.T + self.translation

    def as_dict(self) -> dict[str, object]:
        return {"rotation": self.rotation.round(12).tolist(), "translation": self.translation.round(9).tolist(),
                "rms": self.rms, "max": self.max, "axis_permutation": self.permutation, "inlier_fraction": self.inliers,
                "moved": bool(not np.allclose(self.rotation, np.eye(3)) or np.linalg.norm(self.translation) > 1e-9)}


def signed_permutations() -> list[tuple[str, np.ndarray]]:
    """The 24 rotations that map coordinate axes onto coordinate axes (det = +1), named like '+x+z-y'."""
    out = []
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1, -1), repeat=3):
            R = np.zeros((3, 3))
            for row, (col, sgn) in enumerate(zip(perm, signs)):
                R[row, col] = sgn
            if np.linalg.det(R) > 0:
                name = "".join(f"{'+' if s > 0 else '-'}{'xyz'[c]}" for c, s in zip(perm, signs))
                out.append((name, R))
    return out


def kabsch(src: np.ndarray, dst: np.ndarray, weights: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """R, t minimising Σ w_i |R·src_i + t − dst_i|² (proper rotation)."""
    w = np.ones(len(src)) if weights is None else np.asarray(weights, float)
    w = w / w.sum()
    cs, cd = w @ src, w @ dst
    H = ((src - cs) * w[:, None]).T @ (dst - cd)
    U, _, Vt = np.linalg.svd(H)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return R, cd - R @ cs


def point_to_plane(src: np.ndarray, dst: np.ndarray, normals: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """R, t of one Gauss–Newton step on Σ w_i (n_i · (R·src_i + t − dst_i))², linearised about the identity and the
    points' centroid: the motion that slides each (n, 3) point along its target's plane costs nothing, so a fit to
    surfaces converges where point-to-point pulls toward the facets' corners; a direction the planes do not fix
    (a cylinder's own axis and turn) is not moved (least squares' minimum-norm solution)."""
    w = np.sqrt(np.asarray(weights, float) / np.sum(weights))[:, None]
    centre = (weights @ src) / np.sum(weights)
    arm = src - centre
    scale = max(float(np.abs(arm).max(initial=0.0)), 1e-12)  # rotations in length units, like translations
    rows = np.hstack([cross(arm, normals) / scale, normals]) * w
    rhs = -((src - dst) * normals).sum(axis=1) * w[:, 0]
    x = np.linalg.lstsq(rows, rhs, rcond=1e-6)[0]
    omega, tau = x[:3] / scale, x[3:]
    angle = float(np.linalg.norm(omega))
    R = np.eye(3)
    if angle > 0:
        k = omega / angle
        K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
        R = np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K  # Rodrigues
    return R, centre + tau - R @ centre


def principal_frames(points: np.ndarray) -> list[np.ndarray]:
    """The 4 proper frames (3, 3) (rows = axes) of a cloud's principal axes, largest variance first, up to signs."""
    centred = points - points.mean(axis=0)
    _, _, vt = np.linalg.svd(centred, full_matrices=False)
    out = []
    for sx, sy in itertools.product((1, -1), repeat=2):
        f = vt * np.array([sx, sy, 1.0])[:, None]
        if np.linalg.det(f) < 0:
            f[2] = -f[2]
        out.append(f)
    return out


#: points of the sample that score a start and set ICP's trimming distance (its median nearest distance)
SCORE_POINTS = 2_000


#: ICP rounds on the whole sample after the coarse ones (the fit to the exact surfaces follows in place.py)
FINE_ROUNDS = 8


def _icp(tree: cKDTree, cad_points: np.ndarray, pts: np.ndarray, R: np.ndarray, t: np.ndarray, reach: float,
         inlier_distance: float, rounds: int) -> tuple[np.ndarray, np.ndarray]:
    """Trimmed ICP of (n, 3) points onto the cloud from (R, t): matches within max(3 × the median nearest distance of
    the first SCORE_POINTS, inlier_distance), each query bounded; stops when a round moves by < 1e-12."""
    for _ in range(rounds):
        checkpoint()
        moved = pts @ R.T + t
        near, first = tree.query(moved[:SCORE_POINTS], distance_upper_bound=reach, workers=-1)
        trim = max(3 * float(np.median(np.minimum(near, reach))), inlier_distance)
        if len(moved) <= SCORE_POINTS:  # the nearest within reach ≥ trim are those within trim: no second query
            d, idx = np.where(near < trim, near, np.inf), first
        else:
            d, idx = tree.query(moved, distance_upper_bound=trim, workers=-1)
        keep = np.isfinite(d)
        if keep.sum() < 3:
            break
        dR, dt = kabsch(moved[keep], cad_points[idx[keep]])
        R, t = dR @ R, dR @ t + dt
        if np.abs(dR - np.eye(3)).max() < 1e-12 and np.linalg.norm(dt) < 1e-12:
            break
    return R, t


def align(stl_points: np.ndarray, cad_points: np.ndarray, inlier_distance: float, stl_cloud: np.ndarray | None = None,
          cad_cloud: np.ndarray | None = None, min_inliers: float = 0.6, iterations: int = 40, sample: int = 20_000,
          rng: np.random.Generator | None = None, tree: cKDTree | None = None) -> Alignment:
    """Fit (n, 3) STL points onto a dense (p, 3) cloud on the CAD surface. Starts: the 24 axis rotations about the
    bounding-box centres (STLs turned into print orientation) and the 4 matchings of principal axes about the
    centroids (any other rotation); each is scored by the median nearest distance, the best few are refined by
    trimmed ICP (points within 3× the median distance, so regions where the STL differs from the CAD do not pull
    the fit). Every k-d tree query is bounded (10 % of the CAD's diagonal for scores, the trimming distance in
    ICP), so alignment costs seconds however far the STL starts and however large the part.
    rms and max are over the inliers (points within inlier_distance). stl_cloud: points spread evenly over the STL
    (for the principal axes; default its vertices), cad_cloud the same on the CAD (default cad_points, which need
    not be spread by area: a reference cloud samples slivers and edges densely); `tree` the k-d tree of cad_points when
    the caller has one. Fewer than min_inliers of the points on the CAD: the STL does not belong to it,
    AmprepError(stl_mismatch)."""
    rng = rng or np.random.default_rng(0)
    even = stl_cloud if stl_cloud is not None else stl_points
    # points spread evenly by area: vertices crowd on small curved features, which turn freely about their axes
    pts = even[rng.choice(len(even), min(sample, len(even)), replace=False)]
    probe = pts
    tree = tree if tree is not None else cKDTree(cad_points)
    starts: list[tuple[str, np.ndarray, np.ndarray]] = []
    c_cad = (cad_points.min(axis=0) + cad_points.max(axis=0)) / 2
    c_stl = (stl_points.min(axis=0) + stl_points.max(axis=0)) / 2
    for name, R in signed_permutations():
        starts.append((name, R, c_cad - R @ c_stl))
    cad_even = cad_cloud if cad_cloud is not None else cad_points
    f_cad = principal_frames(cad_even)[0]
    m_cad, m_stl = cad_even.mean(axis=0), even.mean(axis=0)
    for f_stl in principal_frames(even):
        R = f_cad.T @ f_stl
        starts.append(("principal axes", R, m_cad - R @ m_stl))
    # a k-d tree query far from the cloud visits most of the tree: every query is bounded (a miss is inf), so a
    # far-off start costs what a near one does, whatever the part's size
    reach = 0.1 * float(np.linalg.norm(np.ptp(cad_points, axis=0))) + inlier_distance
    scored = []
    for name, R, t in starts:
        checkpoint()
        d, _ = tree.query(probe[:SCORE_POINTS] @ R.T + t, distance_upper_bound=reach)
        scored.append((float(np.median(np.minimum(d, reach))), name, R, t))
    scored.sort(key=lambda s: s[0])
    best, best_key = None, (0.0, 0.0, 0.0)
    for _, name, R, t in scored[:4]:  # symmetric parts: refine the few best starts, keep the best fit
        # coarse to fine: ICP on the scoring points until it settles, then a few rounds on the whole sample
        for cloud, rounds in ((pts[:SCORE_POINTS], iterations), (pts, FINE_ROUNDS)):
            R, t = _icp(tree, cad_points, cloud, R, t, reach, inlier_distance, rounds)
        checkpoint()
        d, _ = tree.query(stl_points @ R.T + t, distance_upper_bound=inlier_distance * (1 + 1e-12), workers=-1)
        inl = np.isfinite(d)
        fit = Alignment(R, t, float(np.sqrt(np.mean(d[inl] ** 2))) if inl.any() else float("inf"),
                        float(d[inl].max(initial=0.0)), name, float(inl.mean()))
        # a symmetric part fits several ways equally well: prefer the smallest rotation among equal fits
        key = (round(fit.inliers, 3), -round(fit.rms / max(inlier_distance, 1e-12), 2), float(np.trace(R)))
        if best is None or key > best_key:
            best, best_key = fit, key
    assert best is not None
    if best.inliers < min_inliers:
        raise AmprepError(ErrorCode.STL_MISMATCH, f"the STL does not fit this CAD: after the best rigid fit only "
                          f"{100 * best.inliers:.0f} % of its vertices lie within {inlier_distance:.3g} mm of the CAD "
                          f"(at least {100 * min_inliers:.0f} % needed)")
    return best
