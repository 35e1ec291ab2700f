"""The default mesher's ruled faces: a cone's apex a fan, a frustum a strip, from the boundary alone
(face_mesher.ruled_patch)."""

import numpy as np
import pytest

from amprep.geometry.cad.read import model_from_shape, read_cad
from amprep.geometry.core.checks import check_mesh
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.pipeline import mesh_model
from tests.conftest import corpus
from tests.geometry.test_mesher import _closed_solid, _sample_corners


def _cone_distance(p: np.ndarray, r: float, h: float) -> np.ndarray:
    """(n,) distance of points (n, 3) from the cone of base radius r at z = 0 and apex (0, 0, h), near its lateral
    face: from the line h·ρ + r·z = r·h in the (ρ, z) half-plane, not from our (u,v) sampling."""
    rho = np.linalg.norm(p[:, :2], axis=1)
    return np.abs(h * rho + r * p[:, 2] - r * h) / np.hypot(h, r)


def _faces_of(mesh, kind: str) -> np.ndarray:  # type: ignore[no-untyped-def]
    """(m,) bool: the triangles on faces of surface type `kind`."""
    return np.isin(mesh.face_ids, [f.id for f in mesh.faces if f.surface_type == kind])


@pytest.mark.parametrize("tol", [0.1, 0.01, 0.001])
def test_a_cones_apex_is_one_fan_within_the_tolerance(reference_solids, tol):
    """BRepMesh's grid on the cone is over the tolerance at its apex; the default mesher meshes it again as a fan, one
    triangle per segment of its rim (the disc's rim points), within the tolerance by the exact distance."""
    model = model_from_shape(reference_solids["cone"])  # r 10, h 20
    mesh = mesh_model(model, MeshParams(tolerance=tol)).mesh
    _closed_solid(mesh)
    cone = _faces_of(mesh, "cone")
    assert [f.meshed_by for f in mesh.faces if f.surface_type == "cone"] == ["ruled"]
    rim = np.flatnonzero((np.abs(mesh.vertices[:, 2]) < 1e-9) & (np.abs(np.linalg.norm(mesh.vertices[:, :2], axis=1) - 10) < 1e-6))
    assert cone.sum() == len(rim)  # a closed rim of n points: n segments, n triangles
    assert _cone_distance(_sample_corners(mesh.corners[cone]), 10, 20).max() <= tol * 1.001
    first = mesh_model(model, MeshParams(tolerance=tol, enforce_tolerance=False)).mesh
    assert cone.sum() < _faces_of(first, "cone").sum()


def test_a_nurbs_cone_is_a_fan_too():
    """The cone converted to a rational B-spline (degree 1 along its rulings, as a CAD round trip leaves it): the same
    fan, within the tolerance of the exact cone it still is."""
    import cadquery as cq
    from OCP.BRepBuilderAPI import BRepBuilderAPI_NurbsConvert

    nurbs = BRepBuilderAPI_NurbsConvert(cq.Solid.makeCone(10, 0, 20).wrapped, True).Shape()
    mesh = mesh_model(model_from_shape(nurbs), MeshParams(tolerance=0.01)).mesh
    _closed_solid(mesh)
    high = np.zeros(len(mesh.faces), bool)  # the lateral face: the one up to the apex (the disc is a B-spline too)
    high[mesh.face_ids[mesh.corners[:, :, 2].max(axis=1) > 1e-6]] = True
    assert [f.meshed_by for f in mesh.faces if high[f.id]] == ["ruled"]
    lateral = high[mesh.face_ids]
    assert _cone_distance(_sample_corners(mesh.corners[lateral]), 10, 20).max() <= 0.01 * 1.001


def test_a_frustum_is_one_strip_and_a_sphere_is_not_ruled():
    """A frustum's lateral face between its two circles: one strip, each triangle on a segment of one circle, within
    the tolerance of the exact cone; a sphere has no straight lines to stand on."""
    import cadquery as cq

    from amprep.geometry.cad.surfaces import surface_of
    from amprep.geometry.cad.topology import Topology
    from amprep.geometry.meshing.face_mesher import bare_ruled_seam, boundary_loops, ruled_direction, ruled_patch

    tol = 0.01
    model = model_from_shape(cq.Solid.makeCone(10, 4, 12).wrapped)
    topo = Topology.of(model.shape)
    k = next(i for i, f in enumerate(model.faces) if surface_of(f).surface_type == "cone")
    face, surface = model.faces[k], surface_of(model.faces[k])
    boundary_loops(face, topo, tol, 0.5)  # every edge discretised
    bare_ruled_seam(face, surface, topo)
    patch = ruled_patch(k, face, boundary_loops(face, topo, tol, 0.5), surface, tol)
    assert patch is not None and patch.meshed_by == "ruled"
    z = patch.nodes[:, 2]
    bottom, top = int((np.abs(z) < 1e-9).sum()), int((np.abs(z - 12) < 1e-9).sum())
    assert len(patch.tris) == (bottom - 1) + (top - 1)  # both circles' segments (each has its seam point twice)
    # the frustum's cone: apex at z = 12 · 10 / 6 = 20
    assert _cone_distance(_sample_corners(patch.nodes[patch.tris]), 10, 20).max() <= tol * 1.001
    sphere = model_from_shape(cq.Solid.makeSphere(12, angleDegrees1=-90, angleDegrees2=90).wrapped)
    assert ruled_direction(surface_of(sphere.faces[0])) is None


def test_ctc02s_drill_points_are_fans():
    """CTC-02's 74 apex cones (drill points) at 0.01 mm: each a fan within the tolerance, the part closed, and fewer
    triangles on its cones than BRepMesh's own grid, which is over the tolerance there."""
    model = read_cad(corpus("nist_ctc02_ap242.stp"))
    r = mesh_model(model, MeshParams(tolerance=0.01))
    assert r.within_tolerance and check_mesh(r.mesh).closed
    apex = [f for f in r.mesh.faces if f.surface_type == "cone" and f.meshed_by == "ruled"]
    assert len(apex) >= 70
    first = mesh_model(model, MeshParams(tolerance=0.01, enforce_tolerance=False)).mesh
    assert _faces_of(r.mesh, "cone").sum() < 0.5 * _faces_of(first, "cone").sum()
