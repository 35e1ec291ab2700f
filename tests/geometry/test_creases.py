"""A B-spline face folded along a C0 knot line is split there before meshing (cad/creases.py): the crease becomes a
shared edge, so no triangle cuts across it and the solid stays closed by topology."""

import numpy as np
import pytest
from OCP.BRepBuilderAPI import (
    BRepBuilderAPI_MakeEdge,
    BRepBuilderAPI_MakeFace,
    BRepBuilderAPI_MakeVertex,
    BRepBuilderAPI_MakeWire,
    BRepBuilderAPI_NurbsConvert,
)
from OCP.BRepExtrema import BRepExtrema_DistShapeShape
from OCP.BRepGProp import BRepGProp
from OCP.BRepPrimAPI import BRepPrimAPI_MakePrism
from OCP.Geom import Geom_BSplineCurve
from OCP.gp import gp_Pnt, gp_Vec
from OCP.GProp import GProp_GProps
from OCP.TColgp import TColgp_Array1OfPnt
from OCP.TColStd import TColStd_Array1OfInteger, TColStd_Array1OfReal

from amprep.geometry.cad.creases import crease_angle, split_at_creases
from amprep.geometry.cad.read import model_from_shape, read_cad
from amprep.geometry.core.checks import check_mesh, manifold3d_accepts
from amprep.geometry.measure.defects import self_intersections
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.pipeline import mesh_model
from tests.conftest import corpus

KINK = 2 * np.degrees(np.arctan(2 / 5))  # the profile's turn at x = 10: (5, −2) then (5, 2)


def _kinked_prism(nurbs: bool = True):
    """A prism 10 high on a profile whose top side is a quadratic B-spline with a double knot at (10, 0): its side
    face over that curve (a surface of extrusion, or with `nurbs` a B-spline surface, as every face converted) is
    folded along the vertical line x = 10."""
    pts = [(0, 0), (5, 2), (10, 0), (15, 2), (20, 0)]
    poles = TColgp_Array1OfPnt(1, len(pts))
    for i, (x, y) in enumerate(pts):
        poles.SetValue(i + 1, gp_Pnt(x, y, 0))
    knots, mults = TColStd_Array1OfReal(1, 3), TColStd_Array1OfInteger(1, 3)
    for i, (k, m) in enumerate(((0.0, 3), (1.0, 2), (2.0, 3))):
        knots.SetValue(i + 1, k)
        mults.SetValue(i + 1, m)
    wire = BRepBuilderAPI_MakeWire()
    wire.Add(BRepBuilderAPI_MakeEdge(Geom_BSplineCurve(poles, knots, mults, 2)).Edge())
    for a, b in (((20, 0), (20, -10)), ((20, -10), (0, -10)), ((0, -10), (0, 0))):
        wire.Add(BRepBuilderAPI_MakeEdge(gp_Pnt(*a, 0), gp_Pnt(*b, 0)).Edge())
    prism = BRepPrimAPI_MakePrism(BRepBuilderAPI_MakeFace(wire.Wire()).Face(), gp_Vec(0, 0, 10)).Shape()
    return BRepBuilderAPI_NurbsConvert(prism, True).Shape() if nurbs else prism


def _volume(shape) -> float:
    props = GProp_GProps()
    BRepGProp.VolumeProperties_s(shape, props)
    return props.Mass()


def _straddling(c: np.ndarray) -> int:
    """Triangles (corners (m, 3, 3)) of the folded face's side with corners on both sides of the fold's plane x = 10."""
    n = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
    upright = np.abs(n[:, 2]) < 0.5 * np.linalg.norm(n, axis=1)  # not the caps
    curved = (c[:, :, 1] > 1e-6).any(axis=1)  # the curved side lies at y > 0 except at its ends and the kink
    x = c[:, :, 0]
    return int((upright & curved & (x.min(axis=1) < 10 - 1e-6) & (x.max(axis=1) > 10 + 1e-6)).sum())


@pytest.mark.parametrize("mesher,nurbs", [("occt", True), ("quality", True), ("occt", False), ("quality", False)])
def test_a_folded_face_is_split_along_its_crease_and_meshed_across_none_of_it(mesher, nurbs):
    shape = _kinked_prism(nurbs)
    angles = [crease_angle(f) for f in model_from_shape(shape).faces]
    assert max(angles) == pytest.approx(KINK, abs=0.5) and sorted(angles)[-2] < 0.01  # one folded face, the rest not
    split, n = split_at_creases(shape)
    assert n == 1
    model = model_from_shape(split)
    assert len(model.faces) == len(model_from_shape(shape).faces) + 1
    tol = 0.01
    mesh = mesh_model(model, MeshParams(tolerance=tol, mesher=mesher)).mesh
    checks = check_mesh(mesh)
    assert checks.closed and manifold3d_accepts(mesh) and self_intersections(mesh)[0] == 0
    assert _straddling(mesh.corners) == 0
    assert checks.volume == pytest.approx(_volume(shape), rel=1e-3)  # OCCT's volume of the solid, not ours
    far = 0.0  # every vertex on the solid by OCCT's distance
    for p in mesh.vertices[:: max(1, len(mesh.vertices) // 200)]:
        dist = BRepExtrema_DistShapeShape(BRepBuilderAPI_MakeVertex(gp_Pnt(*p)).Vertex(), shape)
        far = max(far, dist.Value())
    assert far <= tol
    unsplit = mesh_model(model_from_shape(shape), MeshParams(tolerance=tol, mesher=mesher)).mesh
    assert _straddling(unsplit.corners) > 0  # without the split the mesh cuts across the fold


def test_the_dtmb_hull_is_split_along_its_two_chines_and_meshed_within_tolerance():
    model = read_cad(corpus("dtmb5415_bow_hull.iges"))
    assert len(model.faces) == 3 and any("creases" in n for n in model.notes)
    result = mesh_model(model, MeshParams(tolerance=0.1))
    assert result.max_error <= 0.1 and not result.unmeshed_faces
    checks = check_mesh(result.mesh)
    assert checks.nonmanifold_edges == 0 and checks.misoriented_edges == 0


def test_a_folded_face_placed_twice_is_split_in_both_placements():
    """One solid placed at two locations (its faces shared, as an assembly's instances): a ShapeBuild_ReShape pass
    replaces one placement, so a second pass splits the other."""
    from OCP.BRep import BRep_Builder
    from OCP.gp import gp_Trsf
    from OCP.TopLoc import TopLoc_Location
    from OCP.TopoDS import TopoDS_Compound

    prism = _kinked_prism()
    both = TopoDS_Compound()
    builder = BRep_Builder()
    builder.MakeCompound(both)
    for dy in (0.0, 30.0):
        move = gp_Trsf()
        move.SetTranslation(gp_Vec(0, dy, 0))
        builder.Add(both, prism.Moved(TopLoc_Location(move)))
    split, n = split_at_creases(both)
    model = model_from_shape(split)
    assert n == 2 and len(model.faces) == 2 * len(model_from_shape(prism).faces) + 2
    mesh = mesh_model(model, MeshParams(tolerance=0.01)).mesh
    checks = check_mesh(mesh)
    assert checks.closed and checks.shells == 2
    assert checks.volume == pytest.approx(2 * _volume(prism), rel=1e-3)
    c = mesh.corners
    second = c[:, :, 1].min(axis=1) > 15
    assert second.any() and (~second).any()
    assert _straddling(c[~second]) == 0 and _straddling(c[second] - [0, 30, 0]) == 0  # the second moved onto the first
