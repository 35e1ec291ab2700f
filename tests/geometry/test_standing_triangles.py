"""The quality mesher's boundary segments on curved faces are short enough for a triangle with Triangle's 30°
angles to stand on them within the tolerance (shared_edges.bend_sizes), on edges it grades and on a lattice's side
edges (the rows cut for the free-form face beside it). On a longer segment the only triangles that keep the tolerance
are slivers tilted off the surface: OCCT's hammer.brep at 0.1 mm had a B-spline face whose 86 mm segments carried
them, and the seating of its boundary onto its neighbour's (a 0.3 mm B-rep gap along the surface) took it to
0.115 mm. On an analytic face off the lattice, long straight sides beside small cells made fans of needles (NIST
CTC-02's fillets). Forced here with faces built to have those shapes; the measure checked against closed forms."""

from __future__ import annotations

import cadquery as cq
import numpy as np
import pytest
from OCP.Approx import Approx_IsoParametric
from OCP.BRepAlgoAPI import BRepAlgoAPI_Cut
from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace, BRepBuilderAPI_Sewing
from OCP.BRepPrimAPI import BRepPrimAPI_MakeCylinder
from OCP.GeomAbs import GeomAbs_C2
from OCP.GeomAPI import GeomAPI_PointsToBSplineSurface
from OCP.gp import gp_Ax2, gp_Ax3, gp_Cylinder, gp_Dir, gp_Pnt
from OCP.TColgp import TColgp_Array2OfPnt

from amprep.geometry.cad.read import model_from_shape
from amprep.geometry.cad.surfaces import surface_of, uv_extent
from amprep.geometry.measure.regularity import min_angles
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.pipeline import mesh_model
from amprep.geometry.meshing.uv_seed import standing_error
from tests.geometry.test_independent_distance import _worst_distance

TOL = 0.1


def _sheet(z, x0: float, x1: float, length: float):  # type: ignore[no-untyped-def]
    """A B-spline face fitted to z(x) over [x0, x1] × [0, length], flat along y."""
    n, m = 33, 9
    pts = TColgp_Array2OfPnt(1, n, 1, m)
    for i in range(n):
        for j in range(m):
            x = x0 + (x1 - x0) * i / (n - 1)
            pts.SetValue(i + 1, j + 1, gp_Pnt(x, length * j / (m - 1), z(x)))
    surface = GeomAPI_PointsToBSplineSurface(pts, Approx_IsoParametric, 3, 3, GeomAbs_C2, 1e-5).Surface()
    return BRepBuilderAPI_MakeFace(surface, 1e-6).Face()


def _drilled(face, x: float, y: float):  # type: ignore[no-untyped-def]
    """The face with a vertical 5 mm hole at (x, y): two loops, so no lattice."""
    tool = BRepPrimAPI_MakeCylinder(gp_Ax2(gp_Pnt(x, y, -100), gp_Dir(0, 0, 1)), 5.0, 400).Shape()
    return BRepAlgoAPI_Cut(face, tool).Shape()


def _sewn(*faces):  # type: ignore[no-untyped-def]
    sew = BRepBuilderAPI_Sewing(1e-3)
    for f in faces:
        sew.Add(f)
    sew.Perform()
    return sew.SewedShape()


def _gentle_beside_curved():  # type: ignore[no-untyped-def]
    """Two B-spline faces meeting along the straight line x = 0: gently curved across it on one side (long segments
    do there), curved 27× as much on the other, drilled."""
    gentle = _sheet(lambda x: 0.0015 * x * x, -80, 0, 300)
    return _sewn(gentle, _drilled(_sheet(lambda x: 0.04 * x * x, 0, 80, 300), 40, 150))


def _cylinder_beside_curved():  # type: ignore[no-untyped-def]
    """A quarter of a 200 mm cylinder (a lattice: its rows 16 mm apart, the line x = 0 one of its sides) beside a
    drilled B-spline face curved across that line with a 5 mm radius."""
    axis = gp_Ax3(gp_Pnt(-200, 0, 0), gp_Dir(0, 1, 0), gp_Dir(1, 0, 0))
    quarter = BRepBuilderAPI_MakeFace(gp_Cylinder(axis, 200.0), 0.0, np.pi / 2, 0.0, 400.0).Face()
    return _sewn(quarter, _drilled(_sheet(lambda x: 0.1 * x * x, 0, 60, 400), 30, 200))


def _standing_angles(mesh, face: int, shared: np.ndarray) -> np.ndarray:  # type: ignore[no-untyped-def]
    """Smallest angles (deg) of the face's triangles with a side whose two ends lie on the line x = 0 (`shared`:
    (n,) bool per vertex)."""
    tris = mesh.triangles[mesh.face_ids == face]
    on = shared[tris]
    standing = tris[(on[:, [0, 1, 2]] & on[:, [1, 2, 0]]).any(axis=1)]
    return np.degrees(min_angles(mesh.vertices[standing]))


