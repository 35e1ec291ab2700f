"""BRepMesh in two passes: edges where only ruled faces meet at the tolerance, the others at half, as OCCT does."""

import numpy as np
import pytest
from OCP.BRep import BRep_Tool
from OCP.BRepAdaptor import BRepAdaptor_Curve
from OCP.GeomAbs import GeomAbs_Circle
from OCP.TopLoc import TopLoc_Location

from amprep.geometry.cad.read import model_from_shape, read_cad
from amprep.geometry.cad.surfaces import is_ruled
from amprep.geometry.cad.topology import Topology, face_edges
from amprep.geometry.core.checks import check_mesh, manifold3d_accepts
from amprep.geometry.meshing import brepmesh
from amprep.geometry.meshing.brepmesh import EDGE_TARGET, run_brepmesh
from amprep.geometry.meshing.occt_read import triangulation_arrays
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.pipeline import mesh_model
from tests.conftest import corpus


def _circle_segments(model):
    """{edge index: (radius, segment angles (k,), whether each face on it is ruled)} of every circular edge, from its
    polygon on each face (the same on both: checked)."""
    topo = Topology.of(model.shape)
    out = {}
    for face in model.faces:
        loc = TopLoc_Location()
        tri = BRep_Tool.Triangulation_s(face, loc)
        for edge in face_edges(face):
            curve = BRepAdaptor_Curve(edge)
            if curve.GetType() != GeomAbs_Circle or BRep_Tool.Degenerated_s(edge):
                continue
            poly = BRep_Tool.PolygonOnTriangulation_s(edge, tri, loc)
            steps = np.diff(np.sort([poly.Parameter(i) for i in range(1, poly.NbNodes() + 1)]))
            r, known, ruled = out.get(topo.edge_index(edge), (curve.Circle().Radius(), steps, []))
            assert np.allclose(known, steps)
            out[topo.edge_index(edge)] = (r, known, [*ruled, is_ruled(face)])
    return out


def _cylinder_with_rounded_top():
    import cadquery as cq

    return model_from_shape(cq.Workplane().circle(10).extrude(20).faces(">Z").edges().fillet(3).val().wrapped)


def test_faces_are_told_ruled_or_curved_both_ways(reference_solids):
    import cadquery as cq

    ruled = {name: {is_ruled(f) for f in model_from_shape(reference_solids[name]).faces}
             for name in ("sphere", "torus", "cylinder", "cone", "plate_with_holes")}
    assert ruled == {"sphere": {False}, "torus": {False}, "cylinder": {True}, "cone": {True},
                     "plate_with_holes": {True}}
    extruded = cq.Workplane().spline([(0, 0), (5, 3), (10, 0)]).close().extrude(4).val().wrapped
    assert all(is_ruled(f) for f in model_from_shape(extruded).faces)
    as1 = read_cad(corpus("as1_assembly_ap214.stp"))  # its round faces are B-splines of degree 1 × 3, 2 × 4 poles
    assert all(is_ruled(f) for f in as1.faces)
    loft = model_from_shape(reference_solids["bspline_loft"])
    assert not all(is_ruled(f) for f in loft.faces)


@pytest.mark.parametrize("tol", [0.1, 0.01])
def test_circles_between_ruled_faces_are_at_the_tolerance_and_next_to_a_torus_at_half(tol):
    """A cylinder with a rounded top: the bottom circle joins a plane and the cylinder and gets EDGE_TARGET × the
    tolerance as its sagitta, the circles of the torus fillet get OCCT's half; no segment turns through more than
    the angle asked for. With occt_edges every circle is at half the tolerance and half the angle."""
    model = _cylinder_with_rounded_top()
    run_brepmesh(model.shape, tol, MeshParams(tolerance=tol))
    circles = list(_circle_segments(model).values())
    bottom = [(r, s) for r, s, ruled in circles if all(ruled)]
    fillet = [(r, s) for r, s, ruled in circles if not all(ruled)]
    assert len(bottom) == 1 and len(fillet) == 3  # the fillet's two boundary circles and its seam (r = 3)
    assert max(s.max() for _, s in bottom + fillet) <= 0.5 + 1e-9
    for r, steps in fillet:
        assert (r * (1 - np.cos(steps / 2))).max() <= 0.5 * tol * (1 + 1e-6)
    r, steps = bottom[0]
    assert 0.5 * tol < (r * (1 - np.cos(steps / 2))).max() <= EDGE_TARGET * tol * (1 + 1e-6)
    run_brepmesh(model.shape, tol, MeshParams(tolerance=tol, occt_edges=True))
    for r, steps, _ in _circle_segments(model).values():
        assert steps.max() <= 0.25 + 1e-9 and (r * (1 - np.cos(steps / 2))).max() <= 0.5 * tol * (1 + 1e-6)


