"""A face's mesh is bounded by its edges' discretisation, a discretisation that crosses itself in (u,v) is split
until it does not, and faces agree in orientation with their neighbours: forced on solids built here (a thread swept
along a helix onto a core, whose flank meets the top plane at a small angle beside the core's rim; a nut written as
IGES trimmed surfaces), checked by manifold3d and OCCT's volume."""

import numpy as np
import pytest
from OCP.BRepGProp import BRepGProp
from OCP.GProp import GProp_GProps

from amprep.geometry.cad.read import model_from_shape, read_cad
from amprep.geometry.cad.topology import mirrors
from amprep.geometry.core.checks import check_mesh, manifold3d_accepts
from amprep.geometry.core.edges import edge_incidence
from amprep.geometry.meshing.occt_read import FacePatch, off_boundary_edges
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.pipeline import mesh_file, mesh_model
from amprep.geometry.meshing.uv_cdt import crossing_segments


def _thread(pitch: float, height: float, radius: float, size: float):
    import cadquery as cq

    helix = cq.Wire.makeHelix(pitch=pitch, height=height, radius=radius)
    swept = cq.Workplane("XZ").center(radius, 0).polygon(3, size).sweep(cq.Workplane().add(helix), isFrenet=True)
    return cq.Workplane().circle(radius).extrude(height).union(swept).val().wrapped


def _iges_faces(shape, path) -> None:
    """The shape written as IGES trimmed surfaces (no topology: sewn again on reading)."""
    from OCP.IGESControl import IGESControl_Writer

    writer = IGESControl_Writer("MM", 0)
    writer.AddShape(shape)
    writer.ComputeModel()
    assert writer.Write(str(path))


@pytest.fixture(scope="module")
def thread():
    return _thread(1.5, 12, 5, 1.2)


def _volume(shape) -> float:
    props = GProp_GProps()
    BRepGProp.VolumeProperties_s(shape, props)
    return props.Mass()


def _square(nodes_on_edges: int = 4) -> FacePatch:
    """Two triangles on the unit square, nodes 0-3 its corners; `nodes_on_edges` nodes in all (a fifth on the side
    2-3, used by no triangle, when 5)."""
    nodes = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 1, 0]], float)[:nodes_on_edges]
    k = len(nodes)
    return FacePatch(0, nodes, nodes[:, :2], np.array([[0, 1, 2], [0, 2, 3]]), np.full(k, -1), np.zeros(k, np.int64),
                     np.linspace(0, 1, k))


def test_a_patch_boundary_must_be_its_edge_polygons():
    """Sides used once that join two boundary nodes but follow no edge polygon, and polygon segments no triangle
    uses, break the patch; the ends-on-the-boundary test alone saw neither."""
    sound = _square()
    assert len(off_boundary_edges(sound, np.array([[0, 1], [1, 2], [2, 3], [3, 0]]))) == 0
    skipping = _square(5)  # the polygon runs 2 → 4 → 3; the triangle 0-2-3 cuts across it
    bad = off_boundary_edges(skipping, np.array([[0, 1], [1, 2], [2, 4], [4, 3], [3, 0]]))
    assert {tuple(sorted(e)) for e in bad.tolist()} == {(2, 3), (2, 4), (3, 4)}
    assert len(off_boundary_edges(skipping)) == 0


def test_crossing_segments_of_boundary_polygons():
    square = np.array([[0, 0], [2, 0], [2, 2], [0, 2]], float)
    assert len(crossing_segments([square])) == 0
    bowtie = np.array([[0, 0], [1, 1], [1, 0], [0, 1]], float)
    assert crossing_segments([bowtie]).tolist() == [[0, 2]]
    poking = np.array([[1.5, 0.5], [2.5, 0.5], [2.5, 1.5], [1.5, 1.5]])  # a hole through the square's right side
    assert crossing_segments([square, poking]).tolist() == [[1, 4], [1, 6]]


