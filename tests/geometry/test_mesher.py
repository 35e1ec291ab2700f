"""Conversion core: closed by topology, the tolerance kept on every face, fallback meshing, no stale mesh."""

import numpy as np
import pytest

from amprep.geometry.cad.read import model_from_shape, read_cad
from amprep.geometry.core.checks import check_mesh, manifold3d_accepts
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.pipeline import mesh_model
from tests.conftest import CAD_FILES, OPEN_CAD, corpus

# distance of a point to the exact surface, independent of the (u,v) sampling our mesher uses
EXACT_DISTANCE = {
    "sphere": lambda p: np.abs(np.linalg.norm(p, axis=1) - 12),
    "cylinder": lambda p: np.where((p[:, 2] > 1e-9) & (p[:, 2] < 30 - 1e-9),
                                   np.abs(np.linalg.norm(p[:, :2], axis=1) - 10), 0.0),
    "torus": lambda p: np.abs(np.hypot(np.linalg.norm(p[:, :2], axis=1) - 20, p[:, 2]) - 5),
}


def _closed_solid(mesh):
    c = check_mesh(mesh)
    assert c.boundary_edges == 0 and c.nonmanifold_edges == 0 and c.misoriented_edges == 0, c
    assert c.degenerate_triangles == 0, c
    assert c.volume > 0
    assert manifold3d_accepts(mesh)
    return c


def _sample_triangles(mesh, order=8):
    return _sample_corners(mesh.corners, order)


def _sample_corners(corners, order=8):
    """(m·P, 3) points of an order-`order` barycentric grid on each triangle's corners (m, 3, 3)."""
    w = np.array([(i, j, order - i - j) for i in range(order + 1) for j in range(order + 1 - i)], float) / order
    return np.einsum("pk,mkd->mpd", w, corners).reshape(-1, 3)


@pytest.mark.parametrize("tol", [0.1, 0.01])
@pytest.mark.parametrize("name", ["sphere", "torus", "cylinder", "cone", "filleted_block", "bspline_loft",
                                  "plate_with_holes"])
def test_reference_solids_closed_and_within_tolerance(reference_solids, name, tol):
    r = mesh_model(model_from_shape(reference_solids[name]), MeshParams(tolerance=tol))
    _closed_solid(r.mesh)
    assert r.max_error <= tol
    if name in EXACT_DISTANCE:
        dist = EXACT_DISTANCE[name](_sample_triangles(r.mesh))
        assert dist.max() <= tol * 1.001, dist.max() / tol


def test_sphere_poles_close_where_occt_export_is_open(reference_solids):
    """OCCT's StlAPI_Writer leaves the sphere open at its poles; ours collapses the pole triangles by topology."""
    r = mesh_model(model_from_shape(reference_solids["sphere"]), MeshParams(tolerance=0.01))
    c = _closed_solid(r.mesh)
    assert abs(c.volume - 4 / 3 * np.pi * 12**3) / (4 / 3 * np.pi * 12**3) < 0.01


@pytest.mark.parametrize("name", ["sphere", "torus", "cylinder", "cone", "filleted_block", "bspline_loft",
                                  "plate_with_holes"])
def test_forced_fallback_on_every_face_of_reference_solids(reference_solids, name):
    r = mesh_model(model_from_shape(reference_solids[name]), MeshParams(tolerance=0.05, force_fallback=True))
    assert set(r.fallback_faces) == set(range(len(r.mesh.faces)))
    assert all(f.meshed_by == "fallback" for f in r.mesh.faces)
    _closed_solid(r.mesh)
    assert r.max_error <= 0.05
    if name in EXACT_DISTANCE:
        assert EXACT_DISTANCE[name](_sample_triangles(r.mesh)).max() <= 0.05 * 1.001


@pytest.mark.parametrize("name", [n for n in CAD_FILES if n not in OPEN_CAD and "tessellated" not in n])
@pytest.mark.parametrize("how", ["occt", "forced_fallback", "quality"])
def test_corpus_solids_close_by_topology(name, how):
    params = MeshParams(tolerance=0.1, force_fallback=how == "forced_fallback", mesher="quality" if how == "quality" else "occt")
    r = mesh_model(read_cad(corpus(name)), params)
    _closed_solid(r.mesh)
    assert r.max_error <= 0.1
    assert not r.unmeshed_faces
    assert np.all(np.bincount(r.mesh.face_ids, minlength=len(r.mesh.faces)) > 0), "a face got no triangles"


@pytest.mark.parametrize("name", sorted(OPEN_CAD))
def test_open_iges_converts_to_an_open_mesh(name):
    r = mesh_model(read_cad(corpus(name)), MeshParams(tolerance=0.5))
    c = check_mesh(r.mesh)
    assert c.boundary_edges > 0 and c.nonmanifold_edges == 0 and c.degenerate_triangles == 0
    assert r.max_error <= 0.5


