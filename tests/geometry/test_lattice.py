"""The quality mesher's closed-form lattice on analytic faces (meshing/lattice.py): rows zipped into triangles, closed
by topology, within tolerance by an exact distance independent of our (u,v) measure, fewer triangles than OCCT."""

import numpy as np
import pytest

from amprep.geometry.cad.read import model_from_shape
from amprep.geometry.meshing.lattice import zip_rows
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.pipeline import mesh_model
from tests.geometry.test_mesher import EXACT_DISTANCE, _closed_solid, _sample_triangles


def _lattice_faces(mesh) -> list[str]:
    return [f.surface_type for f in mesh.faces if f.meshed_by == "lattice"]


def _occt_triangles(shape, tol: float) -> int:
    """Triangles of OCCT's own BRepMesh (Delabella, its fastest) on the shape at the same deflection."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepMesh import BRepMesh_IncrementalMesh
    from OCP.BRepTools import BRepTools
    from OCP.IMeshTools import IMeshTools_MeshAlgoType_Delabella, IMeshTools_Parameters
    from OCP.TopLoc import TopLoc_Location

    from amprep.geometry.cad.topology import explore

    BRepTools.Clean_s(shape)
    p = IMeshTools_Parameters()
    p.Deflection, p.Angle, p.MeshAlgo = tol, 0.5, IMeshTools_MeshAlgoType_Delabella
    BRepMesh_IncrementalMesh(shape, p)
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopoDS import TopoDS

    n = sum(BRep_Tool.Triangulation_s(f, TopLoc_Location()).NbTriangles()
            for f in explore(shape, TopAbs_FACE, TopoDS.Face_s))
    BRepTools.Clean_s(shape)
    return n


@pytest.mark.parametrize("name", ["sphere", "torus"])
def test_lattice_is_closed_within_tolerance_and_smaller_than_occt(reference_solids, name):
    """Sphere r12 and torus R20 r5 at 0.002 mm: one lattice face each, closed, every sampled point of every triangle
    within the tolerance of the exact surface, fewer triangles than OCCT's own mesh, the sphere's near equilateral."""
    from amprep.geometry.measure.regularity import regularity

    tol = 0.002
    r = mesh_model(model_from_shape(reference_solids[name]), MeshParams(tolerance=tol, mesher="quality"))
    assert _lattice_faces(r.mesh) == [name]
    _closed_solid(r.mesh)
    assert r.max_error <= tol
    assert EXACT_DISTANCE[name](_sample_triangles(r.mesh)).max() <= tol
    assert EXACT_DISTANCE[name](r.mesh.vertices).max() < 1e-9
    assert r.mesh.n_triangles < _occt_triangles(reference_solids[name], tol)
    q = regularity(r.mesh.corners)["angle"]
    assert q.mean() >= (0.8 if name == "sphere" else 0.55) and (q < 0.2).mean() < 0.01


def test_lattice_on_partial_cylinders_apex_and_revolved_torus():
    """Quarter-cylinder fillets between planes (their straight sides re-cut at the rows, shared with the planes), a
    cone's apex (a fan), a quarter torus ending on two discs: closed, within tolerance by exact distance."""
    import cadquery as cq

    tol = 0.002
    block = cq.Workplane().box(40, 40, 20).edges("|Z").fillet(8).val()
    r = mesh_model(model_from_shape(block.wrapped), MeshParams(tolerance=tol, mesher="quality"))
    assert _lattice_faces(r.mesh).count("cylinder") == 4
    _closed_solid(r.mesh)
    assert r.max_error <= tol
    p = _sample_triangles(r.mesh)
    corner = np.abs(p[:, :2]) > 12 + 1e-6  # in the fillets' quadrants: distance to the fillet's axis
    on = corner.all(axis=1) & (np.abs(p[:, 2]) < 10 - 1e-6)  # not the top and bottom planes
    d = np.abs(np.linalg.norm(np.abs(p[on, :2]) - 12, axis=1) - 8)
    assert d.max() <= tol

    cone = cq.Solid.makeCone(10, 0, 20).wrapped
    r = mesh_model(model_from_shape(cone), MeshParams(tolerance=tol, mesher="quality"))
    assert _lattice_faces(r.mesh) == ["cone"]
    _closed_solid(r.mesh)
    p = _sample_triangles(r.mesh)
    side = p[:, 2] > 1e-9
    # distance to the cone x² + y² = ((20 − z)/2)²: along its normal, (ρ − (20 − z)/2)·cos α with tan α = 1/2
    d = np.abs(np.linalg.norm(p[side, :2], axis=1) - (20 - p[side, 2]) / 2) * (2 / np.sqrt(5))
    assert d.max() <= tol

    quarter = cq.Workplane("XZ").center(20, 0).circle(5).revolve(90, (-20, 0, 0), (-20, 1, 0)).val().wrapped
    r = mesh_model(model_from_shape(quarter), MeshParams(tolerance=tol, mesher="quality"))
    assert _lattice_faces(r.mesh) == ["torus"]
    _closed_solid(r.mesh)
    assert r.max_error <= tol