@pytest.mark.parametrize("mesher", ["occt", "quality"])
def test_thread_comes_out_closed_and_within_tolerance(thread, mesher):
    """OCCT's mesh of the top plane bridged the core's rim to the flank past two of their shared nodes (4 open
    edges); meshed by ours from the edges' discretisation, the rim's and the flank's chords crossed in (u,v) where
    they meet at a few degrees (the face was left unmeshed: 23 open edges). Both meshers close it now."""
    model = model_from_shape(thread)
    r = mesh_model(model, MeshParams(tolerance=0.1, mesher=mesher))
    checks = check_mesh(r.mesh)
    assert checks.boundary_edges == 0 and checks.nonmanifold_edges == 0 and checks.misoriented_edges == 0
    assert not r.unmeshed_faces and r.within_tolerance
    assert manifold3d_accepts(r.mesh)
    assert abs(checks.volume - _volume(thread)) < 0.05 * _volume(thread)
    if mesher == "occt":
        reasons = set(r.fallback_faces.values())
        assert {"broken_triangulation", "boundary_crossing"} <= reasons


@pytest.mark.parametrize("mesher", ["occt", "quality"])
@pytest.mark.parametrize("tolerance", [0.1, 0.01])
@pytest.mark.parametrize("via", ["shape", "step"])
def test_a_face_pinched_at_a_vertex_is_meshed(mesher, tolerance, via, tmp_path):
    """A crescent cut by a circle tangent inside it, its two tips meeting at one vertex, united with a taller disc: the
    bottom plane's hole touches its outer circle there, and the two pcurves put that vertex 1e-16 apart in (u,v) (read
    back from STEP, 1.1e-4 mm: the reader's fit), so their segments crossed and the face was left unmeshed (47 open
    edges with the quality mesher). One node now: the mesh has no open edge, and its only edges with more than two
    triangles lie on the pinch's line, where the B-rep's two cylinders are tangent (OCCT's mesh has the same); its
    volume is OCCT's of the solid, to the chords' loss."""
    import cadquery as cq

    solid = (cq.Workplane().circle(10).extrude(3).cut(cq.Workplane().center(4, 0).circle(6).extrude(3))
             .union(cq.Workplane().center(-3, 0).circle(7).extrude(5)).val())
    shape = solid.wrapped
    if via == "step":
        solid.exportStep(str(tmp_path / "crescent.step"))
        model = read_cad(tmp_path / "crescent.step")
    else:
        model = model_from_shape(shape)
    r = mesh_model(model, MeshParams(tolerance=tolerance, mesher=mesher))
    checks = check_mesh(r.mesh)
    assert not r.unmeshed_faces and r.within_tolerance
    assert checks.boundary_edges == 0 and checks.misoriented_edges == 0
    inc = edge_incidence(r.mesh.triangles)
    pinch = r.mesh.vertices[inc.edges[inc.count > 2]]
    assert 1 <= len(pinch) <= 4 and np.allclose(pinch[..., :2], [10, 0], atol=1e-4)  # STEP: the vertex 1.1e-5 off
    assert abs(checks.volume - _volume(shape)) < 0.02 * _volume(shape)


@pytest.fixture(scope="module")
def trimmed_surface_nut(tmp_path_factory):
    """(path, volume): a chamfered hexagon nut written as IGES trimmed surfaces (no topology: the reader places
    each cone of revolution by a mirroring matrix of its own and sewing orients the faces by their placed normals)."""
    import cadquery as cq

    nut = cq.Workplane().polygon(6, 20).extrude(8).faces(">Z").workplane().hole(10).edges("not |Z").chamfer(0.6)
    shape = nut.val().wrapped
    path = tmp_path_factory.mktemp("nut") / "nut_faces.igs"
    _iges_faces(shape, path)
    return path, _volume(shape)