def test_nist_ctc02_collapsed_short_edges_are_welded():
    """CTC-02 has 0.0004 mm edges that BRepMesh collapses on one face only: the weld identifies their vertices."""
    r = mesh_model(read_cad(corpus("nist_ctc02_ap242.stp")), MeshParams(tolerance=0.1))
    _closed_solid(r.mesh)
    assert {"plane", "cylinder", "cone", "sphere", "torus", "bspline"} <= {f.surface_type for f in r.mesh.faces}


def test_no_stale_triangulation(reference_solids):
    model = model_from_shape(reference_solids["torus"])
    coarse = mesh_model(model, MeshParams(tolerance=0.1))
    fine = mesh_model(model, MeshParams(tolerance=0.01))
    assert fine.mesh.n_triangles > 3 * coarse.mesh.n_triangles
    assert fine.max_error <= 0.01
    again = mesh_model(model, MeshParams(tolerance=0.1))
    assert again.mesh.n_triangles == coarse.mesh.n_triangles


def test_relative_tolerance_is_a_fraction_of_the_bbox_diagonal(reference_solids):
    r = mesh_model(model_from_shape(reference_solids["sphere"]), MeshParams(relative=0.001))
    assert r.tolerance == pytest.approx(0.001 * np.sqrt(3) * 24, rel=1e-3)
    assert r.max_error <= r.tolerance


@pytest.mark.parametrize("algorithm", ["delabella", "watson"])
def test_both_occt_algorithms(reference_solids, algorithm):
    r = mesh_model(model_from_shape(reference_solids["filleted_block"]), MeshParams(tolerance=0.05, algorithm=algorithm))
    _closed_solid(r.mesh)
    assert r.max_error <= 0.05


@pytest.mark.parametrize("bad", [dict(tolerance=0), dict(tolerance=-1), dict(tolerance=float("nan")),
                                 dict(relative=2.0), dict(angular=0), dict(algorithm="magic")])
def test_invalid_parameters(reference_solids, bad):
    from amprep.errors import AmprepError, ErrorCode

    with pytest.raises(AmprepError) as err:
        mesh_model(model_from_shape(reference_solids["sphere"]), MeshParams(**bad))
    assert err.value.code == ErrorCode.INVALID_PARAMETER


def test_tessellated_only_ap242_keeps_the_files_topology():
    """FTC-08 has no exact surfaces: its stored triangles share the file's coordinates. The solid's shell comes
    out closed and outward (it is stored inside-out); the file's one loose face stays open and is reported."""
    from amprep.geometry.core.checks import shell_labels, signed_volume

    r = mesh_model(read_cad(corpus("nist_ftc08_tessellated_ap242.stp")), MeshParams(tolerance=0.1))
    mesh = r.mesh
    assert all(f.meshed_by == "stored" for f in mesh.faces)
    assert np.isnan(r.max_error)  # no surface, no chordal error
    n, label = shell_labels(mesh)
    sizes = np.bincount(label)
    main = np.argmax(sizes)
    assert n == 2 and sizes.min() == 2
    assert signed_volume(mesh.corners[label == main]) > 0
    c = check_mesh(mesh)
    assert c.boundary_edges == 4 and c.nonmanifold_edges == 0 and c.misoriented_edges == 0


def test_slivers_thinner_than_the_degenerate_check_send_the_face_to_the_fallback():
    """OCCT leaves a 36 nm high sliver on two B-spline faces of CTC-02's twin at 0.01 mm: not a needle by its own
    edge (area/L² ≈ 5e-4) but degenerate for the output check (area ≤ 1e-12 · diagonal²), so the face is re-meshed."""
    from amprep.geometry.core.checks import DEGENERATE_REL_AREA
    from amprep.geometry.meshing.local_refine import flat_triangles
    from amprep.geometry.meshing.occt_read import FacePatch

    nodes = np.array([[174.90300131, -229.69594043, 86.50283839], [174.90164246, -229.71095813, 86.51537158],
                      [174.9043103, -229.68139348, 86.4906021], [175.0, -229.0, 86.0]])
    tris = np.array([[0, 1, 2], [0, 2, 3]])
    none = np.full(4, -1)
    patch = FacePatch(0, nodes, None, tris, none, none, np.full(4, np.nan))
    diag = 1100.0  # CTC-02's bounding-box diagonal, mm
    assert not flat_triangles(patch).any()  # not a needle by the triangle's own proportions
    assert flat_triangles(patch, DEGENERATE_REL_AREA * diag**2).any()
    assert not flat_triangles(patch, DEGENERATE_REL_AREA * 100.0**2).any()  # on a 100 mm part it is a fine triangle


