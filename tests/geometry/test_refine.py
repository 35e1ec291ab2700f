"""SMA and VTA on exact parts: the facet-count rule, closedness, the error drop, the report and the CLI."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import jsonschema
import numpy as np
import pytest

from amprep.errors import AmprepError
from amprep.geometry.cad.read import model_from_shape
from amprep.geometry.cad.surfaces import Surface, surface_of
from amprep.geometry.core.checks import check_mesh, manifold3d_accepts
from amprep.geometry.core.edges import face_edge_table
from amprep.geometry.core.mesh import Mesh
from amprep.geometry.io.stl import read_stl
from amprep.geometry.measure.analysis import face_chordal_errors
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.pipeline import mesh_model
from amprep.geometry.refine.compare import RefineParams
from amprep.geometry.refine.sma import Ratios, sma_refine
from amprep.geometry.refine.vta import vta_refine
from amprep.jobs.refine import refine_file
from tests.conftest import corpus


def _euler(mesh: Mesh) -> int:
    t = mesh.triangles
    e = np.unique(np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1), axis=0)
    return len(np.unique(t)) - len(e) + len(t)


def _coarse(shape, tol=0.2):
    model = model_from_shape(shape)
    mesh = mesh_model(model, MeshParams(tolerance=tol)).mesh
    return mesh, {i: surface_of(f) for i, f in enumerate(model.faces)}


def _curved(surfaces):
    return [i for i, s in surfaces.items() if s.surface_type != "plane"]


def _cross_drilled_cylinder():
    import cadquery as cq

    body = cq.Workplane("XY").cylinder(30, 10)
    return body.cut(cq.Workplane("YZ").cylinder(30, 3)).val().wrapped


@pytest.mark.parametrize("name", ["cylinder", "sphere", "torus", "bspline_loft", "cone", "filleted_block"])
def test_sma_keeps_the_part_closed_follows_the_count_rule_and_cuts_the_error(reference_solids, name):
    mesh, surfaces = _coarse(reference_solids[name])
    faces = _curved(surfaces)
    r = sma_refine(mesh, faces, surfaces)
    out = r.mesh
    before, after = check_mesh(mesh), check_mesh(out)
    assert before.closed and after.closed and manifold3d_accepts(out)
    assert after.degenerate_triangles == 0 and after.duplicate_triangles == 0
    assert _euler(out) == _euler(mesh)  # same genus (the torus: 0): no T-junction, no hole, no extra handle
    assert after.volume == pytest.approx(before.volume, rel=0.05) and after.volume > 0
    e0, e1 = face_chordal_errors(mesh, surfaces, 6), face_chordal_errors(out, surfaces, 6)
    for f in faces:
        cats = r.categories[f]
        assert sum(cats) == (mesh.face_ids == f).sum()
        assert (out.face_ids == f).sum() == sum(n * (27 + 2 * k) for k, n in enumerate(cats))
        assert e1[out.face_ids == f].mean() <= 0.3 * e0[mesh.face_ids == f].mean()
    untouched = ~np.isin(mesh.face_ids, faces)
    assert (out.face_ids[~np.isin(out.face_ids, faces)] == mesh.face_ids[untouched]).all()
    # every new vertex lies on its face's exact surface
    new = np.arange(mesh.n_vertices, out.n_vertices)
    assert len(new) and np.isin(out.vertex_entity[new], faces).all()


def test_sma_on_a_face_with_holes_and_a_seam():
    mesh, surfaces = _coarse(_cross_drilled_cylinder())
    side = [i for i, s in surfaces.items() if s.surface_type == "cylinder" and s.data["radius"] == pytest.approx(10)]
    assert len(side) == 1
    _, inner = face_edge_table(mesh)
    r = sma_refine(mesh, side, surfaces)
    after = check_mesh(r.mesh)
    assert check_mesh(mesh).closed and after.closed and after.degenerate_triangles == 0
    assert _euler(r.mesh) == _euler(mesh)
    assert r.categories[side[0]][1] > 0  # triangles along the holes' and the caps' contour edges


def test_one_triangle_per_category_and_shared_edge_points():
    """A flat square face of two triangles: the diagonal is inner (Type I, shared points), the four sides are
    contour (Type II, intact): each triangle has 2 contour edges → 31 triangles, and the square's outline stays
    the four original edges."""
    v = np.array([[0, 0, 0], [10, 0, 0], [10, 10, 0], [0, 10, 0]], float)
    t = np.array([[0, 1, 2], [0, 2, 3]])
    uv = v[t][:, :, :2].copy()
    plane = Surface("plane", lambda q: np.column_stack([q, np.zeros(len(q))]))
    mesh = Mesh(v, t, np.zeros(2, np.int32), uv)
    r = sma_refine(mesh, [0], {0: plane})
    assert r.mesh.n_triangles == 2 * 31 and r.categories[0] == [0, 0, 2, 0]
    c = check_mesh(r.mesh)
    assert c.boundary_edges == 4 and c.nonmanifold_edges == 0 and c.misoriented_edges == 0
    assert c.degenerate_triangles == 0 and c.area == pytest.approx(100)
    assert _euler(r.mesh) == 1  # a disc
    new = r.mesh.vertices[4:]
    on_diagonal = np.abs(new[:, 0] - new[:, 1]) < 1e-12
    assert on_diagonal.sum() == 2  # the two shared points of the inner edge, once each
    assert np.allclose(np.sort(new[on_diagonal, 0]), [3, 7])  # p:q:p = 3:4:3 along the diagonal
    # a single triangle whose three edges are contour: 33
    r1 = sma_refine(Mesh(v, t[:1], np.zeros(1, np.int32), uv[:1]), [0], {0: plane})
    assert r1.mesh.n_triangles == 33 and check_mesh(r1.mesh).boundary_edges == 3


def test_sma_on_a_sheared_parametrisation_turns_no_triangle_over_and_keeps_shared_points_shared():
    """A flat sheet S(u,v) = (u² + u/20, v, 0): (u,v) crowds toward x = 0, so the (u,v) centroid of the triangle
    (0, ½) (1, 0) (1, 1) lands at x = 0.48 while its corners' centroid in space is at 0.70, and four of its 33
    children turn over (their area counted twice). Its face's points are placed in space instead: no child turned,
    the area the sheet's, the edge it shares with its neighbour split at the same two points from both sides."""
    sheared = Surface("bspline", lambda q: np.column_stack([q[:, 0] ** 2 + q[:, 0] / 20, q[:, 1], np.zeros(len(q))]),
                      bounds=(0.0, 1.0, 0.0, 1.0))
    uv = np.array([[0, 0.5], [1, 0], [1, 1], [2, 0.5]], float)
    t = np.array([[0, 1, 2], [1, 3, 2]])
    mesh = Mesh(sheared.evaluate(uv), t, np.zeros(2, np.int32), uv[t])
    r = sma_refine(mesh, [0], {0: sheared}).mesh
    assert r.n_triangles == 62
    c = r.corners
    assert (np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])[:, 2] > 0).all()  # every child faces up, as the sheet
    checks = check_mesh(r)
    assert checks.area == pytest.approx(check_mesh(mesh).area, rel=1e-12)
    assert checks.boundary_edges == 4 and checks.nonmanifold_edges == 0 and checks.misoriented_edges == 0
    on_edge = np.abs(r.vertices[:, 0] - 1.05) < 1e-9  # the shared edge (1, 0)-(1, 1): its points at 3/10, 7/10
    assert np.allclose(np.sort(r.vertices[on_edge, 1]), [0, 0.3, 0.7, 1])


