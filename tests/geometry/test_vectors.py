"""core.vectors gives numpy's own bits: cross, lengths and normals against np.cross and np.linalg.norm."""

import numpy as np
import pytest

from amprep.geometry.core.vectors import cross, norms, triangle_normals, unit_normals


@pytest.mark.parametrize("shapes", [((500, 3), (500, 3)), ((3,), (3,)), ((4, 6, 3), (4, 6, 3)), ((200, 3), (3,)),
                                    ((3,), (7, 3))])
def test_cross_and_norms_are_numpys_to_the_bit(shapes):
    rng = np.random.default_rng(7)
    a, b = rng.normal(size=shapes[0]) * 1e3, rng.normal(size=shapes[1]) * 1e-2
    assert np.array_equal(cross(a, b), np.cross(a, b))
    assert np.array_equal(norms(a), np.linalg.norm(a, axis=-1))
    ints = rng.integers(-9, 9, size=(20, 3)), rng.integers(-9, 9, size=(20, 3))
    assert np.array_equal(cross(*ints), np.cross(*ints))


def test_unit_normals_of_a_right_triangle_and_a_degenerate_one():
    corners = np.array([[[0, 0, 0], [2, 0, 0], [0, 3, 0]], [[0, 0, 0], [1, 1, 1], [2, 2, 2]]], float)
    assert np.array_equal(triangle_normals(corners), [[0, 0, 6], [0, 0, 0]])
    unit, length = unit_normals(corners)
    assert np.array_equal(unit, [[0, 0, 1], [0, 0, 0]]) and np.array_equal(length, [6, 0])