@pytest.mark.parametrize("name", ["as1_assembly_ap214.stp", "nist_ctc02_ap242.stp", "featuretype_inch_ap214.step"])
def test_bulk_triangulation_read_equals_the_node_by_node_read(name, monkeypatch):
    """The binary-stream reader returns exactly what OCCT's accessors give, face by face (an assembly's instanced
    solids share triangulations; every face still gets its own), without falling back to the slow reader."""
    from OCP.BRep import BRep_Tool
    from OCP.TopLoc import TopLoc_Location

    from amprep.geometry.cad.read import read_cad
    from amprep.geometry.meshing import occt_read
    from amprep.geometry.meshing.brepmesh import run_brepmesh
    from amprep.geometry.meshing.occt_read import bulk_triangulation_arrays, triangulation_arrays

    model = read_cad(corpus(name))
    run_brepmesh(model.shape, 0.05, MeshParams(tolerance=0.05))
    slow = []
    monkeypatch.setattr(occt_read, "triangulation_arrays", lambda t: slow.append(t))
    bulk = bulk_triangulation_arrays(model.faces)
    monkeypatch.undo()
    assert not slow
    assert len(bulk) == len(model.faces) and sum(b is not None for b in bulk) > 0
    for face, got in zip(model.faces, bulk, strict=True):
        tri = BRep_Tool.Triangulation_s(face, TopLoc_Location())
        if tri is None or tri.NbTriangles() == 0:
            assert got is None
            continue
        want = triangulation_arrays(tri)
        assert got is not None
        for a, b in zip(got, want, strict=True):
            assert (a is None and b is None) or np.array_equal(a, b)


def test_a_close_call_is_measured_again_on_a_finer_grid_instead_of_re_meshed(reference_solids, monkeypatch):
    """OCCT meshes the torus R20 r5 at 0.001 mm to 0.9955× the tolerance on the order-6 grid: within it, but inside
    the band where that grid could miss the true maximum. The band's triangles are measured on the order-24 grid,
    which keeps the doubt under FINE_MARGIN, so OCCT's mesh is kept (its triangle count, no fallback); a face whose
    finer measure leaves the doubt is re-meshed."""
    from amprep.geometry.meshing import enforce
    from amprep.geometry.meshing.brepmesh import run_brepmesh

    model = model_from_shape(reference_solids["torus"])
    params = MeshParams(tolerance=0.001, own_large_faces=False)  # the torus is OCCT's to mesh here
    res = mesh_model(model, params)
    run_brepmesh(model.shape, 0.001, params)
    from amprep.geometry.meshing.occt_read import bulk_triangulation_arrays

    occt_triangles = sum(len(b[2]) for b in bulk_triangulation_arrays(model.faces) if b is not None)
    assert res.fallback_faces == {} and res.mesh.n_triangles == occt_triangles
    assert enforce.TRIGGER_MARGIN < res.max_error / 0.001 <= enforce.FINE_MARGIN
    monkeypatch.setattr(enforce, "FINE_MARGIN", 0.99)  # the finer measure no longer clears the doubt: re-meshed
    strict = mesh_model(model, params)
    assert strict.fallback_faces == {0: "tolerance"} and strict.max_error <= 0.001 * enforce.FINE_MARGIN


def test_fallback_points_keep_apart_so_float32_cannot_merge_them():
    """CTC-02's face 174 at 0.001 mm, re-meshed from OCCT's interior nodes (not the curvature-sized points, which
    this face, curved one way, does without): insertion once put two nodes 3.2e-6 mm apart (one vertex after
    float32 rounding in the STL: degenerate triangles, non-manifold edges). Inserted and seeded points now keep
    MIN_SPACING × tolerance from every other node."""
    from scipy.spatial import cKDTree

    from amprep.geometry.cad.surfaces import surface_of
    from amprep.geometry.cad.topology import Topology
    from amprep.geometry.meshing import face_mesher as fallback
    from amprep.geometry.meshing import uv_cdt
    from amprep.geometry.meshing.brepmesh import run_brepmesh
    from amprep.geometry.meshing.occt_read import extract_patch

    pts = np.array([[0.0, 0.0], [1.0, 0.0]])
    new = np.array([[0.0, 5e-6], [0.5, 0.5], [0.5, 0.5 + 5e-6], [2.0, 2.0]])
    assert np.array_equal(uv_cdt.apart(new, pts, 1e-5), new[[1, 3]])
    model = read_cad(corpus("nist_ctc02_ap242.stp"))
    # its dense interior, by OCCT on this face alone (the whole part at a micron takes minutes; without `apart` these
    # seeds too give two nodes 3.2e-6 mm apart)
    run_brepmesh(model.faces[174], 0.001, MeshParams(tolerance=0.001, occt_surface_control=True))
    topo = Topology.of(model.shape)
    face = model.faces[174]
    occt = extract_patch(174, face, topo)
    seeds = occt.uv[(occt.node_edge < 0) & (occt.node_vertex < 0)]
    patch = fallback.mesh_face(174, face, topo, surface_of(face), 0.00098, 0.5, seeds=seeds, curvature_sized=False)
    inner = (patch.node_edge < 0) & (patch.node_vertex < 0)
    spacing = cKDTree(patch.nodes).query(patch.nodes[inner], k=2)[0][:, 1]
    assert spacing.min() > 0.5 * uv_cdt.MIN_SPACING * 0.001
    corners = patch.nodes[patch.tris[inner[patch.tris].all(axis=1)]].astype(np.float32).astype(np.float64)
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    assert area.min() > 1e-7