def test_a_face_the_lattice_cannot_take_goes_the_delaunay_way():
    """A cylinder with a cross hole has two loops: not a lattice face, still meshed, closed and within tolerance; a
    coarse tolerance on a small radius (the arc limit sets the size) is not one either."""
    import cadquery as cq

    tube = cq.Solid.makeCylinder(10, 30).cut(
        cq.Solid.makeCylinder(2, 40, cq.Vector(-20, 0, 15), cq.Vector(1, 0, 0))).wrapped
    r = mesh_model(model_from_shape(tube), MeshParams(tolerance=0.002, mesher="quality"))
    assert _lattice_faces(r.mesh) == []
    _closed_solid(r.mesh)
    assert r.max_error <= 0.002
    r = mesh_model(model_from_shape(cq.Solid.makeCylinder(2, 30).wrapped), MeshParams(tolerance=0.3, mesher="quality"))
    assert _lattice_faces(r.mesh) == []
    _closed_solid(r.mesh)


@pytest.mark.parametrize("na,nb,stagger", [(5, 5, 0.0), (5, 5, 0.5), (7, 4, 0.0), (2, 9, 0.3), (13, 12, 0.5)])
def test_zip_fills_the_strip_once_counter_clockwise(na, nb, stagger):
    """Two rows of n_a and n_b nodes from u = 0 to 1 (the upper staggered): n_a + n_b − 2 triangles, every one
    counter-clockwise, their areas summing to the strip's, every segment of either row in exactly one triangle."""
    au = np.linspace(0, 1, na)
    inner = (np.arange(nb - 2) + 1 + stagger) / (nb - 1) if nb > 2 else np.zeros(0)
    bu = np.concatenate([[0.0], np.clip(inner, 1e-3, 1 - 1e-3), [1.0]])
    a, b = np.arange(na), na + np.arange(nb)
    tris = zip_rows(a, au, b, bu, np.zeros(na, np.int64), np.zeros(nb, np.int64))
    uv = np.concatenate([np.stack([au, np.zeros(na)], 1), np.stack([bu, np.ones(nb)], 1)])
    assert len(tris) == na + nb - 2
    p = uv[tris]
    area = 0.5 * ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                  - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1]))
    assert (area > 0).all() and np.isclose(area.sum(), 1.0)
    edges = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    keys, counts = np.unique(edges, axis=0, return_counts=True)
    row_segments = {(i, i + 1) for i in range(na - 1)} | {(na + j, na + j + 1) for j in range(nb - 1)}
    assert all(counts[i] == 1 for i, k in enumerate(map(tuple, keys)) if k in row_segments)
    assert row_segments <= set(map(tuple, keys))


def test_an_edge_of_a_few_micrometres_is_collapsed_by_topology(monkeypatch):
    """A prism whose top edge is split by a CAD edge 5 µm long, 300 mm from the origin (float32 steps there are
    30 µm): its two vertices become one by topology, so the written STL has no triangle float32 rounds flat; without
    the collapse it has."""
    import cadquery as cq

    from amprep.geometry.core.checks import float32_degenerate_count
    from amprep.geometry.meshing import enforce

    pts = [(300, 0), (310, 0), (310, 10), (305.000004, 10), (305, 10.000003), (300, 10.000003)]
    prism = cq.Workplane().polyline(pts).close().extrude(5).val().wrapped
    params = MeshParams(tolerance=0.01, mesher="quality")
    r = mesh_model(model_from_shape(prism), params)
    _closed_solid(r.mesh)
    assert float32_degenerate_count(r.mesh) == 0
    monkeypatch.setattr(enforce, "collapse_short_edges", lambda *a: None)
    assert float32_degenerate_count(mesh_model(model_from_shape(prism), params).mesh) > 0