def test_sma_places_a_sheared_face_in_space_past_a_triangle_of_no_area_in_uv():
    """A face placed in space (one child turned over) may hold a triangle whose (u,v) corners are on one line, as at
    a pole: its points stay where (u,v) put them instead of stopping the refinement on a singular matrix."""
    sheared = Surface("bspline", lambda q: np.column_stack([q[:, 0] ** 2 + q[:, 0] / 20, q[:, 1], np.zeros(len(q))]),
                      bounds=(0.0, 1.0, 0.0, 1.0))
    uv = np.array([[0, 0.5], [1, 0], [1, 1], [2, 0.5], [3, 0], [3, 0.5], [3, 1]], float)
    t = np.array([[0, 1, 2], [1, 3, 2], [4, 5, 6]])
    r = sma_refine(Mesh(sheared.evaluate(uv), t, np.zeros(3, np.int32), uv[t]), [0], {0: sheared}).mesh
    assert r.n_triangles == 62 + 33 and np.isfinite(r.vertices).all()
    c = r.corners[:62]  # the two sheared triangles' children (kept in their parents' order) all face up
    assert (np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])[:, 2] > 0).all()


def test_ratios_are_parsed_and_checked():
    r = Ratios.parse("1:2:1,2:1:2")
    assert r.spoke_fractions == (0.25, 0.75) and r.edge_fractions == (0.4, 0.6)
    for bad in ("3:4:3", "3:4:3,3:4:2", "1:8:1,3:4:3", "a:b:c,1:1:1", "0:1:1,1:1:1"):
        with pytest.raises(AmprepError) as e:
            Ratios.parse(bad)
        assert e.value.code.value == "invalid_parameter"