def test_triangles_that_float32_rounding_makes_degenerate_are_counted_and_said():
    """A sliver 1.4e-5 mm high at 300–400 mm from the origin: not degenerate in float64, flat once its corners are
    rounded to float32 as STL stores them (the spacing of float32 there is 3e-5 mm); the same sliver near the origin
    survives the rounding."""
    from amprep.geometry.core.checks import degenerate_mask, float32_degenerate_count
    from amprep.geometry.core.mesh import Mesh

    base = np.array([400.0, 300.0, 100.0])
    verts = base + np.array([[0, 0, 0], [0.25, 0, 0], [0.125, 1.4e-5, 0], [0, 5.0, 5.0]])
    sliver = Mesh.from_arrays(verts, np.array([[0, 1, 2], [0, 1, 3]]))
    assert not degenerate_mask(sliver).any()
    assert float32_degenerate_count(sliver) == 1
    assert float32_degenerate_count(Mesh.from_arrays(verts - base, sliver.triangles)) == 0


@pytest.mark.parametrize("name", ["sphere", "torus", "cylinder", "cone", "filleted_block", "bspline_loft",
                                  "plate_with_holes"])
def test_quality_mesher_closed_and_within_tolerance_checked_independently(reference_solids, name):
    r = mesh_model(model_from_shape(reference_solids[name]), MeshParams(tolerance=0.05, mesher="quality"))
    _closed_solid(r.mesh)
    assert r.max_error <= 0.05
    if name in EXACT_DISTANCE:
        assert EXACT_DISTANCE[name](_sample_triangles(r.mesh)).max() <= 0.05 * 1.001


@pytest.mark.parametrize("name", [n for n in CAD_FILES if "tessellated" not in n])  # bench/regularity.py's parts
def test_quality_mesher_regularity_at_the_papers_tolerance(name):
    """At ε = 0.34 mm (paper 000's Table 2) the quality mesher's mean angle regularity is ≥ 0.6 and 0.1 above the
    default's on every corpus part with exact surfaces, with fewer than 0.5 % of its triangles in the paper's first
    bin [0, 0.005); closed, within tolerance."""
    from amprep.geometry.measure.regularity import regularity, summarize

    model = read_cad(corpus(name))
    occt = mesh_model(model, MeshParams(tolerance=0.34))
    ours = mesh_model(model, MeshParams(tolerance=0.34, mesher="quality"))
    if name not in OPEN_CAD:  # the IGES lens is an open surface
        _closed_solid(ours.mesh)
    assert ours.max_error <= 0.34
    q, q_occt = (summarize(regularity(m.mesh.corners)) for m in (ours, occt))
    assert q.mean["angle"] >= 0.6 and q.mean["angle"] > q_occt.mean["angle"] + 0.1, (q.mean, q_occt.mean)
    assert q.bins["angle"][0] < 0.005 * ours.mesh.n_triangles


def test_quality_mesher_is_deterministic(reference_solids):
    shape = reference_solids["filleted_block"]
    a, b = (mesh_model(model_from_shape(shape), MeshParams(tolerance=0.02, mesher="quality")).mesh for _ in range(2))
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.triangles, b.triangles)


def test_graded_edges_stay_shared_by_both_faces(reference_solids):
    """The grading cuts a long edge for the narrow face beside it; the wide face takes the same points: closed."""
    import cadquery as cq

    strip = cq.Workplane().box(100, 40, 10).edges("|X").chamfer(1).val().wrapped  # 1.4 mm chamfer strips, 100 long
    r = mesh_model(model_from_shape(strip), MeshParams(tolerance=0.1, mesher="quality"))
    _closed_solid(r.mesh)
    lengths = np.linalg.norm(np.roll(r.mesh.corners, -1, axis=1) - r.mesh.corners, axis=2)
    assert lengths.max() < 100 / 4, "the 100 mm edges were not cut for the chamfers beside them"


def test_min_size_stops_the_quality_mesher_cutting_edges_to_a_thin_wall():
    """A 0.5 mm wall 100 mm long: its long edges are cut to its width (segments under 1 mm), unless min_size sets the
    size they are cut to at 4 mm (equal cuts of a longer segment, then the strip's staggered end segments halved: at
    least 1 mm); either way closed and within the tolerance, which still cuts the rounded ends' edges."""
    import cadquery as cq

    wall = cq.Workplane().box(100, 0.5, 20).edges("|Y").fillet(0.2).val().wrapped
    model = model_from_shape(wall)
    fine, coarse = (mesh_model(model, MeshParams(tolerance=0.01, mesher="quality", min_size=m)) for m in (0.0, 4.0))
    for r in (fine, coarse):
        _closed_solid(r.mesh)
        assert r.within_tolerance

    def long_sides(mesh) -> np.ndarray:  # the sides along x on the wall's long straight edges (y = ±0.25, z = ±10)
        a, b = mesh.corners, np.roll(mesh.corners, -1, axis=1)
        on = (np.abs(np.abs(a[..., 1]) - 0.25) < 1e-9) & (np.abs(np.abs(a[..., 2]) - 10) < 1e-9)
        along = on & (np.abs(b[..., 1] - a[..., 1]) < 1e-9) & (np.abs(b[..., 2] - a[..., 2]) < 1e-9)
        return np.abs(b[..., 0] - a[..., 0])[along]

    assert long_sides(fine.mesh).max() < 1.0 <= long_sides(coarse.mesh).min()
    assert coarse.mesh.n_triangles < fine.mesh.n_triangles / 2


