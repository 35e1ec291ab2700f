"""Local refinement of a meshed face: only the neighbourhood of the triangles over tolerance is re-triangulated."""

from dataclasses import replace

import numpy as np
import pytest

from amprep.geometry.cad.read import model_from_shape, read_cad
from amprep.geometry.cad.surfaces import surface_of
from amprep.geometry.cad.topology import Topology
from amprep.geometry.core.checks import check_mesh, manifold3d_accepts
from amprep.geometry.measure.chordal import triangle_chordal_error
from amprep.geometry.meshing import enforce, prepare
from amprep.geometry.meshing.brepmesh import run_brepmesh
from amprep.geometry.meshing.local_refine import refine_patch
from amprep.geometry.meshing.occt_check import patch_error
from amprep.geometry.meshing.occt_read import extract_patch
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.pipeline import mesh_model
from tests.conftest import boundary_chord_floor, corpus


def _edges(tris):
    e = np.sort(np.stack([tris, np.roll(tris, -1, axis=1)], axis=2).reshape(-1, 2), axis=1)
    pairs, count = np.unique(e, axis=0, return_counts=True)
    return {tuple(p) for p in pairs[count == 1]}, count


def _coarse_interior_brepmesh(shape, tol, params, skip=()):
    assert not skip  # these parts have no torus large enough to be left out of BRepMesh
    from OCP.BRepMesh import BRepMesh_IncrementalMesh
    from OCP.BRepTools import BRepTools
    from OCP.IMeshTools import IMeshTools_Parameters

    BRepTools.Clean_s(shape)
    p = IMeshTools_Parameters()
    p.Deflection, p.DeflectionInterior, p.Angle, p.AngleInterior = tol, 3 * tol, params.angular, 3 * params.angular
    BRepMesh_IncrementalMesh(shape, p)


def _uv_area(uv, tris):
    a, b, c = uv[tris[:, 0]], uv[tris[:, 1]], uv[tris[:, 2]]
    return np.abs((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])).sum()


def _occt_patches(shape, tol):
    model = model_from_shape(shape)
    run_brepmesh(model.shape, tol, MeshParams(tolerance=tol))
    topo = Topology.of(model.shape)
    for i, face in enumerate(model.faces):
        surface = surface_of(face)
        patch = extract_patch(i, face, topo)
        yield patch, surface, patch_error(patch, surface, 6)


@pytest.mark.parametrize("name", ["torus", "sphere", "bspline_loft", "cone"])
@pytest.mark.parametrize("fraction", [0.9, 0.4])
def test_refined_patch_is_within_target_and_keeps_boundary_nodes_and_the_rest(reference_solids, name, fraction):
    """OCCT's mesh at 0.1 mm, refined to `fraction` × its own worst error (a few or most triangles over): every
    triangle is then within the target, or its boundary chords' own distance from the surface where that is more (at
    0.4 of the worst the chords kept are over it: their tilted neighbours hid that until triangles over 10° off were
    measured by their distance), on an independent measure, the face's boundary edges are the same node pairs
    (so neighbours still weld), no node moves, a round leaves the triangles away from the bad ones as they were, and the (u,v) area
    is unchanged (no fold, no gap)."""
    for patch, surface, err in _occt_patches(reference_solids[name], 0.1):
        if surface.surface_type == "plane" or len(patch.tris) < 20:
            continue
        target = fraction * err.max()
        bad = err > target
        out = refine_patch(patch, err, surface, target)
        assert out is not None
        measured = triangle_chordal_error(out.nodes[out.tris], out.uv[out.tris], surface, 6, affine=surface.affine)
        floor = boundary_chord_floor(patch, surface)  # the kept boundary's own chords: no insertion mends them
        assert measured.max() <= max(target, 1.001 * floor) and np.allclose(measured, out.error, rtol=0, atol=1e-12)
        k = len(patch.nodes)
        assert np.array_equal(out.nodes[:k], patch.nodes) and np.array_equal(out.uv[:k], patch.uv)
        assert np.array_equal(out.node_edge[:k], patch.node_edge) and (out.node_edge[k:] == -1).all()
        before, _ = _edges(patch.tris)
        after, count = _edges(out.tris)
        assert before == after and count.max() == 2
        near = np.zeros(k, bool)
        near[patch.tris[bad]] = True
        far = patch.tris[~near[patch.tris].any(axis=1)]
        one = refine_patch(patch, err, surface, target, rounds=1)  # the first round touches only the bad's ring
        assert {tuple(t) for t in far} <= {tuple(t) for t in one.tris} and len(one.tris) > len(patch.tris)
        assert _uv_area(out.uv, out.tris) == pytest.approx(_uv_area(patch.uv, patch.tris), rel=1e-9)
        assert out.meshed_by == "refined" and len(out.tris) > len(patch.tris)


