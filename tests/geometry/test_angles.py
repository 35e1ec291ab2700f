"""measure.angles: the compiled smallest angles, normals and flip candidates give numpy's bits, and the numbers are
right against triangles whose angles are known."""

import numpy as np
import pytest

from amprep.geometry.core.compiled import compiled
from amprep.geometry.measure import angles
from amprep.geometry.measure.regularity import min_angles


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a).view(np.int64 if a.dtype == np.float64 else a.dtype)


def _nodes(scale: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Random nodes (NaN one, slivers, repeated corners among the triangles) and triangles over them."""
    rng = np.random.default_rng(11)
    xyz, uv = rng.normal(size=(3000, 3)) * scale, rng.normal(size=(3000, 2))
    tris = rng.integers(0, 3000, size=(60000, 3))
    tris[:50, 1] = tris[:50, 0]  # a zero-length side
    xyz[tris[50:100, 2]] = 0.5 * (xyz[tris[50:100, 0]] + xyz[tris[50:100, 1]])  # collinear: a sliver
    xyz[3] = np.nan
    return xyz, uv, tris


@pytest.mark.parametrize("scale", [1e-6, 1.0, 1e4])
def test_the_kernels_give_numpys_bits(scale):
    xyz, uv, tris = _nodes(scale)
    with compiled(True):
        fast = angles.min_angles_at(xyz, tris), angles.unit_normals_at(xyz, tris)
    assert angles._kernel is not None  # the compiled path ran
    with compiled(False):
        slow = angles.min_angles_at(xyz, tris), angles.unit_normals_at(xyz, tris)
    for a, b in zip(fast, slow, strict=True):
        assert np.array_equal(_bits(a), _bits(b))
    assert np.array_equal(_bits(slow[0]), _bits(min_angles(xyz[tris])))
    rng = np.random.default_rng(3)
    t1, t2 = rng.integers(0, len(tris), 20000), rng.integers(0, len(tris), 20000)
    k1, k2 = rng.integers(0, 3, 20000), rng.integers(0, 3, 20000)
    normals = slow[1]
    with compiled(True):
        a = angles.flip_candidates(xyz, uv, tris, normals, t1, k1, t2, k2)
    with compiled(False):
        b = angles.flip_candidates(xyz, uv, tris, normals, t1, k1, t2, k2)
    for name, x, y in zip(a._fields, a, b, strict=True):
        assert np.array_equal(_bits(x), _bits(y)), name


@pytest.mark.parametrize("on", [True, False])
def test_angles_of_known_triangles(on):
    s = np.sqrt(3) / 2
    xyz = np.array([[0, 0, 0], [1, 0, 0], [0.5, s, 0], [0, 1, 0], [0, 0, 0], [2, 0, 0], [3, 0, 0], [1, 0, 0],
                    [0, 1 / np.sqrt(3), 0]], float)
    tris = np.array([[0, 1, 2],  # equilateral: 60°
                     [0, 1, 3],  # right isosceles: 45°
                     [0, 4, 1],  # a repeated point: 0
                     [0, 5, 6],  # collinear: 0
                     [0, 7, 8]])  # 30-60-90: 30°
    with compiled(on):
        got = np.degrees(angles.min_angles_at(xyz, tris))
        normals = angles.unit_normals_at(xyz, tris)
    assert np.allclose(got, [60, 45, 0, 0, 30], atol=1e-12, rtol=0)
    assert np.allclose(normals, [[0, 0, 1], [0, 0, 1], [0, 0, 0], [0, 0, 0], [0, 0, 1]], atol=1e-15)


@pytest.mark.parametrize("on", [True, False])
def test_flip_candidates_of_a_square_and_a_fold(on):
    # the unit square split along 0-2, then with 1 and 3 raised by 1 (a regular tetrahedron's four corners: each
    # diagonal's pair folded alike, its triangles equilateral)
    xyz = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    uv = xyz[:, :2].copy()
    tris = np.array([[0, 1, 2], [0, 2, 3]])
    for lift, fold in ((0.0, 1.0), (1.0, -1 / 3)):
        nodes = xyz + np.array([0, 0, lift]) * np.array([[0], [1], [0], [1]])
        with compiled(on):
            normals = angles.unit_normals_at(nodes, tris)
            # triangle 0's side 2 (corners 2 → 0) is triangle 1's side 0 (0 → 2)
            f = angles.flip_candidates(nodes, uv, tris, normals, np.array([0]), np.array([2]), np.array([1]),
                                       np.array([0]))
        assert f.new1.tolist() == [[2, 3, 1]] and f.new2.tolist() == [[3, 0, 1]]
        assert f.area1[0] > 0 and f.area2[0] > 0  # both counter-clockwise in (u,v)
        assert np.isclose(f.fold_old[0], fold, atol=1e-12)
        assert np.isclose(f.fold_new[0], fold, atol=1e-12)
        assert np.isclose(np.degrees(f.angle1[0]), 45 if lift == 0 else 60, atol=1e-9)
        assert np.isclose(np.degrees(f.angle2[0]), 45 if lift == 0 else 60, atol=1e-9)