def test_the_triangle_limit_is_kept_while_meshing_not_only_estimated(monkeypatch):
    """The quality mesher can outgrow its estimates (forced here: its faces estimated at none): the limit is checked
    on its planned rows before they are made, and on the mesh as it is made (with no lattice planned)."""
    from amprep.errors import AmprepError, ErrorCode
    from amprep.geometry.cad.estimate import estimate_triangles
    from amprep.geometry.meshing import enforce, lattice

    model = read_cad(corpus("featuretype_inch_ap214.step"))
    limit = estimate_triangles(model, 0.01, 0.5) * 6 + 1000  # under the mesh's 55k, over its B-rep estimate's floor
    monkeypatch.setattr(enforce, "quality_estimate", lambda surfaces, *a, **k: np.zeros(len(surfaces)))
    for lattice_min, said in ((lattice.LATTICE_MIN, "rows alone"), (np.inf, "while it was made")):
        monkeypatch.setattr(lattice, "LATTICE_MIN", lattice_min)
        with pytest.raises(AmprepError) as err:
            mesh_model(model, MeshParams(tolerance=0.01, mesher="quality", max_triangles=limit))
        assert err.value.code == ErrorCode.OUTPUT_TOO_LARGE and said in err.value.message


def test_a_face_of_no_width_keeps_its_edges_uncut_and_is_meshed(monkeypatch):
    """A face bounded by two edges on one line, out and back (FreeCAD's SOD-323 IDF part has two): the grading would
    cut them for the narrow face beside it, leaving points the no-width face cannot join; they stay as discretised."""
    from OCP.BRepBuilderAPI import (
        BRepBuilderAPI_MakeEdge,
        BRepBuilderAPI_MakeFace,
        BRepBuilderAPI_MakeVertex,
        BRepBuilderAPI_MakeWire,
    )
    from OCP.BRepLib import BRepLib
    from OCP.gp import gp_Pln, gp_Pnt
    from OCP.TopoDS import TopoDS

    from amprep.geometry.cad.topology import compound
    from amprep.geometry.meshing import shared_edges

    va, vb, vc = (BRepBuilderAPI_MakeVertex(gp_Pnt(*p)).Vertex() for p in ((0, 0, 0), (10, 0, 0), (5, 0.5, 0)))
    ab, ba = BRepBuilderAPI_MakeEdge(va, vb).Edge(), BRepBuilderAPI_MakeEdge(vb, va).Edge()

    def face(*edges):
        wire = BRepBuilderAPI_MakeWire()
        for e in edges:
            wire.Add(e)
        f = BRepBuilderAPI_MakeFace(gp_Pln(), wire.Wire()).Face()
        BRepLib.BuildCurves3d_s(f)
        return f

    narrow = face(ab, BRepBuilderAPI_MakeEdge(vb, vc).Edge(), BRepBuilderAPI_MakeEdge(vc, va).Edge())  # 0.25 mm wide
    none = face(TopoDS.Edge_s(ab.Reversed()), TopoDS.Edge_s(ba.Reversed()))
    model = model_from_shape(compound([narrow, none]))
    r = mesh_model(model, MeshParams(tolerance=0.01, mesher="quality"))
    assert r.unmeshed_faces == ()
    on_ab = r.mesh.vertices[np.abs(r.mesh.vertices[:, 1]) < 1e-12]
    assert len(on_ab) <= 3, "the no-width face's edges were cut"
    monkeypatch.setattr(shared_edges, "SLIVER", -1.0)  # the rule off: cut, and the face is left unmeshed
    r = mesh_model(model, MeshParams(tolerance=0.01, mesher="quality"))
    assert r.unmeshed_faces != ()