@pytest.mark.parametrize("name", ["bspline_loft", "nist_ctc02_ap242.stp"])
def test_forced_local_refinement_gives_closed_solids_within_tolerance(reference_solids, name, monkeypatch):
    """OCCT's face interiors meshed 3× too coarse (edges at the tolerance, so no edge is split) and every face over
    tolerance refined locally, whatever its size or share of bad triangles (the mesher keeps that for large faces
    with few of them): the solid is closed, oriented and within tolerance."""
    monkeypatch.setattr(enforce, "LOCAL_MIN_TRIANGLES", 0)
    monkeypatch.setattr(enforce, "LOCAL_MAX_BAD", 1.0)
    monkeypatch.setattr(prepare, "run_brepmesh", _coarse_interior_brepmesh)
    model = read_cad(corpus(name)) if "." in name else model_from_shape(reference_solids[name])
    r = mesh_model(model, MeshParams(tolerance=0.02))
    assert "refined" in {f.meshed_by for f in r.mesh.faces}
    c = check_mesh(r.mesh)
    assert c.closed and c.degenerate_triangles == 0 and c.volume > 0 and manifold3d_accepts(r.mesh)
    assert r.max_error <= 0.02


def test_large_faces_occt_leaves_over_tolerance_are_mended_not_re_meshed():
    """CTC-02's B-spline face 55 at 0.01 mm with OCCT's own surface deflection control and edges: 87k triangles with 176 over
    the target. It is mended in place (its other triangles kept), so it ends within 1 % of OCCT's count; the part is
    closed and within tolerance."""
    model = read_cad(corpus("nist_ctc02_ap242.stp"))
    params = MeshParams(tolerance=0.01, occt_surface_control=True, occt_edges=True)
    run_brepmesh(model.shape, 0.01, params)
    occt = extract_patch(55, model.faces[55], Topology.of(model.shape))
    r = mesh_model(model, params)
    assert r.mesh.faces[55].meshed_by == "refined" and r.fallback_faces[55] == "tolerance"
    n = int((r.mesh.face_ids == 55).sum())
    assert len(occt.tris) < n < 1.01 * len(occt.tris)
    c = check_mesh(r.mesh)
    assert c.closed and c.degenerate_triangles == 0 and r.max_error <= 0.01