def test_vta_splits_each_triangle_in_three_per_iteration_and_stays_closed(reference_solids):
    mesh, surfaces = _coarse(reference_solids["torus"])
    r1 = vta_refine(mesh, [0], surfaces, iterations=1)
    r2 = vta_refine(mesh, [0], surfaces, iterations=2)
    assert r1.mesh.n_triangles == 3 * mesh.n_triangles and r2.mesh.n_triangles == 9 * mesh.n_triangles
    for r in (r1, r2):
        c = check_mesh(r.mesh)
        assert c.closed and c.degenerate_triangles == 0 and manifold3d_accepts(r.mesh)
    e0, e2 = face_chordal_errors(mesh, surfaces, 6), face_chordal_errors(r2.mesh, surfaces, 6)
    assert e2.mean() < e0.mean()
    r_thr = vta_refine(mesh, [0], surfaces, iterations=1, threshold=float(np.median(e0)))
    assert mesh.n_triangles < r_thr.mesh.n_triangles < 3 * mesh.n_triangles


def test_refine_report_selects_by_threshold_and_brackets_the_file_size(tmp_path, reference_solids):
    from OCP.BRepTools import BRepTools

    shape = reference_solids["filleted_block"]
    path = tmp_path / "block.brep"
    BRepTools.Write_s(shape, str(path))
    params = MeshParams(tolerance=0.2, occt_edges=True)  # OCCT's edges: only the sphere corners' mean is over 0.03
    r = refine_file(path, None, params, RefineParams(max_chordal=0.03))
    rep = r.report
    jsonschema.validate(rep, json.loads((Path(__file__).resolve().parents[2] / "schemas" / "report.schema.json").read_text(encoding="utf-8")))
    chosen = {f["id"] for f in rep["refined_faces"]}
    assert chosen and all(f["surface_type"] == "sphere" for f in rep["refined_faces"])  # corners: 0.042 > 0.03
    for f in rep["refined_faces"]:
        assert f["reason"].startswith("mean chordal error") and f["chordal_error_before"]["mean"] > 0.03
        assert set(f["categories"]) == {"0", "1", "2", "3"}
        assert f["triangles_after"] == sum(n * (27 + 2 * int(k)) for k, n in f["categories"].items())
        assert f["chordal_error_after"]["mean"] <= 0.3 * f["chordal_error_before"]["mean"]
        assert {"cusp_height_before", "cusp_height_after", "cylindricity_before", "cylindricity_after"} <= set(f)
    assert rep["mesh"]["watertight"] and rep["mesh_before"]["watertight"] and rep["issues"] == []
    cmp_ = rep["comparison"]
    sizes = [u["file_size"] for u in cmp_["uniform"]]
    assert min(sizes) <= cmp_["refined"]["file_size"] <= max(sizes)
    assert cmp_["refined"]["file_size"] == 84 + 50 * rep["mesh"]["triangles"]
    assert cmp_["refined"]["chordal_error"]["mean"] < cmp_["before"]["chordal_error"]["mean"]
    assert cmp_["other_method"]["label"].startswith("VTA")
    none = refine_file(path, None, params, RefineParams(max_chordal=10.0, compare=False))
    assert none.report["refined_faces"] == [] and none.mesh.n_triangles == r.before.n_triangles
    assert none.report["issues"][0]["code"] == "nothing_to_refine"
    named = refine_file(path, None, params, RefineParams(method="vta", faces=(1,), compare=False))
    assert [f["id"] for f in named.report["refined_faces"]] == [1] and named.report["refined_faces"][0]["reason"] == "named"
    with pytest.raises(AmprepError) as e:
        refine_file(path, None, params, RefineParams(faces=(999,)))
    assert e.value.code.value == "invalid_parameter"