def test_a_solid_under_the_collapse_length_keeps_its_edges_and_is_meshed(monkeypatch):
    """A 0.5 µm cube beside a 10 mm one, meshed at 0.1 mm by the quality mesher: its edges are under the 1 µm
    (0.01 × tolerance) that collapses an edge, but its faces keep them (their perimeters are under 8 such lengths),
    so both solids come out closed, the small one with its 12 triangles and its volume."""
    import cadquery as cq

    from amprep.geometry.meshing import shared_edges

    small = cq.Solid.makeBox(5e-4, 5e-4, 5e-4, cq.Vector(20, 0, 0))
    model = model_from_shape(cq.Compound.makeCompound([cq.Solid.makeBox(10, 10, 10), small]).wrapped)
    r = mesh_model(model, MeshParams(tolerance=0.1, mesher="quality"))
    checks = check_mesh(r.mesh)
    assert r.unmeshed_faces == () and checks.closed and checks.shells == 2
    assert checks.volume == pytest.approx(1000 + 5e-4 ** 3, rel=1e-12)
    assert (r.mesh.corners[:, :, 0] > 15).all(axis=1).sum() == 12

    monkeypatch.setattr(shared_edges, "TINY_FACE", 0.0)  # the rule off: the small cube's faces collapse whole
    r = mesh_model(model_from_shape(cq.Compound.makeCompound([cq.Solid.makeBox(10, 10, 10), small]).wrapped),
                   MeshParams(tolerance=0.1, mesher="quality"))
    assert r.unmeshed_faces != () or check_mesh(r.mesh).shells == 1


def test_a_circle_brepmesh_collapses_onto_its_vertex_is_cut_and_its_disc_meshed(monkeypatch):
    """A pin's rounded end (a B-spline arc revolved) leaves a 0.05 mm disc; with the vertex's tolerance 0.5 mm (as a
    KiCad DSUB-15's pins have) BRepMesh collapses the disc's circle onto its vertex and the disc gets no triangles.
    The closed edge is cut in three, the disc and the round end meshed from it: every face meshed, closed, within
    tolerance by OCCT's distance; without the cut the disc is left unmeshed."""
    import math

    from OCP.BRep import BRep_Builder, BRep_Tool
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeFace, BRepBuilderAPI_MakeWire
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeRevol
    from OCP.GC import GC_MakeArcOfCircle
    from OCP.GeomConvert import GeomConvert
    from OCP.gp import gp_Ax1, gp_Dir, gp_Pnt
    from OCP.TopAbs import TopAbs_VERTEX
    from OCP.TopoDS import TopoDS

    from amprep.geometry.cad.topology import explore
    from amprep.geometry.meshing import enforce
    from tests.geometry.test_independent_distance import _worst_distance

    r, big, s = 0.025, 0.15, math.sqrt(0.5)
    f = big - r
    arc = GC_MakeArcOfCircle(gp_Pnt(r, 0, 0), gp_Pnt(r + f * s, 0, f - f * s), gp_Pnt(big, 0, f)).Value()
    wire = BRepBuilderAPI_MakeWire()
    for edge in (BRepBuilderAPI_MakeEdge(gp_Pnt(0, 0, 0), gp_Pnt(r, 0, 0)),
                 BRepBuilderAPI_MakeEdge(GeomConvert.CurveToBSplineCurve_s(arc)),
                 BRepBuilderAPI_MakeEdge(gp_Pnt(big, 0, f), gp_Pnt(big, 0, 2)),
                 BRepBuilderAPI_MakeEdge(gp_Pnt(big, 0, 2), gp_Pnt(0, 0, 2)),
                 BRepBuilderAPI_MakeEdge(gp_Pnt(0, 0, 2), gp_Pnt(0, 0, 0))):
        wire.Add(edge.Edge())
    profile = BRepBuilderAPI_MakeFace(wire.Wire()).Face()
    shape = BRepPrimAPI_MakeRevol(profile, gp_Ax1(gp_Pnt(0, 0, 0), gp_Dir(0, 0, 1)), 2 * math.pi).Shape()
    rim = [v for v in explore(shape, TopAbs_VERTEX, TopoDS.Vertex_s)
           if abs(BRep_Tool.Pnt_s(v).Z()) < 1e-9 and abs(BRep_Tool.Pnt_s(v).X() - r) < 1e-9]
    assert rim
    for v in rim:
        BRep_Builder().UpdateVertex(v, 0.5)
    model = model_from_shape(shape)
    res = mesh_model(model, MeshParams(tolerance=0.1))
    assert res.fallback_faces.get(0) == "no_triangulation"  # the disc: BRepMesh gave it nothing
    assert res.unmeshed_faces == ()
    _closed_solid(res.mesh)
    assert np.bincount(res.mesh.face_ids, minlength=len(model.faces)).min() > 0
    assert _worst_distance(model, res.mesh, samples=200) <= 0.1 * 1.001
    monkeypatch.setattr(enforce, "CLOSED_EDGE_SEGMENTS", 0)  # no cut: the disc stays without triangles
    assert mesh_model(model, MeshParams(tolerance=0.1)).unmeshed_faces == (0,)


