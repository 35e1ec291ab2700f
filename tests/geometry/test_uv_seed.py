"""Curvature-sized interior points for meshing a face from scratch (uv_seed) and the fallback mesher that uses them."""

import numpy as np
import pytest

from amprep.geometry.cad.read import read_cad
from amprep.geometry.cad.surfaces import Surface, cylinder, surface_of, torus
from amprep.geometry.cad.topology import Topology
from amprep.geometry.meshing import face_mesher as fallback
from amprep.geometry.meshing import uv_seed
from amprep.geometry.meshing.brepmesh import run_brepmesh
from amprep.geometry.meshing.occt_read import extract_patch
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.uv_cdt import inside_loops, metric_scale
from tests.conftest import boundary_chord_floor, corpus

ORIGIN, X, Y, Z = np.zeros(3), np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), np.array([0, 0, 1.0])


def test_second_form_of_a_cylinder_and_a_torus():
    """Cylinder r=10: |L| = r, M = N = 0. Torus R=20, r=5 at v (tube angle): |L| = (R + r cos v) cos v, N = r."""
    cyl = Surface("cylinder", cylinder(ORIGIN, X, Y, Z, 10.0))
    uv = np.array([[0.3, 2.0], [4.0, -7.0]])
    L, M, N = uv_seed.second_form(cyl, uv, np.array([1e-4, 1e-4]))
    assert np.allclose(np.abs(L), 10, rtol=1e-5) and np.allclose(M, 0, atol=1e-5) and np.allclose(N, 0, atol=1e-5)
    tor = Surface("torus", torus(ORIGIN, X, Y, Z, 20.0, 5.0))
    v = np.array([0.0, 1.0, 2.5])
    L, M, N = uv_seed.second_form(tor, np.stack([np.full(3, 0.7), v], axis=1), np.array([1e-4, 1e-4]))
    assert np.allclose(np.abs(L), np.abs((20 + 5 * np.cos(v)) * np.cos(v)), rtol=1e-5)
    assert np.allclose(M, 0, atol=1e-4) and np.allclose(np.abs(N), 5, rtol=1e-5)


@pytest.mark.parametrize("target", [0.1, 0.01, 0.001])
def test_cells_of_a_cylinder_are_as_wide_as_the_chord_allows_and_uncut_along_the_axis(target):
    """|L| a²/8 ≤ target around the cylinder (a the cells' angle), within SLACK of a whole number of parts; the
    straight direction is never cut (N = 0)."""
    cyl = Surface("cylinder", cylinder(ORIGIN, X, Y, Z, 10.0))
    box = np.array([[0.0, 0.0], [2 * np.pi, 30.0]])
    centers, sizes = uv_seed.size_cells(cyl, box, target)
    assert np.allclose(sizes[:, 1], 30.0)
    allowed = np.sqrt(8 * target / 10.0)
    parts = 2 * np.pi / sizes[:, 0]
    assert np.allclose(parts, np.round(parts)) and (sizes[:, 0] <= allowed * (1 + uv_seed.SLACK / parts) + 1e-12).all()
    needed = 2 * np.pi / allowed
    assert (parts <= 1.1 * needed + 2).all()  # not much finer than the chord needs
    assert np.isclose(sizes.prod(axis=1).sum(), 2 * np.pi * 30.0)  # the cells tile the box


@pytest.mark.parametrize(("need", "cut", "quality_cut"), [(5.04, 5, 6), (2.05, 2, 3), (1.05, 1, 1), (0.9, 1, 1)])
def test_the_quality_mesher_keeps_slack_only_for_whether_a_cell_is_cut(need, cut, quality_cut):
    """A cylinder's box whose angle needs `need` cells by the chord: the default rounds a little over a whole number
    down (SLACK), the quality mesher up, every cell then within the chord (a face of even curvature: every cell the
    same fraction over, all its triangles over); both leave a cell needing under 2 whole (one more would double it)."""
    cyl = Surface("cylinder", cylinder(ORIGIN, X, Y, Z, 10.0))
    target = 0.01
    allowed = np.sqrt(8 * target / 10.0)
    box = np.array([[0.0, 0.0], [need * allowed, 30.0]])
    for leaf_slack, expected in ((False, cut), (True, quality_cut)):
        centers, sizes = uv_seed.size_cells(cyl, box, target, leaf_slack=leaf_slack)
        assert len(sizes) == expected and np.allclose(sizes[:, 0], need * allowed / expected)
    assert need < 2 or (sizes[:, 0] <= allowed).all()