def test_the_report_counts_faces_by_method(tmp_path):
    """convert's summary says how each face was meshed: the sphere by the lattice; a box's planes by the quality
    mesher's Delaunay; the default mesher's by OCCT."""
    import cadquery as cq

    from amprep.jobs.convert import convert

    for shape, params, expected in (
            (cq.Solid.makeSphere(12, angleDegrees1=-90, angleDegrees2=90), dict(mesher="quality"), {"lattice": 1}),
            (cq.Solid.makeBox(10, 20, 30), dict(mesher="quality"), {"quality": 6}),
            (cq.Solid.makeBox(10, 20, 30), {}, {"occt": 6})):
        path = tmp_path / "part.step"
        cq.exporters.export(cq.Workplane().add(shape), str(path))
        summary = convert(path, MeshParams(tolerance=0.005, **params)).summary()
        assert summary["meshing"]["faces_by_method"] == expected


def test_a_b_spline_face_bounded_by_iso_lines_is_a_sampled_lattice(reference_solids):
    """A cylinder r10 h30 converted to NURBS (its side a rational B-spline whose (u,v) speed varies along the arc):
    the side meshed as a lattice from its sampled curvature and its side edges' pcurves inverted, closed, every
    sampled point within the tolerance of the exact cylinder."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_NurbsConvert

    nurbs = BRepBuilderAPI_NurbsConvert(reference_solids["cylinder"], True).Shape()
    tol = 0.002
    r = mesh_model(model_from_shape(nurbs), MeshParams(tolerance=tol, mesher="quality"))
    assert _lattice_faces(r.mesh) == ["bspline"]
    _closed_solid(r.mesh)
    assert r.max_error <= tol
    assert EXACT_DISTANCE["cylinder"](_sample_triangles(r.mesh)).max() <= tol


def test_corpus_b_spline_half_cylinders_are_lattices():
    """as1's bolts and tubes are rational B-spline half-cylinders, u along the axis and v round the arc, their end
    arcs circles in space whose parameter is not affine in the surface's v (the pcurve inverted): at 0.01 mm they
    are lattices, the part closed and within tolerance, with better angles than the Delaunay path's faces."""
    from amprep.geometry.cad.read import read_cad
    from amprep.geometry.measure.regularity import regularity
    from tests.conftest import corpus

    r = mesh_model(read_cad(corpus("as1_assembly_ap214.stp")), MeshParams(tolerance=0.01, mesher="quality"))
    _closed_solid(r.mesh)
    assert r.max_error <= 0.01
    assert _lattice_faces(r.mesh).count("bspline") >= 20
    q = regularity(r.mesh.corners)["angle"]
    method = np.array([r.mesh.faces[i].meshed_by for i in r.mesh.face_ids])
    assert q[method == "lattice"].mean() > 0.8 and q[method == "lattice"].min() > 0.2


def test_a_lattice_of_one_strip():
    """A disc 100 mm across and 0.05 mm thick at 0.001 mm: its band is one strip of over 1,000 triangles (no row
    between its two circles), zipped directly; closed, within tolerance."""
    import cadquery as cq

    r = mesh_model(model_from_shape(cq.Solid.makeCylinder(50, 0.05).wrapped),
                   MeshParams(tolerance=0.001, mesher="quality"))
    assert _lattice_faces(r.mesh) == ["cylinder"]
    _closed_solid(r.mesh)
    assert r.max_error <= 0.001


def test_rows_over_the_triangle_limit_are_refused_before_they_are_made(reference_solids):
    """The sphere at 0.0001 mm would take ~800k lattice triangles: with max_triangles 500k the plan refuses it,
    output_too_large, before any node is made."""
    from amprep.errors import AmprepError, ErrorCode
    from amprep.geometry.meshing import prepare

    import_limit = MeshParams(tolerance=0.0001, mesher="quality", max_triangles=500_000)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(prepare, "QUALITY_LEAST_FACTOR", 0)  # past the B-rep estimate, to the plan's own
        with pytest.raises(AmprepError) as err:
            mesh_model(model_from_shape(reference_solids["sphere"]), import_limit)
    assert err.value.code == ErrorCode.OUTPUT_TOO_LARGE and "rows alone" in str(err.value)

