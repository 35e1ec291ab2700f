"""Smallest angles, unit normals and edge-flip candidates of triangles given as indices into nodes: by numpy, or by the
compiled kernels of _angle_kernel.py (no (m, 3, 3) gather, ~8× faster) where core.compiled chooses them. The kernels
compute every product and sum in the numpy formulas' order and leave arctan2 to numpy, so both give the same bits:
the choice changes no mesh."""

from __future__ import annotations

from types import ModuleType
from typing import NamedTuple

import numpy as np

from amprep.geometry.core.compiled import compiled, use_compiled
from amprep.geometry.core.vectors import dot, turn, unit_normals
from amprep.geometry.measure.regularity import angles_from, min_angles

#: a call of at least this many triangles runs the kernels when no enclosing computation chose (core.compiled)
COMPILED_MIN_TRIANGLES = 100_000

_kernel: ModuleType | None = None


def load_angle_kernels() -> ModuleType:
    """The compiled kernels, imported once (numba's cached compilation)."""
    global _kernel
    if _kernel is None:
        from amprep.geometry.measure import _angle_kernel

        _kernel = _angle_kernel
    return _kernel


def min_angles_at(xyz: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """(m,) regularity.min_angles of the triangles tris (m, 3) over nodes xyz (n, 3)."""
    if not use_compiled(len(tris), COMPILED_MIN_TRIANGLES):
        return min_angles(xyz[tris])
    m = len(tris)
    y, x, ok = np.empty(m), np.empty(m), np.empty(m, bool)
    load_angle_kernels().min_angle_parts(_f64(xyz), _i64(tris), y, x, ok)
    return angles_from(y, x, ok)


def unit_normals_at(xyz: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """(m, 3) core.vectors.unit_normals of the triangles tris (m, 3) over nodes xyz (n, 3): (c₁ − c₀) × (c₂ − c₀) / |…|,
    0 where that length is not > 0."""
    if not use_compiled(len(tris), COMPILED_MIN_TRIANGLES):
        return unit_normals(xyz[tris])[0]
    out = np.empty((len(tris), 3))
    load_angle_kernels().unit_normals(_f64(xyz), _i64(tris), out)
    return out


class Flips(NamedTuple):
    """Shared sides' flipped pairs: new1, new2 (p, 3); their smallest angles angle1, angle2 (p,), unit normals
    normal1, normal2 (p, 3) and twice their signed (u,v) areas area1, area2 (p,); fold_old, fold_new (p,) the dot of
    the old pair's and the new pair's normals."""

    new1: np.ndarray
    new2: np.ndarray
    angle1: np.ndarray
    angle2: np.ndarray
    normal1: np.ndarray
    normal2: np.ndarray
    area1: np.ndarray
    area2: np.ndarray
    fold_old: np.ndarray
    fold_new: np.ndarray


def flip_candidates(xyz: np.ndarray, uv: np.ndarray, tris: np.ndarray, normals: np.ndarray, t1: np.ndarray,
                    k1: np.ndarray, t2: np.ndarray, k2: np.ndarray) -> Flips:
    """Flips of the sides triangle t1's side k1 = t2's side k2 (p,): t1 = [a, b, c] from corner k1 and d t2's far
    corner give new1 = [a, d, c], new2 = [d, b, c]; xyz (n, 3), uv (n, 2) the nodes, normals (t, 3) the triangles'
    unit normals."""
    p = len(t1)
    if use_compiled(p, COMPILED_MIN_TRIANGLES):
        new, y, x, ok = np.empty((2 * p, 3), np.int64), np.empty(2 * p), np.empty(2 * p), np.empty(2 * p, bool)
        fold_old, fold_new, normal, area = np.empty(p), np.empty(p), np.empty((2 * p, 3)), np.empty(2 * p)
        load_angle_kernels().flip_candidates(_f64(xyz), _f64(uv), _i64(tris), _f64(normals), _i64(t1), _i64(k1),
                                             _i64(t2), _i64(k2), new, y, x, ok, fold_old, fold_new, normal, area)
        angle = angles_from(y, x, ok)
        return Flips(new[:p], new[p:], angle[:p], angle[p:], normal[:p], normal[p:], area[:p], area[p:], fold_old,
                     fold_new)
    a, b, c = tris[t1, k1], tris[t1, (k1 + 1) % 3], tris[t1, (k1 + 2) % 3]
    d = tris[t2, (k2 + 2) % 3]
    new1, new2 = np.stack([a, d, c], axis=1), np.stack([d, b, c], axis=1)
    normal1, normal2 = unit_normals(xyz[new1])[0], unit_normals(xyz[new2])[0]
    return Flips(new1, new2, min_angles(xyz[new1]), min_angles(xyz[new2]), normal1, normal2,
                 turn(uv[a], uv[d], uv[c]), turn(uv[d], uv[b], uv[c]), dot(normals[t1], normals[t2]),
                 dot(normal1, normal2))


def warm_angle_kernels() -> None:
    """Each kernel called once on a small input with the types of real calls (numba's first dispatch paid here)."""
    xyz = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.1]])
    uv = xyz[:, :2].copy()
    tris = np.array([[0, 1, 2], [2, 1, 3]])
    with compiled(True):
        normals = unit_normals_at(xyz, tris)
        min_angles_at(xyz, tris)
        one = np.array([1])
        flip_candidates(xyz, uv, tris, normals, np.array([0]), one, one, np.array([0]))


def _f64(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64)


def _i64(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.int64)