@pytest.mark.parametrize("build", [_gentle_beside_curved, _cylinder_beside_curved])
def test_free_form_face_stands_on_the_shared_edge_without_slivers(build):
    model = model_from_shape(build())
    r = mesh_model(model, MeshParams(tolerance=TOL, mesher="quality"))
    curved = [i for i, f in enumerate(r.mesh.faces) if f.surface_type == "bspline"][-1]
    if build is _cylinder_beside_curved:
        assert r.mesh.faces[0].meshed_by == "lattice"  # the rows were cut, the lattice kept
    shared = (np.abs(r.mesh.vertices[:, 0]) < 1e-6) & (np.abs(r.mesh.vertices[:, 2]) < 1e-6)
    angles = _standing_angles(r.mesh, curved, shared)
    assert len(angles) >= 4  # the line was found
    # before: 0.85° (gentle beside curved: the line cut to the gentle face's needs) and 9.6° (the rows 16 mm apart)
    assert angles.min() >= 15.0, np.sort(angles)[:5]
    assert r.max_error <= TOL
    assert _worst_distance(model, r.mesh, samples=80) <= TOL * 1.001


def _unit_error(face, uv: np.ndarray, along: np.ndarray, apex: float) -> float:  # type: ignore[no-untyped-def]
    s = surface_of(face)
    step = np.full((1, 2), 1e-4) * uv_extent(s)
    return float(standing_error(s, uv[None], step, np.zeros(2), along[None], apex)[0])


@pytest.mark.parametrize("apex", [0.29, 0.5])
def test_standing_error_matches_closed_forms(apex):
    # a sphere: the triangle's angle at its apex is 90° or more, so the worst point is its base's middle: 1/(8R)
    sphere = cq.Workplane().sphere(12.0).faces().val().wrapped
    s = surface_of(sphere)
    uv = np.array([0.7, 0.3])
    p = s.evaluate(uv[None])[0]
    along = np.cross(p, [0.0, 0.0, 1.0])
    assert _unit_error(sphere, uv, along, apex) == pytest.approx(1 / (8 * 12.0), rel=1e-3)
    # a cylinder of radius 4: along its axis only the apex's rise across counts (apex²/(8R)), around it the base's
    # chord (1/(8R)) and the rise along the flat axis adds nothing
    side = [f for f in cq.Workplane().cylinder(10.0, 4.0).faces().vals() if f.geomType() == "CYLINDER"][0].wrapped
    c = surface_of(side)
    uv = np.array([1.0, 0.0]) * uv_extent(c) * 0.3 + np.array([0.0, -2.0])
    assert _unit_error(side, uv, np.array([0.0, 0.0, 1.0]), apex) == pytest.approx(apex**2 / (8 * 4.0), rel=1e-3)
    p = c.evaluate(uv[None])[0]
    around = np.cross([0.0, 0.0, 1.0], p)
    assert _unit_error(side, uv, around, apex) == pytest.approx(1 / (8 * 4.0), rel=1e-3)


def _fillet_cut_slant():  # type: ignore[no-untyped-def]
    """A 320 mm bar with a 6 mm fillet along one side, both ends cut at 35°: the fillet is a quarter cylinder whose
    ends are ellipses (not iso-lines: no lattice) and whose two sides are 320 mm straight lines (NIST CTC-02 has such
    faces)."""
    bar = cq.Workplane().box(40, 40, 320).edges("|Z and >X and >Y").fillet(6)
    cut = cq.Workplane().box(400, 400, 200).rotate((0, 0, 0), (1, 0, 0), 35)
    return bar.cut(cut.translate((0, 0, 230))).cut(cut.translate((0, 0, -230))).val().wrapped


@pytest.mark.parametrize("tolerance", [0.1, 0.01])
def test_analytic_face_off_the_lattice_stands_on_its_straight_sides(tolerance):
    """The fillet's sides were graded to the face's width alone (27 mm segments beside 2 mm cells): fans of needles,
    2.8° at 0.1 mm and 0.36° at 0.01 mm. Cut by the standing rule (the analytic face's own target, its edges being
    discretised at it): the cylinder's triangles are ≥ 7°, within the tolerance by OCCT's distance."""
    model = model_from_shape(_fillet_cut_slant())
    r = mesh_model(model, MeshParams(tolerance=tolerance, mesher="quality"))
    fillet = [i for i, f in enumerate(r.mesh.faces) if f.surface_type == "cylinder"]
    assert len(fillet) == 1 and r.mesh.faces[fillet[0]].meshed_by == "quality"
    tris = r.mesh.triangles[r.mesh.face_ids == fillet[0]]
    assert np.degrees(min_angles(r.mesh.vertices[tris])).min() >= 7.0
    assert r.max_error <= tolerance
    assert _worst_distance(model, r.mesh, samples=80) <= tolerance * 1.001