@pytest.mark.parametrize("mesher", ["occt", "quality"])
def test_faces_mirrored_inside_their_shell_agree_with_their_neighbours(trimmed_surface_nut, mesher):
    """Those faces were wound by the mirrored-instance rule (a mirror turns the normal, so reverse), which is wrong
    for a face oriented by its own mirrored surface: 48 misoriented edges, and only after the read in a child (its
    BREP round trip turned the reader's +1 scale on the mirror into -1). Now oriented like their neighbours, and the
    same arrays whichever process read the file."""
    path, volume = trimmed_surface_nut
    model = read_cad(path)
    assert any(mirrors(f) for f in model.faces)
    direct = mesh_model(model, MeshParams(tolerance=0.1, mesher=mesher)).mesh
    _, r = mesh_file(path, "iges", MeshParams(tolerance=0.1, mesher=mesher))
    checks = check_mesh(r.mesh)
    assert checks.boundary_edges == checks.misoriented_edges == checks.inside_out_shells == 0
    assert manifold3d_accepts(r.mesh) and abs(checks.volume - volume) < 0.02 * volume
    assert np.array_equal(direct.triangles, r.mesh.triangles) and np.array_equal(direct.vertices, r.mesh.vertices)


def test_two_polygons_of_one_edge_are_not_kept(tmp_path):
    """A finer thread written as IGES trimmed surfaces: BRepMesh gave the top circle two polygons, 9 segments on the
    top plane and 5 on the core, and the weld, which knows an edge node by its parameter, left 14 edges open. The
    second face is meshed by ours from the first one's discretisation now."""
    shape = _thread(0.8, 6, 3, 0.6)
    _iges_faces(shape, tmp_path / "thread_faces.igs")
    r = mesh_model(read_cad(tmp_path / "thread_faces.igs"), MeshParams(tolerance=0.1))
    checks = check_mesh(r.mesh)
    assert checks.boundary_edges == checks.nonmanifold_edges == checks.misoriented_edges == 0
    assert "edge_mismatch" in r.fallback_faces.values() and r.within_tolerance
    assert abs(checks.volume - _volume(shape)) < 0.05 * _volume(shape)


@pytest.mark.parametrize("mesher", ["occt", "quality"])
def test_one_closed_trimmed_surface_is_sewn_to_itself(tmp_path, mesher):
    """A torus written as one IGES trimmed surface: its seams come as two pairs of free edges, and a file of one face
    was never sewn (136 open edges at 0.1 mm). Sewn onto itself it meshes closed."""
    import cadquery as cq

    shape = cq.Solid.makeTorus(30, 0.4).wrapped
    _iges_faces(shape, tmp_path / "torus.igs")
    model = read_cad(tmp_path / "torus.igs")
    assert model.sewn and len(model.faces) == 1
    r = mesh_model(model, MeshParams(tolerance=0.1, mesher=mesher))
    checks = check_mesh(r.mesh)
    assert checks.boundary_edges == checks.nonmanifold_edges == checks.misoriented_edges == 0 and r.within_tolerance


def test_straight_edges_keep_only_the_points_the_grading_cuts():
    """BRepMesh leaves a point a third along every line; the quality mesher drops it where every face of the edge
    keeps lines straight in (u,v), and cuts the line by its own rules alone: a 10 mm cube is 12 triangles on its 8
    corners; a 40 × 4 × 4 bar's long edges are cut into four equal steps (GRADE × the 40 × 4 faces' width 2A/P =
    320/88 mm: 10.9 mm, so ⌈40 / 10.9⌉ = 4), then the end ones halved (GROWTH: a step may be its midpoint's distance
    from the end, 5 mm, plus the 4 mm edges there), none at that third."""
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox

    cube = mesh_model(model_from_shape(BRepPrimAPI_MakeBox(10, 10, 10).Shape()),
                      MeshParams(tolerance=0.34, mesher="quality")).mesh
    assert (len(cube.vertices), cube.n_triangles) == (8, 12)
    assert check_mesh(cube).closed and abs(check_mesh(cube).volume - 1000) < 1e-6
    bar = mesh_model(model_from_shape(BRepPrimAPI_MakeBox(40, 4, 4).Shape()),
                     MeshParams(tolerance=0.34, mesher="quality")).mesh
    on_edge = bar.vertices[(np.abs(bar.vertices[:, 1]) < 1e-9) & (np.abs(bar.vertices[:, 2]) < 1e-9)]
    assert np.allclose(np.sort(on_edge[:, 0]), [0, 5, 10, 20, 30, 35, 40])
    assert check_mesh(bar).closed and manifold3d_accepts(bar)