def test_inputs_that_crash_triangle_are_refused_or_cleaned_first():
    """Triangle (C) takes the whole process down on two equal points joined by segments (a face whose boundary
    touches itself in (u,v)) and on a hole point outside the convex hull: triangulate_pslg refuses the first with
    meshing_failed and drops the second; fewer than three points (a sliver face's boundary, 1e-7 mm wide, seen on a
    real IGES) are meshing_failed too, not Triangle's ValueError. Run in a child process, so a crash fails this
    test, not the run."""
    import subprocess
    import sys

    code = """
import numpy as np
from amprep.errors import AmprepError
from amprep.geometry.meshing.uv_cdt import triangulate_pslg
square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
ring = np.array([[0, 1], [1, 2], [2, 3], [3, 0]])
pinched = np.vstack([square, [[0.5, 0.5], [0.5, 0.5]]])
for pts, seg in ((pinched, np.vstack([ring, [[0, 4], [5, 2]]])), (np.vstack([square, [[np.nan, 0]]]), ring),
                 (square[:2], np.array([[0, 1]]))):
    try:
        triangulate_pslg(pts, seg)
        print("accepted")
    except AmprepError as exc:
        print(exc.code.value)
print(len(triangulate_pslg(square, ring, np.array([[5.0, 5.0], [-1.0, 0.5]]))))
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["meshing_failed", "meshing_failed", "meshing_failed", "2"]


def test_flat_triangle_at_an_apex_is_flipped_away_when_the_flip_keeps_the_tolerance(reference_solids):
    """On a cone, (u,v) points on one generator are collinear in space with the apex, whatever the apex node's u:
    the (u,v)-valid triangle (apex, A, B) with A and B on one generator is flat (a zero-area triangle in the STL,
    seen on CTC-02's B-spline twin). Flipping its longest side with the neighbour's gives two proper triangles,
    oriented as before; a flip that would break the tolerance is not made."""
    from amprep.geometry.meshing.local_refine import flat_triangles, flip_flat_triangles
    from amprep.geometry.meshing.occt_read import FacePatch

    model = model_from_shape(reference_solids["cone"])
    face = next(f for f in model.faces if surface_of(f).surface_type == "cone")
    surface = surface_of(face)
    apex = 20 * np.sqrt(1.25)  # v of the apex: the generator's length
    uv = np.array([[0.0, apex], [0.5, apex - 2], [0.5, apex - 1], [-0.5, apex - 2]])  # apex, A, B on u = 0.5, C
    tris = np.array([[0, 1, 2], [1, 0, 3]])  # (apex, A, B) and its neighbour across apex–A
    patch = FacePatch(0, surface.evaluate(uv), uv, tris, np.array([0, -1, -1, -1]), np.full(4, -1),
                      np.full(4, np.nan), error=np.zeros(2))
    assert flat_triangles(patch).tolist() == [True, False]
    fixed = flip_flat_triangles(patch, surface, 1.0)
    assert not flat_triangles(fixed).any() and {frozenset(t) for t in fixed.tris} == {frozenset({0, 3, 2}),
                                                                                       frozenset({3, 1, 2})}
    a, b, c = uv[fixed.tris[:, 0]], uv[fixed.tris[:, 1]], uv[fixed.tris[:, 2]]
    signed = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    assert (signed > 0).all() and 0 < fixed.error.max() <= 1.0
    strict = flip_flat_triangles(patch, surface, 1e-6)  # the flipped pair is off the cone by more than that
    assert flat_triangles(strict).tolist() == [True, False] and np.array_equal(strict.tris, tris)


def test_bspline_twin_at_a_hundredth_is_closed_with_no_flat_triangle():
    """CTC-02's B-spline-only twin at 0.01 mm: its cone-like B-spline faces have apexes, where our refinement made
    three flat triangles before flip_flat_triangles; the part must come out closed, with none, within tolerance."""
    from amprep.geometry.core.checks import float32_degenerate_count

    r = mesh_model(read_cad(corpus("nist_ctc02_bspline_ap203.stp")), MeshParams(tolerance=0.01))
    c = check_mesh(r.mesh)
    assert c.closed and c.degenerate_triangles == 0 and c.volume > 0 and r.max_error <= 0.01
    assert float32_degenerate_count(r.mesh) == 0 and not r.unmeshed_faces


def _sheared_plane():
    """A face on the plane z = 0 parametrised as S(u,v) = (u², v, 0) on [0,1]² (a degree-2 B-spline in u): a triangle
    counter-clockwise in (u,v) can be clockwise in space."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.Geom import Geom_BSplineSurface
    from OCP.gp import gp_Pnt
    from OCP.TColgp import TColgp_Array2OfPnt
    from OCP.TColStd import TColStd_Array1OfInteger, TColStd_Array1OfReal

    poles = TColgp_Array2OfPnt(1, 3, 1, 2)
    for i, x in enumerate((0.0, 0.0, 1.0)):
        for j, y in enumerate((0.0, 1.0)):
            poles.SetValue(i + 1, j + 1, gp_Pnt(x, y, 0.0))
    knots, mults_u, mults_v = TColStd_Array1OfReal(1, 2), TColStd_Array1OfInteger(1, 2), TColStd_Array1OfInteger(1, 2)
    for k, (t, mu, mv) in enumerate(((0.0, 3, 2), (1.0, 3, 2))):
        knots.SetValue(k + 1, t)
        mults_u.SetValue(k + 1, mu)
        mults_v.SetValue(k + 1, mv)
    surface = Geom_BSplineSurface(poles, knots, knots, mults_u, mults_v, 2, 1)
    return BRepBuilderAPI_MakeFace(surface, 1e-7).Face()


def test_a_pair_turned_over_against_each_other_in_space_is_flipped_apart():
    """Two triangles counter-clockwise in (u,v) on a sheared parametrisation, one of them turned over in space (the
    DTMB hull's quality mesh had 97 such pairs at 0.34 mm and 39 crossing pairs): the quality mesher's flips unfold
    them, keeping the (u,v) orientation and the tolerance, and never fold a pair that was not."""
    from amprep.geometry.meshing.local_refine import flip_for_angles
    from amprep.geometry.meshing.occt_read import FacePatch

    surface = surface_of(_sheared_plane())
    # A, B; D above the diagonal AB, C below it; the unfolded pair has a smaller angle (1.3° against 11.9°), so only
    # the unfolding flips it
    uv = np.array([[0.0, 0.0], [1.0, 1.0], [0.211, 0.407], [0.615, 0.594]])
    xyz = surface.evaluate(uv)
    assert np.allclose(xyz[:, 0], uv[:, 0] ** 2) and np.allclose(xyz[:, 2], 0)
    tris = np.array([[0, 1, 2], [0, 3, 1]])

    def normals_z(t):
        c = xyz[t]
        return np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])[:, 2]

    def uv_area(t):
        a, b, c = uv[t[:, 0]], uv[t[:, 1]], uv[t[:, 2]]
        return (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])

    assert (uv_area(tris) > 0).all() and normals_z(tris)[0] > 0 > normals_z(tris)[1]  # folded in space
    none = np.full(4, -1, np.int64)
    patch = FacePatch(0, xyz, uv, tris, none, none, np.full(4, np.nan), meshed_by="quality", error=np.zeros(2))
    out = flip_for_angles(patch, surface, tolerance=0.01)
    assert (uv_area(out.tris) > 0).all()
    assert (normals_z(out.tris) > 0).all(), "still turned over"
    assert sorted(map(tuple, np.sort(out.tris, axis=1))) == [(0, 2, 3), (1, 2, 3)]
    assert (triangle_chordal_error(xyz[out.tris], uv[out.tris], surface, 6) <= 0.01).all()
    # the unfolded pair: no flip folds it back, whatever the angles would gain
    again = flip_for_angles(out, surface, tolerance=0.01)
    assert (normals_z(again.tris) > 0).all()