def test_a_fillet_cylinder_is_seeded_within_the_chord_not_mended_by_refinement():
    """occt_top's 1 mm fillets at 0.01 mm (1.412 rad × 31.7 mm) need 5.04 cells around: cut into 5, every cell 0.9 %
    too wide, refinement took the face from 874 triangles to 3,650; cut into 6, it adds a few. Within the tolerance
    by OCCT's distance."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.gp import gp_Ax3, gp_Cylinder, gp_Dir, gp_Pnt

    from amprep.geometry.cad.read import model_from_shape
    from amprep.geometry.meshing.pipeline import mesh_model
    from tests.geometry.test_independent_distance import _worst_distance

    face = BRepBuilderAPI_MakeFace(gp_Cylinder(gp_Ax3(gp_Pnt(0, 0, 0), gp_Dir(0, 0, 1)), 1.0), 0.0, 1.412, 0.0,
                                   31.7).Face()
    seeded = []
    real = fallback.refine_patch

    def spy(patch, error, *args, **kwargs):
        seeded.append(len(error))
        return real(patch, error, *args, **kwargs)

    model = model_from_shape(face)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(fallback, "refine_patch", spy)
        r = mesh_model(model, MeshParams(tolerance=0.01, mesher="quality"))
    assert r.mesh.faces[0].meshed_by == "quality" and len(seeded) == 1
    assert len(r.mesh.triangles) < 1.5 * seeded[0]  # measured: 1,604 from 1,298 (3,650 from 874 before)
    assert r.max_error <= 0.01 and _worst_distance(model, r.mesh, samples=60) <= 0.01 * 1.001


@pytest.fixture(scope="module")
def ctc02_face35():
    """CTC-02's large periodic B-spline face 35 at 0.01 mm: OCCT leaves 15 interior nodes in it and misses the
    tolerance; re-meshed from those it took nine refinement rounds and ~70k triangles."""
    model = read_cad(corpus("nist_ctc02_ap242.stp"))
    run_brepmesh(model.shape, 0.01, MeshParams(tolerance=0.01))
    topo = Topology.of(model.shape)
    face = model.faces[35]
    return face, topo, surface_of(face)


def test_curvature_seeds_mesh_a_large_bspline_face_close_to_the_tolerance_at_once(ctc02_face35, monkeypatch):
    face, topo, surface = ctc02_face35
    tol = 0.0098
    loops = fallback.boundary_loops(face, topo, tol, 0.5)
    uv_loops = [lp["uv"] for lp in loops]
    scale = metric_scale(surface, np.concatenate(uv_loops))
    seeds, stretched = uv_seed.curvature_seeds(surface, uv_loops, tol, scale)
    assert 1000 < len(seeds) < 20000 and not np.allclose(stretched, scale)
    assert inside_loops(seeds * scale, [u * scale for u in uv_loops]).mean() > 0.95
    first = []
    real = fallback.refine_patch

    def spy(patch, error, *args, **kwargs):
        first.append(np.asarray(error))
        return real(patch, error, *args, **kwargs)

    monkeypatch.setattr(fallback, "refine_patch", spy)
    patch = fallback.mesh_face(35, face, topo, surface, tol, 0.5)
    floor = boundary_chord_floor(patch, surface)  # the boundary's chords: no interior point mends them
    assert patch.error.max() <= max(tol, 1.001 * floor)
    assert len(first) == 1 and (first[0] > tol).mean() < 0.35  # cells within SLACK of the target: a few over
    assert len(patch.tris) < 1.5 * len(first[0])  # which refinement mends with a touch
    occt = extract_patch(35, face, topo)
    old_seeds = occt.uv[(occt.node_edge < 0) & (occt.node_vertex < 0)]  # what the re-mesh started from before
    greedy = fallback.mesh_face(35, face, topo, surface, tol, 0.5, seeds=old_seeds, curvature_sized=False)
    assert greedy.error.max() <= max(tol, 1.001 * floor)
    assert len(patch.tris) < 0.5 * len(greedy.tris)  # insertion one point per bad triangle over-refines


def test_refining_in_the_space_the_mesh_was_made_in_converges(ctc02_face35):
    """A curvature-seeded mesh is Delaunay in its stretched (u,v), not in the metric one: re-triangulating regions
    in the metric space flips the neighbours' diagonals and the bad triangles moved along the face for 40 rounds;
    in its own space insertions finish it with a third of the triangles."""
    from amprep.geometry.measure.chordal import triangle_chordal_error
    from amprep.geometry.meshing.local_refine import refine_patch
    from amprep.geometry.meshing.occt_read import FacePatch
    from amprep.geometry.meshing.uv_cdt import triangulate_pslg

    face, topo, surface = ctc02_face35
    tol = 0.0098
    loops = fallback.boundary_loops(face, topo, tol, 0.5)
    uv_loops = [lp["uv"] for lp in loops]
    b_uv = np.concatenate(uv_loops)
    seeds, scale = uv_seed.curvature_seeds(surface, uv_loops, 1.3 * tol, metric_scale(surface, b_uv))
    nb = len(b_uv)
    seg = np.stack([np.arange(nb), np.roll(np.arange(nb), -1)], axis=1)  # face 35 has one wire
    assert len(loops) == 1
    uv = np.concatenate([b_uv, seeds])
    tris = triangulate_pslg(uv * scale, seg)
    tris = tris[inside_loops((uv * scale)[tris].mean(axis=1), [b_uv * scale])]
    xyz = surface.evaluate(uv)
    err = triangle_chordal_error(xyz[tris], uv[tris], surface, 6)
    assert (err > tol).sum() > 100  # seeded for 1.3× the tolerance: work to do
    node = np.full(len(uv), -1)
    node_edge = np.where(np.arange(len(uv)) < nb, 0, -1)
    patch = FacePatch(35, xyz, uv, tris, node, node_edge, np.full(len(uv), np.nan), "fallback", err)
    done = refine_patch(patch, err, surface, tol, 6, scale=scale)
    assert done is not None and done.error.max() <= max(tol, 1.001 * boundary_chord_floor(patch, surface))
    assert len(done.tris) < 3 * len(tris)
    metric = refine_patch(patch, err, surface, tol, 6)  # the same, re-triangulating in metric-scaled (u,v)
    assert metric is None or len(metric.tris) > 1.5 * len(done.tris)  # measured: 55k triangles against 18k


@pytest.mark.parametrize(("major", "minor", "span", "before", "floor"),
                         [(92.5, 1.0, 0.88, 3.27, 9.0), (17.0, 0.5, 2 * np.pi, 1.55, 5.0)])
def test_cells_cut_differently_meet_without_needles(major, minor, span, before, floor):
    """The inner half of a thin torus (OCCT's top.brep has such fillets), off the lattice at 0.1 mm (its tube's edges
    are sized by their angle): the cells either side of its middle were cut into 64 and 56 along it, and their corners
    there interleaved, pairs 0.18 mm apart in cells of 1.3 mm, the smallest angle `before`°. Corners nearer than half a
    cell to an earlier one are dropped (uv_seed.SEED_APART): above `floor`°, within the tolerance by OCCT's distance."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.gp import gp_Ax3, gp_Dir, gp_Pnt, gp_Torus

    from amprep.geometry.cad.read import model_from_shape
    from amprep.geometry.measure.regularity import min_angles
    from amprep.geometry.meshing.pipeline import mesh_model
    from tests.geometry.test_independent_distance import _worst_distance

    axis = gp_Ax3(gp_Pnt(0, 0, 0), gp_Dir(0, 0, 1))
    face = BRepBuilderAPI_MakeFace(gp_Torus(axis, major, minor), 0.0, span, np.pi / 2, np.pi).Face()
    model = model_from_shape(face)
    r = mesh_model(model, MeshParams(tolerance=0.1, mesher="quality"))
    assert r.mesh.faces[0].meshed_by == "quality"
    assert np.degrees(min_angles(r.mesh.vertices[r.mesh.triangles])).min() >= floor > before
    assert r.max_error <= 0.1 and _worst_distance(model, r.mesh, samples=60) <= 0.1 * 1.001