@pytest.mark.parametrize("tol", [0.1, 0.01, 0.001])
def test_a_cylinder_gets_fewer_triangles_than_from_occts_edges_within_the_tolerance(reference_solids, tol):
    """OCCT meshes a cylinder r=10 at 0.49× the tolerance (about 1.4× the segments needed): from edges at the
    tolerance it has fewer triangles, no face re-meshed, closed, and its error is near the tolerance but within it."""
    model = model_from_shape(reference_solids["cylinder"])
    occt = mesh_model(model, MeshParams(tolerance=tol, occt_edges=True))
    res = mesh_model(model, MeshParams(tolerance=tol))
    assert occt.fallback_faces == {} and occt.max_error < 0.6 * tol
    assert res.fallback_faces == {} and 0.85 * tol < res.max_error <= tol
    assert res.mesh.n_triangles <= 0.8 * occt.mesh.n_triangles
    c = check_mesh(res.mesh)
    assert c.closed and c.degenerate_triangles == 0 and manifold3d_accepts(res.mesh)


def test_holes_get_the_angle_asked_for_not_half():
    """Holes r=1.55 at 0.1 mm: the tolerance allows 0.70 rad segments, so the angle binds: 13 segments at
    angular 0.5 (BRepMesh given 0.5 would make 26), 7 at angular 1.0 (the tolerance then binds at 0.95 × 0.1)."""
    import cadquery as cq

    plate = cq.Workplane().box(20, 20, 3).faces(">Z").workplane().hole(3.1).val().wrapped
    model = model_from_shape(plate)
    counts = {}
    for angular in (0.5, 1.0):
        run_brepmesh(model.shape, 0.1, MeshParams(tolerance=0.1, angular=angular))
        counts[angular] = {len(s) for r, s, _ in _circle_segments(model).values()}
    run_brepmesh(model.shape, 0.1, MeshParams(tolerance=0.1, occt_edges=True))
    counts["occt"] = {len(s) for r, s, _ in _circle_segments(model).values()}
    step = 2 * np.arccos(1 - EDGE_TARGET * 0.1 / 1.55)
    assert counts == {0.5: {13}, 1.0: {int(np.ceil(2 * np.pi / step))}, "occt": {26}}


def test_faces_curved_both_ways_keep_their_first_pass_mesh(monkeypatch):
    """The second pass reuses the torus fillet's triangulation and the edges it shares (BRepMesh's consistency check):
    after it, the torus face's nodes are those the first pass made."""
    model = _cylinder_with_rounded_top()
    torus = next(i for i, f in enumerate(model.faces) if not is_ruled(f))
    seen = []
    real = brepmesh.BRepMesh_IncrementalMesh

    def spy(shape, p):
        out = real(shape, p)
        tri = BRep_Tool.Triangulation_s(model.faces[torus], TopLoc_Location())
        seen.append(triangulation_arrays(tri)[0] if tri is not None else None)
        return out

    monkeypatch.setattr(brepmesh, "BRepMesh_IncrementalMesh", spy)
    run_brepmesh(model.shape, 0.05, MeshParams(tolerance=0.05))
    assert len(seen) == 2 and seen[0] is not None and np.array_equal(seen[0], seen[1])


def test_ruled_b_spline_parts_lose_occts_excess_and_stay_closed_within_tolerance():
    """as1's round faces are ruled B-splines: from edges at the tolerance the assembly has ~45 % fewer triangles
    than from OCCT's edges at 0.1 mm, every solid closed, the error near the tolerance and within it."""
    model = read_cad(corpus("as1_assembly_ap214.stp"))
    occt = mesh_model(model, MeshParams(tolerance=0.1, occt_edges=True))
    res = mesh_model(model, MeshParams(tolerance=0.1))
    assert occt.max_error < 0.55 * 0.1 and 0.85 * 0.1 < res.max_error <= 0.1
    assert res.mesh.n_triangles < 0.7 * occt.mesh.n_triangles
    c = check_mesh(res.mesh)
    assert c.closed and c.degenerate_triangles == 0 and manifold3d_accepts(res.mesh)