def test_a_cap_of_three_nodes_on_one_line_is_split_into_its_neighbour():
    """A degenerate triangle whose middle corner lies on its longest side (three nodes of one straight edge that a
    face's (u,v) Delaunay joined: FreeCAD's SOD_323 quality mesh had two) is folded into the neighbour across that
    side: no degenerate triangle, the same boundary, orientation and area; left where the neighbour is another face's."""
    from amprep.geometry.core.mesh import FaceInfo, Mesh
    from amprep.geometry.meshing.weld import split_caps

    a, c, b, d, e = (0, 0, 0), (2, 0, 0), (1, 0, 0), (1, 1, 0), (1, -1, 0)
    vertices = np.array([a, c, b, d, e], float)
    tris = np.array([[0, 1, 2], [1, 0, 3], [0, 2, 4], [2, 1, 4]])  # the cap, its neighbour across a–c, two below
    uv = vertices[tris][..., :2].copy()

    def mesh_of(face_ids):
        return Mesh(vertices, tris, np.array(face_ids, np.int32), uv,
                    faces=tuple(FaceInfo(i, "plane") for i in range(max(face_ids) + 1)))

    before = check_mesh(mesh_of([0, 0, 0, 0]))
    assert before.degenerate_triangles == 1 and before.misoriented_edges == 0
    out = split_caps(mesh_of([0, 0, 0, 0]))
    after = check_mesh(out)
    assert after.degenerate_triangles == 0 and after.misoriented_edges == 0 and after.nonmanifold_edges == 0
    assert after.boundary_edges == before.boundary_edges and np.isclose(after.area, before.area)
    assert sorted(map(tuple, np.sort(out.triangles[:2], axis=1))) == [(0, 2, 3), (1, 2, 3)]
    assert np.allclose(out.uv[..., 0], out.vertices[out.triangles][..., 0])  # each corner keeps its own (u,v)
    assert check_mesh(split_caps(mesh_of([0, 1, 0, 0]))).degenerate_triangles == 1  # the neighbour is another face's


def test_a_face_the_quality_path_fails_on_is_meshed_as_the_default_meshes_its_own(reference_solids, monkeypatch):
    """The quality mesher's Delaunay refinement failing on every face (forced): each face is meshed from its boundary
    and refinement alone, as the default mesher's own faces are, reported `fallback`, closed and within tolerance."""
    from amprep.errors import AmprepError, ErrorCode
    from amprep.geometry.meshing import face_mesher

    def fails(*args, **kwargs):  # type: ignore[no-untyped-def]
        raise AmprepError(ErrorCode.MESHING_FAILED, "forced")

    monkeypatch.setattr(face_mesher, "quality_pslg", fails)
    monkeypatch.setattr(face_mesher, "curvature_seeds", fails)
    model = model_from_shape(reference_solids["filleted_block"])
    r = mesh_model(model, MeshParams(tolerance=0.01, mesher="quality", own_large_faces=True))
    lattice = {f.id for f in r.mesh.faces if f.meshed_by == "lattice"}
    assert r.unmeshed_faces == () and check_mesh(r.mesh).closed
    assert {f.meshed_by for f in r.mesh.faces if f.id not in lattice} == {"fallback"}
    assert float(r.face_error.max()) <= 0.01


def _lens(length: float = 2.2, radius: float = 0.1):  # type: ignore[no-untyped-def]
    """A sliver solid: the lens between a 90° arc of `radius` and its chord (0.029 mm thick), extruded `length` mm;
    the chord's plane and the arc's cylinder share both long edges."""
    import cadquery as cq

    a = np.radians(45)
    p1, p2 = (radius * np.cos(a), -radius * np.sin(a)), (radius * np.cos(a), radius * np.sin(a))
    return cq.Workplane("XY").moveTo(*p1).threePointArc((radius, 0), p2).close().extrude(length).val().wrapped


def test_two_faces_closer_than_the_tolerance_are_pinched_not_left_non_manifold(monkeypatch):
    """At 0.1 mm the lens's plane and cylinder are each within tolerance as a strip straight across from one long edge
    to the other, on the same graded nodes: four triangles on each such edge. The strip both cover is dropped from
    both, the solid pinched to zero thickness there (its two ends left as two shells): closed, and each triangle left
    within tolerance by OCCT."""
    from amprep.geometry.meshing import pipeline
    from tests.geometry.test_independent_distance import _worst_distance

    model = model_from_shape(_lens())
    r = mesh_model(model, MeshParams(tolerance=0.1, mesher="quality"))
    checks = check_mesh(r.mesh)
    assert checks.closed and checks.shells == 2 and r.unmeshed_faces == ()
    assert _worst_distance(model, r.mesh, samples=200) <= 0.1
    assert 0 < checks.volume < 0.00628  # the lens's own volume: (π/4 − 1/2) r² × 2.2

    monkeypatch.setattr(pipeline, "pinch_double_sheets", lambda mesh: mesh)
    assert check_mesh(mesh_model(model, MeshParams(tolerance=0.1, mesher="quality")).mesh).nonmanifold_edges > 0


def _stepped_block(step: float = 0.001):  # type: ignore[no-untyped-def]
    """A 10 × 10 × 1 mm block whose top has a riser `step` mm high across it, 10 mm long (KiCad's pin sockets have
    such 1 µm steps)."""
    import cadquery as cq

    pts = [(0, 0), (10, 0), (10, 1 + step), (5, 1 + step), (5, 1), (0, 1)]
    return cq.Workplane("XZ").polyline(pts).close().extrude(-10).val().wrapped