def test_thin_strips_get_one_long_edge_staggered_so_their_triangles_are_isosceles():
    """A chamfer 0.5 mm wide along a 40 mm edge is a strip: both long edges cut alike by the grading, a triangle
    spans it from one to the other, right-angled (22° at 2.5 segments per width) where their points face each other.
    One long edge's points are moved to the middles of its segments: every strip triangle's apex then lies between
    the other edge's points, its smallest angle over 30°. A 40 × 4 × 4 bar's four sides, strips sharing edges, get
    alternate edges moved, so each side is staggered."""
    import cadquery as cq

    from amprep.geometry.measure.regularity import min_angles

    shape = cq.Workplane().box(40, 20, 10).edges("|X").chamfer(0.5).val().wrapped
    r = mesh_model(model_from_shape(shape), MeshParams(tolerance=0.1, mesher="quality"))
    m = r.mesh
    assert check_mesh(m).closed and manifold3d_accepts(m) and r.max_error <= 0.1
    strips = [f for f in range(len(m.faces)) if np.ptp(m.vertices[np.unique(m.triangles[m.face_ids == f])], axis=0)[1:].max() < 0.6]
    assert len(strips) == 4
    for f in strips:
        t = m.triangles[m.face_ids == f]
        x = m.vertices[np.unique(t)]
        sides = np.unique(np.round(x[:, 1:], 6), axis=0, return_inverse=True)[1].ravel()
        xs = [np.sort(x[sides == k, 0]) for k in range(2)]
        assert len(xs[0]) >= 5 and abs(len(xs[0]) - len(xs[1])) == 1  # one edge has one point more: its ends half
        fewer, more = sorted(xs, key=len)
        assert (np.searchsorted(fewer, more[1:-1]) == np.arange(1, len(fewer))).all()  # strictly interleaved
        assert np.degrees(min_angles(m.vertices[t])).min() > 30
    bar = mesh_model(model_from_shape(cq.Workplane().box(40, 4, 4).val().wrapped),
                     MeshParams(tolerance=0.34, mesher="quality")).mesh
    assert np.degrees(min_angles(bar.corners)).min() > 30 and check_mesh(bar).closed


def test_boundary_loops_are_made_again_only_when_an_edge_changes(reference_solids):
    """A face's loops are kept while its edges keep their params (the same arrays) and collapses; a cut edge, or an
    edge's two ends made one node, makes them anew, and what is kept cannot be written to."""
    from amprep.geometry.cad.topology import Topology, face_edges
    from amprep.geometry.meshing.face_mesher import boundary_loops

    model = model_from_shape(reference_solids["plate_with_holes"])
    topo = Topology.of(model.shape)
    face = max(model.faces, key=lambda f: len(face_edges(f)))  # the top, with its holes
    first = boundary_loops(face, topo, 0.1, 0.5)
    assert boundary_loops(face, topo, 0.1, 0.5) is first
    with pytest.raises(ValueError):
        first[0]["uv"][0, 0] = 1.0
    edge = next(e for e in face_edges(face) if len(topo.edge_params[topo.edge_index(e)]) >= 2)
    ei = topo.edge_index(edge)
    params = topo.edge_params[ei]
    topo.edge_params[ei] = np.sort(np.append(params, params[:2].mean()))
    cut = boundary_loops(face, topo, 0.1, 0.5)
    assert cut is not first
    assert sum(len(lp["uv"]) for lp in cut) == sum(len(lp["uv"]) for lp in first) + 1
    topo.edge_params[ei] = params.copy()  # equal values, another array: made again, the same as before
    again = boundary_loops(face, topo, 0.1, 0.5)
    assert again is not cut and all(np.array_equal(a["uv"], b["uv"]) for a, b in zip(again, first, strict=True))
    _, v1, _, v2, _, _ = topo.edge_facts(edge)
    topo.merge_vertices(v1, v2)
    assert boundary_loops(face, topo, 0.1, 0.5) is not again
