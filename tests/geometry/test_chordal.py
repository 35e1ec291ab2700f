"""Chordal error against closed-form answers."""

import numpy as np
import pytest

from amprep.geometry.chordal import barycentric_grid, triangle_chordal_error
from amprep.geometry.surfaces import cylinder, plane


def test_grid_has_28_points_at_order_6_and_sums_to_one():
    w = barycentric_grid(6)
    assert w.shape == (28, 3)
    np.testing.assert_allclose(w.sum(axis=1), 1)


@pytest.mark.parametrize("n", [8, 24, 96])
def test_cylinder_strip_error_is_the_sagitta(n):
    """A strip of the cylinder r=10 between two angles 2π/n apart has chordal error r(1 − cos(π/n))."""
    r = 10.0
    s = cylinder(np.zeros(3), np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), np.array([0, 0, 1.0]), r)
    du = 2 * np.pi / n
    uv = np.array([[[0, 0], [du, 0], [du, 5]], [[0, 0], [du, 5], [0, 5]]], float)
    corners = s(uv.reshape(-1, 2)).reshape(-1, 3, 3)
    err = triangle_chordal_error(corners, uv, s, order=12)  # the midline u = du/2 is on the order-12 grid
    np.testing.assert_allclose(err, r * (1 - np.cos(np.pi / n)), rtol=1e-9)


def test_plane_bound_is_zero_on_the_plane_and_the_offset_off_it():
    s = plane(np.array([1.0, 2, 3]), np.array([1.0, 0, 0]), np.array([0, 1.0, 0]))
    uv = np.array([[[0, 0], [1, 0], [0, 1]]], float)
    corners = s(uv.reshape(-1, 2)).reshape(1, 3, 3)
    assert triangle_chordal_error(corners, uv, s, affine=True)[0] == pytest.approx(0, abs=1e-12)
    lifted = corners + [0, 0, 0.25]
    assert triangle_chordal_error(lifted, uv, s, affine=True)[0] == pytest.approx(0.25)
    assert triangle_chordal_error(lifted, uv, s)[0] == pytest.approx(0.25)  # sampling agrees