def test_the_dtmb_hull_quality_mesh_does_not_cross_itself():
    """DTMB 5415's bow hull (one B-spline face whose (u,v) shears under the triangles): the quality mesher's output at
    0.34 mm has no pair of triangles crossing each other (39 before the flips unfolded turned-over pairs)."""
    from amprep.geometry.measure.defects import self_intersections

    mesh = mesh_model(read_cad(corpus("dtmb5415_bow_hull.iges")), MeshParams(tolerance=0.34, mesher="quality")).mesh
    assert self_intersections(mesh)[0] == 0


def test_a_quality_face_its_refinement_cannot_bring_within_is_meshed_by_the_default_mesher(monkeypatch):
    """Forced: the quality mesher's local refinement stops short everywhere (its patch handed back unrefined, as when
    every insertion point is nearer than the spacing to a node), so each round meets the same mesh again. After three
    rounds over, such a face is meshed as the default mesher meshes its own faces, within the tolerance, and listed
    in fallback_faces as quality_refinement; the solid stays closed."""
    from dataclasses import replace

    from amprep.geometry.meshing import face_mesher, lattice

    def stops_short(real):
        def refine(patch, error, *args, **kwargs):
            if patch.meshed_by in ("quality", "lattice"):
                return replace(patch, error=np.asarray(error, float))
            return real(patch, error, *args, **kwargs)
        return refine

    for module in (face_mesher, lattice, enforce):
        monkeypatch.setattr(module, "refine_patch", stops_short(module.refine_patch))
    tol = 0.34
    r = mesh_model(read_cad(corpus("featuretype_inch_ap214.step"), "step"),
                   MeshParams(tolerance=tol, mesher="quality", parallel=False))
    plain = sorted(i for i, why in r.fallback_faces.items() if why == "quality_refinement")
    assert len(plain) >= 5  # the faces whose first quality mesh had a triangle over (18 on this part)
    assert all(r.mesh.faces[i].meshed_by == "fallback" for i in plain)
    assert (r.face_error[plain] <= tol).all()
    c = check_mesh(r.mesh)
    assert c.closed and c.degenerate_triangles == 0 and manifold3d_accepts(r.mesh)
    assert r.max_error <= tol


def test_the_flips_side_table_updated_in_place_equals_one_built_afresh():
    """flip_for_angles keeps its side table across passes, rewriting only the flipped triangles' rows
    (local_refine._repacked); after any rewrites it must equal the table sorted afresh, so the flips are the same."""
    from amprep.geometry.meshing.local_refine import _packed_sides, _pairs, _repacked, _shared_sides

    rng = np.random.default_rng(7)
    tris = rng.integers(0, 400, (3000, 3))
    packed = _packed_sides(tris, 400)
    for _ in range(25):
        changed = np.unique(rng.integers(0, len(tris), 60))
        tris[changed] = rng.integers(0, 400, (len(changed), 3))
        packed = _repacked(packed, tris, changed, 400)
        assert np.array_equal(packed, _packed_sides(tris, 400))
        assert all(np.array_equal(a, b) for a, b in zip(_pairs(packed, 3 * len(tris)), _shared_sides(tris, 400)))