@pytest.mark.parametrize("tol", [0.01, 0.1])
def test_a_face_narrower_than_the_tolerance_is_cut_at_the_tolerance_not_its_width(monkeypatch, tol):
    """The 1 µm riser's 10 mm edges are cut to about GRADE × the tolerance at 0.01 mm (the riser holds needles whatever
    its segments), not to 3 µm floored at the tolerance, which filled both top faces with triangles graded from 1,000
    segments; at 0.1 mm NEEDLE × 1 µm is under the tolerance and the mesh is as before. No more needles in the
    paper's first bin either way."""
    from amprep.geometry.core.mesh import ON_BREP_EDGE
    from amprep.geometry.measure.regularity import regularity
    from amprep.geometry.meshing import shared_edges

    def riser_segments(mesh) -> int:  # type: ignore[no-untyped-def]
        v = mesh.vertices
        on = (mesh.vertex_dim == ON_BREP_EDGE) & (np.abs(v[:, 0] - 5) < 1e-9) & (np.abs(v[:, 2] - 1) < 1e-9)
        return int(on.sum()) + 1  # the nodes inside the riser's lower edge, plus one

    def first_bin(mesh) -> int:  # type: ignore[no-untyped-def]
        return int((regularity(mesh.corners)["angle"] < 0.005).sum())

    model = model_from_shape(_stepped_block())
    r = mesh_model(model, MeshParams(tolerance=tol, mesher="quality"))
    assert check_mesh(r.mesh).closed and float(r.face_error.max()) <= tol
    monkeypatch.setattr(shared_edges, "NEEDLE", shared_edges.GRADE)  # the cap of the faces' widths alone, as before
    before = mesh_model(model, MeshParams(tolerance=tol, mesher="quality"))
    assert first_bin(r.mesh) <= first_bin(before.mesh)
    if tol == 0.01:
        assert riser_segments(r.mesh) <= 10 / (shared_edges.GRADE * tol) * 1.2
        assert riser_segments(before.mesh) > 2.5 * riser_segments(r.mesh)
        assert before.mesh.n_triangles > 2.5 * r.mesh.n_triangles
    else:
        assert before.mesh.n_triangles == r.mesh.n_triangles


def test_the_quality_mesher_keeps_the_triangles_a_tessellated_only_face_stores():
    """NIST's FTC-08 in AP242 stores triangles and no surfaces: there is nothing for the quality mesher to mesh, and
    its faces keep their own triangles, as with the default mesher (it used to give no triangles: empty_model)."""
    model = read_cad(corpus("nist_ftc08_tessellated_ap242.stp"))
    quality, default = (mesh_model(model, MeshParams(tolerance=0.1, mesher=m)).mesh for m in ("quality", "occt"))
    assert quality.n_triangles == default.n_triangles > 3000
    assert np.array_equal(np.sort(quality.corners.reshape(-1, 3), axis=0), np.sort(default.corners.reshape(-1, 3), axis=0))


@pytest.mark.parametrize("mesher", ["occt", "quality"])
def test_convert_reports_the_papers_regularity_of_what_it_wrote(reference_solids, mesher, tmp_path):
    """The convert summary's `regularity` (paper 000's measures: mean and the four bins) agrees with the angles by the
    law of cosines and the side ratios of the triangles parsed from the binary STL by numpy alone; the quality mesher's
    angle mean is over 0.6."""
    from amprep.geometry.io.stl import write_stl
    from amprep.jobs.convert import convert

    path = tmp_path / "part.stl"  # STL passthrough: the summary is of the triangles as read
    write_stl(mesh_model(model_from_shape(reference_solids["filleted_block"]),
                         MeshParams(tolerance=0.05, mesher=mesher)).mesh, path)
    r = convert(path).summary()["regularity"]
    record = np.dtype([("normal", "<f4", 3), ("corners", "<f4", (3, 3)), ("attr", "<u2")])
    corners = np.frombuffer(path.read_bytes(), record, offset=84)["corners"].astype(float)
    a, b, c = (np.linalg.norm(corners[:, (k + 1) % 3] - corners[:, (k + 2) % 3], axis=1) for k in range(3))
    smallest = np.arccos(np.clip((b * b + c * c - a * a) / (2 * b * c), -1, 1))  # the angle opposite the shortest side
    for x, y, z in ((c, a, b), (a, b, c)):
        smallest = np.minimum(smallest, np.arccos(np.clip((x * x + y * y - z * z) / (2 * x * y), -1, 1)))
    sides = np.stack([a, b, c], axis=1)
    for name, q in (("angle", smallest / (np.pi / 3)), ("edge", sides.min(axis=1) / sides.max(axis=1))):
        assert r[name]["mean"] == pytest.approx(q.mean(), abs=1e-6)
        assert r[name]["bins"] == np.histogram(np.clip(q, 0, 1), [0, 0.005, 0.4, 0.8, 1.0 + 1e-12])[0].tolist()
    if mesher == "quality":
        assert r["angle"]["mean"] > 0.6
