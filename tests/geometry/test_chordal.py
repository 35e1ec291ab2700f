"""Chordal error against closed-form answers."""

import numpy as np
import pytest

from amprep.geometry.cad.surfaces import cylinder, plane
from amprep.geometry.core.compiled import compiled
from amprep.geometry.measure.chordal import barycentric_grid, triangle_chordal_error


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


def _faces_of(model, mesh):
    from amprep.geometry.cad.surfaces import surface_of

    for f in np.unique(mesh.face_ids):
        sel = mesh.face_ids == f
        yield surface_of(model.faces[int(f)]), mesh.corners[sel], mesh.uv[sel]


def _assert_tilt_cosines(fast, cos):
    """The compiled kernel's tilt cosines (fast[2]) are numpy's `facing` (cos) to 1e-7 on the triangles the tilt check
    screens (grid offset over TILT_SCREEN × the measure; some are, and one is tilted), 1 on the others."""
    from amprep.geometry.measure.chordal import TILT_MAX, TILT_SCREEN

    screened = fast[1] > TILT_SCREEN * fast[0]
    np.testing.assert_allclose(fast[2][screened], cos[screened], rtol=0, atol=1e-7)
    assert (fast[2][~screened] == 1).all()
    return screened.any() and (cos[screened] < TILT_MAX).any()


@pytest.mark.parametrize("source", ["reference", "nist_ctc02_ap242.stp"])
def test_the_compiled_kernel_gives_the_numpy_answer_on_every_surface_kind(reference_solids, source):
    """The fused numba kernels (closed forms; rational B-splines with periodic wrap, CTC-02's face 54) against the
    numpy evaluate-then-project path, on every face, forced on small calls; and they do run there. Their tilt cosines
    (closed-form tangents; the B-spline's by central differences in the kernel) are `facing`'s to 1e-7."""
    from amprep.geometry.cad.read import model_from_shape, read_cad
    from amprep.geometry.measure import chordal
    from amprep.geometry.meshing.params import MeshParams
    from amprep.geometry.meshing.pipeline import mesh_model
    from tests.conftest import corpus

    models = ([model_from_shape(s) for s in reference_solids.values()] if source == "reference"
              else [read_cad(corpus(source))])
    w = barycentric_grid(6)
    chordal.load_kernels()
    kinds, tilted = set(), set()
    for model in models:
        mesh = mesh_model(model, MeshParams(tolerance=0.2)).mesh
        for surf, corners, uv in _faces_of(model, mesh):
            with compiled(True):  # every call of any size takes the compiled path
                fast = chordal._compiled(surf, corners, uv, w)
            with compiled(False):
                slow = chordal._sampled(corners, uv, surf.evaluate, w, None)
            if surf.surface_type in ("plane", "cylinder", "cone", "sphere", "torus", "bspline"):
                assert fast is not None
                kinds.add(surf.surface_type)
                for a, b in zip(fast[:2], slow, strict=True):  # the measure, and the grid points' whole offsets
                    np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9)
                if _assert_tilt_cosines(fast, chordal.facing(corners, uv, surf)):
                    tilted.add(surf.surface_type)
    assert tilted  # the comparison met tilted triangles
    assert kinds >= ({"plane", "cylinder", "cone", "sphere", "torus", "bspline"} if source == "reference"
                     else {"plane", "cylinder", "bspline"})


@pytest.mark.parametrize("kind", ["sphere", "torus", "cone"])
def test_the_compiled_kernels_turn_tables_keep_large_triangles_exact(kind):
    """The compiled closed-form kernel takes a sample's sin and cos from products of three per triangle
    (_chordal_kernel._turns); on triangles up to 6 rad across in u and v, at orders 4, 6 and 12, and with corners off
    the surface, it gives the numpy path's direct sin and cos to rounding, and `facing`'s tilt cosine to 1e-7."""
    import cadquery as cq

    from amprep.geometry.cad.surfaces import surface_of
    from amprep.geometry.measure import chordal

    solid = {"sphere": lambda: cq.Solid.makeSphere(12), "torus": lambda: cq.Solid.makeTorus(20, 5),
             "cone": lambda: cq.Solid.makeCone(8, 3, 10)}[kind]()
    surf = next(s for s in map(surface_of, (f.wrapped for f in solid.Faces())) if s.surface_type == kind)
    rng = np.random.default_rng(7)
    uv = rng.uniform(-3, 3, (3000, 3, 2)) + rng.uniform(-20, 20, (3000, 1, 2))
    corners = surf.evaluate(uv.reshape(-1, 2)).reshape(-1, 3, 3) + rng.normal(0, 0.01, (3000, 3, 3))
    chordal.load_kernels()
    for order in (4, 6, 12):
        with compiled(True):
            fast = chordal._compiled(surf, corners, uv, barycentric_grid(order))
        with compiled(False):
            slow = chordal._sampled(corners, uv, surf.evaluate, barycentric_grid(order), None)
        assert fast is not None
        for a, b in zip(fast[:2], slow, strict=True):
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)
        assert _assert_tilt_cosines(fast, chordal.facing(corners, uv, surf))


@pytest.mark.parametrize("name, tol", [("nist_ctc02_ap242.stp", 0.1), ("nist_ctc02_bspline_ap203.stp", 0.05)])
def test_a_stop_value_bounds_only_triangles_over_it_and_serial_kernels_equal_parallel(name, tol):
    """Every curved face of a real part, measured in one call (the parallel kernels, over BLOCK triangles) and in
    calls of a few triangles (the serial kernels): the same values, bit for bit. With a stop at the median, values
    at or under it are exact, values over it are over it and at most the true ones, and exact_over restores them."""
    from amprep.geometry.cad.read import read_cad
    from amprep.geometry.measure import chordal
    from amprep.geometry.meshing.params import MeshParams
    from amprep.geometry.meshing.pipeline import mesh_model
    from tests.conftest import corpus

    chordal.load_kernels()
    model = read_cad(corpus(name))
    mesh = mesh_model(model, MeshParams(tolerance=tol)).mesh
    checked = 0
    for surf, corners, uv in _faces_of(model, mesh):
        if surf.surface_type not in ("cylinder", "cone", "sphere", "torus", "bspline") or len(corners) < 8:
            continue
        with compiled(True):
            checked += _serial_equals_parallel(surf, corners, uv)
    assert checked, "no face large enough for the parallel kernel"


def _serial_equals_parallel(surf, corners: np.ndarray, uv: np.ndarray) -> bool:  # type: ignore[no-untyped-def]
    """One face measured in one call (the parallel kernels) and in calls of 7 (the serial ones): the same values; with
    a stop at the median, exact at or under it, bounded over it, and exact_over restores them. True when the face is
    over one parallel block."""
    from amprep.geometry.measure import _chordal_kernel, chordal

    full = triangle_chordal_error(corners, uv, surf)
    pieces = np.concatenate([triangle_chordal_error(corners[s:s + 7], uv[s:s + 7], surf)
                             for s in range(0, len(corners), 7)])
    assert np.array_equal(full, pieces)
    stop = float(np.median(full))
    bounded = triangle_chordal_error(corners, uv, surf, stop=stop)
    under = full <= stop
    assert np.array_equal(bounded[under], full[under])
    assert (bounded[~under] > stop).all() and (bounded[~under] <= full[~under]).all()
    nodes, tris = corners.reshape(-1, 3), np.arange(3 * len(corners)).reshape(-1, 3)
    assert np.array_equal(chordal.exact_over(bounded, stop, nodes, uv.reshape(-1, 2), tris, surf), full)
    return len(corners) > _chordal_kernel.BLOCK