def _sphere_patch(tol: float):  # type: ignore[no-untyped-def]
    """OCCT's mesh of a sphere r 10 about the origin at tol: its face's (patch, surface, error)."""
    import cadquery as cq

    for patch, surface, err in _occt_patches(cq.Solid.makeSphere(10.0).wrapped, tol):
        if surface.surface_type == "sphere":
            return patch, surface, err
    raise AssertionError("no sphere face")


def _off_sphere(corners: np.ndarray, order: int) -> np.ndarray:
    """(m,) the largest distance from the sphere r 10 about the origin, in closed form, of the points of each triangle
    (corners (m, 3, 3)) on its barycentric grid of `order`."""
    w = np.array([[a, b, order - a - b] for a in range(order + 1) for b in range(order + 1 - a)]) / order
    return np.abs(np.linalg.norm(np.einsum("pk,mkd->mpd", w, corners), axis=-1) - 10.0).max(axis=1)


def test_triangles_over_by_their_boundary_nodes_alone_are_left_as_they_are(monkeypatch):
    """A sphere whose boundary nodes (seam, poles) stand 3× the tolerance off it, radially (a B-rep gap): no point
    inserted inside lowers the triangles standing on them, since the measure counts their corners. They are left as
    they are, with no round of insertions (refined regardless, each node's fan grew round after round). Checked by
    closed-form distance from the sphere: the triangles off the moved nodes are within, and were left."""
    from amprep.geometry.meshing import local_refine

    tol = 0.1
    patch, surface, _ = _sphere_patch(tol)
    boundary = (patch.node_edge >= 0) | (patch.node_vertex >= 0)
    nodes = patch.nodes.copy()
    nodes[boundary] += 3 * tol * nodes[boundary] / 10.0
    moved = replace(patch, nodes=nodes)
    err = triangle_chordal_error(nodes[patch.tris], patch.uv[patch.tris], surface, 6)
    touching = boundary[patch.tris].any(axis=1)
    assert (err > tol).any() and (err[~touching] <= tol).all()
    rounds = []
    real = local_refine._retriangulate
    monkeypatch.setattr(local_refine, "_retriangulate", lambda *args: rounds.append(1) or real(*args))
    out = refine_patch(moved, err, surface, tol)
    assert out is not None and not rounds and np.array_equal(out.tris, patch.tris)
    distance = _off_sphere(nodes[patch.tris], 6)
    assert (distance[~touching] <= tol).all() and np.allclose(out.error, err, rtol=1e-9, atol=0)


def test_corners_on_the_surface_whose_uv_is_off_are_refined_not_left():
    """A sphere whose seam nodes are moved along the seam, on the sphere, their (u,v) kept (a pcurve a way from its
    3D curve along the face, as IGES files have): measured along OCCT's triangles' normals such a corner is off by
    over the tolerance, yet no point of the face is, so it is not left as a B-rep gap's corner is (judged by those
    normals, four faces of OCCT's hammer.brep were). Refined, every triangle comes within the tolerance, checked by
    closed-form distance from the sphere; the moved nodes stay where they are."""
    tol = 0.1
    patch, surface, _ = _sphere_patch(tol)
    seam = (patch.node_edge >= 0) & (np.abs(np.cos(patch.uv[:, 1])) > 1e-9)  # not the poles
    u, v = patch.uv[seam, 0], patch.uv[seam, 1]
    v = v + 0.2 * np.cos(v)  # monotone along the seam (v' = 1 − 0.2 sin v > 0): up to 2 mm, the poles fixed
    nodes = patch.nodes.copy()
    nodes[seam] = 10.0 * np.stack([np.cos(v) * np.cos(u), np.cos(v) * np.sin(u), np.sin(v)], axis=1)
    assert np.allclose(np.linalg.norm(surface.evaluate(patch.uv[seam]), axis=1), 10.0)  # the frame: r 10, origin
    moved = replace(patch, nodes=nodes)
    err = triangle_chordal_error(nodes[patch.tris], patch.uv[patch.tris], surface, 6)
    touching = seam[patch.tris].any(axis=1)
    assert (err[touching] > tol).sum() >= 5  # the corners' offsets, measured along the triangles' normals
    out = refine_patch(moved, err, surface, tol)
    assert out is not None and len(out.tris) > len(patch.tris)
    assert np.array_equal(out.nodes[: len(nodes)], nodes)
    assert (out.error <= tol).all()
    assert _off_sphere(out.nodes[out.tris], 12).max() <= tol