def test_refine_cli_on_the_users_stl_writes_it_back_in_its_frame(tmp_path):
    out, report = tmp_path / "refined.stl", tmp_path / "r.json"
    stl = corpus("voron_vhb_din_mount.stl")
    r = subprocess.run([sys.executable, "-m", "amprep", "refine", str(corpus("voron_vhb_din_mount.step")), "--stl",
                        str(stl), "-o", str(out), "--max-chordal", "0.001", "--report", str(report),
                        "--out-dir", str(tmp_path / "all"), "--quiet"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    rep = json.loads(report.read_text())
    refined, original = read_stl(out), read_stl(stl)
    assert check_mesh(refined).closed and refined.n_triangles == rep["mesh"]["triangles"] > original.n_triangles
    assert np.allclose(refined.bbox()[0], original.bbox()[0], atol=0.02)
    assert np.allclose(refined.bbox()[1], original.bbox()[1], atol=0.02)
    assert rep["alignment"]["inlier_fraction"] > 0.6 and rep["refined_faces"]
    assert {"refined.stl", "report.json", "chordal_error.f32", "error_vs_size.png"} <= {
        p.name for p in (tmp_path / "all").iterdir()}
    bad = subprocess.run([sys.executable, "-m", "amprep", "refine", str(stl), "-o", str(tmp_path / "x.stl")],
                         capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and bad.stderr.startswith("amprep: error [invalid_parameter]")


def test_refine_cli_summary_on_an_ascii_terminal(tmp_path):
    import os

    r = subprocess.run([sys.executable, "-m", "amprep", "refine", str(corpus("cq_cube_cylinder_colors.step")), "-o",
                        str(tmp_path / "r.stl"), "--method", "vta", "--iterations", "2", "--no-compare"],
                       capture_output=True, timeout=300, env=os.environ | {"PYTHONIOENCODING": "ascii"})
    assert r.returncode == 0, r.stderr
    assert b"refined by VTA" in r.stdout and re.search(rb"\d+ \? \d+ triangles", r.stdout)


def test_a_refinement_over_the_triangle_limit_is_refused_before_it_runs(tmp_path, reference_solids):
    from OCP.BRepTools import BRepTools

    from amprep.geometry.refine.compare import predicted_size
    from amprep.geometry.refine.sma import sma_output_size

    mesh, surfaces = _coarse(reference_solids["torus"])
    assert sma_output_size(mesh, [0]) == sma_refine(mesh, [0], surfaces).mesh.n_triangles
    assert predicted_size("vta", mesh, np.array([0]), 2) == vta_refine(mesh, [0], surfaces, 2).mesh.n_triangles
    path = tmp_path / "torus.brep"
    BRepTools.Write_s(reference_solids["torus"], str(path))
    for params in (RefineParams(method="vta", iterations=50), RefineParams(max_triangles=10_000)):
        with pytest.raises(AmprepError) as e:
            refine_file(path, None, MeshParams(tolerance=0.2), params)
        assert e.value.code.value == "output_too_large"
    limit = 3 * mesh.n_triangles  # VTA × 1 fits exactly, the SMA comparison (27×) does not: it is left out
    r = refine_file(path, None, MeshParams(tolerance=0.2), RefineParams(method="vta", max_triangles=limit))
    assert r.report["comparison"]["other_method"] is None and r.mesh.n_triangles == limit


@pytest.mark.parametrize("name, occt_edges", [("cone", False), ("cone", True), ("sphere", False)])
@pytest.mark.parametrize("by_sagitta", [True, False])
def test_adaptive_splits_edges_to_a_pole_along_them(reference_solids, name, occt_edges, by_sagitta):
    """A cone's apex and a sphere's poles are one vertex with a different (u,v) corner in each triangle. An edge to
    the pole is split at its other end's free coordinate (on the ruling or meridian the edge follows, not at the
    pole corner's arbitrary u), and each pole corner sits between its triangle's two others: no triangle joins the
    pole to two points of one ruling (a flat triangle once made on the cone), and no round folds the (u,v) near it.
    Longest-edge splitting (by_sagitta off) splits edges to the pole all the time."""
    from amprep.geometry.cad.edge_curves import EdgeCurves
    from amprep.geometry.refine.adaptive import adaptive_refine, pole_vertices

    model = model_from_shape(reference_solids[name])
    mesh = mesh_model(model, MeshParams(tolerance=0.2, occt_edges=occt_edges)).mesh
    surfaces = {i: surface_of(f) for i, f in enumerate(model.faces)}
    faces = np.array(_curved(surfaces))
    poles = pole_vertices(mesh.vertices, mesh.triangles, mesh.uv, mesh.face_ids, mesh.vertex_dim, surfaces, faces)
    assert len(poles) == (1 if name == "cone" else 2)
    r = adaptive_refine(mesh, faces, surfaces, 0.005, curves=EdgeCurves(model), by_sagitta=by_sagitta)
    c = check_mesh(r.mesh)
    assert c.closed and c.degenerate_triangles == 0 and manifold3d_accepts(r.mesh)
    # error ∝ h², so 40× less error needs ~40× the triangles; a fold at the pole ran away to 60,000×. The start is
    # BRepMesh's grid's size: the default mesher's cone is a fan (face_mesher.ruled_patch), whose few long triangles
    # need as many
    first = mesh_model(model, MeshParams(tolerance=0.2, occt_edges=occt_edges, enforce_tolerance=False)).mesh
    assert r.mesh.n_triangles < 3 * (0.2 / 0.005) * max(mesh.n_triangles, first.n_triangles)
    err = face_chordal_errors(r.mesh, surfaces, 6)
    assert err[np.isin(r.mesh.face_ids, faces)].max() <= 0.005


@pytest.mark.parametrize("name", ["cylinder", "sphere", "torus", "cone", "bspline_loft", "plate_with_holes"])
def test_adaptive_reaches_the_target_on_every_triangle_with_fewer_triangles_than_sma(reference_solids, name):
    from amprep.geometry.cad.edge_curves import EdgeCurves
    from amprep.geometry.core.mesh import ON_BREP_EDGE
    from amprep.geometry.refine.adaptive import adaptive_refine

    model = model_from_shape(reference_solids[name])
    mesh = mesh_model(model, MeshParams(tolerance=0.2)).mesh
    surfaces = {i: surface_of(f) for i, f in enumerate(model.faces)}
    faces = _curved(surfaces)
    target = 0.01
    r = adaptive_refine(mesh, faces, surfaces, target, curves=EdgeCurves(model))
    out = r.mesh
    c = check_mesh(out)
    assert c.closed and manifold3d_accepts(out) and c.degenerate_triangles == 0 and _euler(out) == _euler(mesh)
    err = face_chordal_errors(out, surfaces, 6)
    on = np.isin(out.face_ids, faces)
    assert err[on].max() <= target  # contour edges were split too, on both sides, on the exact B-rep edge
    assert on.sum() < (sma_refine(mesh, faces, surfaces).mesh.face_ids >= 0).sum()
    new = np.arange(mesh.n_vertices, out.n_vertices)
    on_edge = new[out.vertex_dim[new] == ON_BREP_EDGE]
    if name in ("cylinder", "cone", "plate_with_holes"):  # circles bounding the curved faces got new points
        assert len(on_edge)
        from OCP.BRepAdaptor import BRepAdaptor_Curve
        from OCP.TopoDS import TopoDS

        curves = EdgeCurves(model)
        for v in on_edge[:20]:
            e = TopoDS.Edge_s(curves.topo.edges.FindKey(int(out.vertex_entity[v]) + 1))
            assert np.allclose(BRepAdaptor_Curve(e).Value(float(out.vertex_param[v])).Coord(), out.vertices[v], atol=1e-9)


def test_adaptive_without_b_rep_edges_leaves_contour_edges_whole(reference_solids):
    """The user-STL case (no B-rep edge behind the vertices): only inner edges are split, the other faces' triangles
    are untouched, and triangles whose error is their contour edge's own sagitta are left alone."""
    from dataclasses import replace

    from amprep.geometry.refine.adaptive import adaptive_refine

    mesh, surfaces = _coarse(reference_solids["sphere"])
    no_topology = replace(mesh, vertex_dim=None, vertex_entity=None, vertex_param=None)
    r = adaptive_refine(no_topology, [0], surfaces, 0.01)
    assert check_mesh(r.mesh).closed
    assert face_chordal_errors(r.mesh, surfaces, 6).max() <= 0.01  # a sphere has no contour edge to limit it
    block, bsurf = _coarse(reference_solids["filleted_block"])
    curved = _curved(bsurf)
    r = adaptive_refine(replace(block, vertex_dim=None, vertex_entity=None, vertex_param=None), curved, bsurf, 0.005)
    flat_before = np.sort(block.triangles[~np.isin(block.face_ids, curved)], axis=1)
    flat_after = np.sort(r.mesh.triangles[~np.isin(r.mesh.face_ids, curved)], axis=1)
    assert np.array_equal(np.unique(flat_before, axis=0), np.unique(flat_after, axis=0))
    assert check_mesh(r.mesh).closed and r.mesh.n_triangles > block.n_triangles


def test_refine_adaptive_report(tmp_path, reference_solids):
    from OCP.BRepTools import BRepTools

    path = tmp_path / "plate.brep"
    BRepTools.Write_s(reference_solids["plate_with_holes"], str(path))
    r = refine_file(path, None, MeshParams(tolerance=0.2), RefineParams(method="adaptive", target=0.005))
    rep = r.report
    jsonschema.validate(rep, json.loads((Path(__file__).resolve().parents[2] / "schemas" / "report.schema.json").read_text(encoding="utf-8")))
    assert rep["method"] == "adaptive" and rep["params"]["target"] == 0.005 and rep["mesh"]["watertight"]
    assert all(f["chordal_error_after"]["max"] <= 0.005 for f in rep["refined_faces"])
    assert rep["comparison"]["other_method"]["label"] == "SMA"
    assert rep["comparison"]["refined"]["triangles"] < rep["comparison"]["other_method"]["triangles"]


def test_adaptive_on_real_edges_that_wrap_a_periodic_face_and_stray_from_their_pcurves():
    """NIST CTC-02: face 54 is a periodic B-spline whose boundary edge winds once round it (its pcurve runs a whole
    period, its two B-rep vertices 1e-5 mm apart) and face 35's edge strays 0.006 mm from its pcurve: every contour
    split must land on the right period and the right end, so the error falls under the target on every triangle,
    the part stays closed and no B-rep edge point is made twice."""
    from amprep.geometry.cad.edge_curves import EdgeCurves
    from amprep.geometry.cad.read import read_cad
    from amprep.geometry.core.mesh import ON_BREP_EDGE
    from amprep.geometry.refine.adaptive import adaptive_refine

    model = read_cad(corpus("nist_ctc02_ap242.stp"))
    mesh = mesh_model(model, MeshParams(tolerance=0.2)).mesh
    faces = [35, 54]
    surfaces = {i: surface_of(f) for i, f in enumerate(model.faces)}
    target = 0.02
    out = adaptive_refine(mesh, faces, surfaces, target, curves=EdgeCurves(model)).mesh
    err, err0 = face_chordal_errors(out, surfaces, 6), face_chordal_errors(mesh, surfaces, 6)
    assert err[np.isin(out.face_ids, faces)].max() <= target < err0[np.isin(mesh.face_ids, faces)].max()
    c = check_mesh(out)
    assert c.closed and c.degenerate_triangles == 0 and out.n_triangles > mesh.n_triangles
    on = out.vertex_dim == ON_BREP_EDGE
    pairs = np.stack([out.vertex_entity[on], out.vertex_param[on]], axis=1)
    assert len(np.unique(pairs, axis=0)) == len(pairs)


def test_adaptive_puts_no_point_beyond_a_faces_trim():
    """A cylinder r = 10 cut by a plane tilted 30°: the side face's (u,v) boundary at the cut is a cosine, concave
    where it dips, so an edge between two of its 0.5 mm mesh's nodes can have its (u,v) midpoint beyond the trim (CTC-02's
    mitred fillets: such points crossed the next fillet's triangles, 29 pairs). With the face's domain no new vertex
    is off the solid (OCCT's distance); without it some are."""
    import math

    from OCP.BRepAlgoAPI import BRepAlgoAPI_Cut
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeVertex, BRepBuilderAPI_Transform
    from OCP.BRepExtrema import BRepExtrema_DistShapeShape
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox, BRepPrimAPI_MakeCylinder
    from OCP.gp import gp_Ax1, gp_Ax2, gp_Dir, gp_Pnt, gp_Trsf

    from amprep.geometry.refine.adaptive import adaptive_refine
    from amprep.geometry.refine.face_domain import FaceDomains

    cylinder = BRepPrimAPI_MakeCylinder(gp_Ax2(gp_Pnt(0, 0, 0), gp_Dir(0, 0, 1)), 10, 100).Shape()
    tilt = gp_Trsf()
    tilt.SetRotation(gp_Ax1(gp_Pnt(0, 0, 80), gp_Dir(0, 1, 0)), math.radians(30))
    cutter = BRepBuilderAPI_Transform(BRepPrimAPI_MakeBox(gp_Pnt(-50, -50, 80), 100, 100, 100).Shape(), tilt).Shape()
    shape = BRepAlgoAPI_Cut(cylinder, cutter).Shape()
    model = model_from_shape(shape)
    mesh = mesh_model(model, MeshParams(tolerance=0.5)).mesh
    side = [i for i, f in enumerate(mesh.faces) if f.surface_type == "cylinder"]
    assert len(side) == 1
    surfaces = {side[0]: surface_of(model.faces[side[0]])}

    def off_the_solid(refined):
        count = 0
        for p in refined.vertices[mesh.n_vertices:]:
            vertex = BRepBuilderAPI_MakeVertex(gp_Pnt(*map(float, p))).Vertex()
            count += BRepExtrema_DistShapeShape(vertex, shape).Value() > 1e-6
        return count

    kept = adaptive_refine(mesh, side, surfaces, 0.01, domain=FaceDomains(model, 0.01)).mesh
    assert kept.n_triangles > 5 * mesh.n_triangles
    assert off_the_solid(kept) == 0
    assert check_mesh(kept).closed
    assert off_the_solid(adaptive_refine(mesh, side, surfaces, 0.01).mesh) > 0
