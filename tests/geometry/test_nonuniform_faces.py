"""The quality mesher on faces with no single scale to their (u,v) lengths, forced: B-spline sheets fitted with
uniform parameters to points crowded toward one corner (|S_u| and |S_v| vary 10–30× over the face, or vanish along a
side). Each cell is judged by the surface's own lengths, the mesh finished by flips and smoothing measured in space,
and the lattice refuses rows that cannot take one step: regular triangles within the tolerance (by OCCT's distance,
not our measure), where one scale gave a mean angle regularity of 0.15–0.45."""

from __future__ import annotations

import numpy as np
import pytest
from OCP.Approx import Approx_IsoParametric
from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
from OCP.GeomAbs import GeomAbs_C2
from OCP.GeomAPI import GeomAPI_PointsToBSplineSurface
from OCP.gp import gp_Pnt
from OCP.TColgp import TColgp_Array2OfPnt

from amprep.geometry.cad.read import model_from_shape
from amprep.geometry.cad.surfaces import surface_of
from amprep.geometry.measure.regularity import regularity, summarize
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.pipeline import mesh_model
from amprep.geometry.meshing.uv_cdt import metric_uniform
from tests.geometry.test_independent_distance import _worst_distance

SHEETS = {  # x(s), y(t) of the fitted points at uniform parameters s, t in [0, 1]
    "crowded": (lambda s: 100 * (0.1 * s + 0.9 * s**3), lambda t: 60 * (0.2 * t + 0.8 * t**2)),
    "degenerate side": (lambda s: 100 * s**2.5, lambda t: 60 * t**2),  # |S_u| = 0 along u = 0, |S_v| along v = 0
}


def _sheet(name: str):  # type: ignore[no-untyped-def]
    fx, fy = SHEETS[name]
    n, m = 12, 9
    pts = TColgp_Array2OfPnt(1, n, 1, m)
    for i in range(n):
        for j in range(m):
            x, y = fx(i / (n - 1)), fy(j / (m - 1))
            pts.SetValue(i + 1, j + 1, gp_Pnt(x, y, 10 * np.sin(x / 30) * np.cos(y / 25)))
    surface = GeomAPI_PointsToBSplineSurface(pts, Approx_IsoParametric, 3, 3, GeomAbs_C2, 1e-3).Surface()
    return BRepBuilderAPI_MakeFace(surface, 1e-6).Face()


@pytest.mark.parametrize("tol", [0.34, 0.1, 0.05, 0.01])
@pytest.mark.parametrize("name", sorted(SHEETS))
def test_regular_and_within_tolerance_where_no_single_scale_fits(name, tol):
    face = _sheet(name)
    uv = np.stack(np.meshgrid(np.linspace(0, 1, 9), np.linspace(0, 1, 9)), -1).reshape(-1, 2)
    assert not metric_uniform(surface_of(face), uv)  # the case forced: one scale does not fit
    model = model_from_shape(face)
    r = mesh_model(model, MeshParams(tolerance=tol, mesher="quality"))
    q = summarize(regularity(r.mesh.corners))
    assert q.mean["angle"] >= 0.6, q.mean
    assert q.bins["angle"][0] < 0.005 * r.mesh.n_triangles
    assert r.max_error <= tol
    assert _worst_distance(model, r.mesh, samples=150) <= tol * 1.001
    default = mesh_model(model, MeshParams(tolerance=tol))
    assert r.mesh.n_triangles <= 5 * default.mesh.n_triangles


def test_the_lattice_refuses_rows_that_cannot_take_one_step():
    """The degenerate sheet at 0.05 mm is a rectangle the lattice would take, its rows set by the corner that needs
    them closest: flat triangles everywhere else (mean angle regularity 0.15). It goes to the Delaunay path."""
    model = model_from_shape(_sheet("degenerate side"))
    r = mesh_model(model, MeshParams(tolerance=0.05, mesher="quality"))
    assert [f.meshed_by for f in r.mesh.faces] == ["quality"]
    assert summarize(regularity(r.mesh.corners)).mean["angle"] >= 0.6
    crowded = mesh_model(model_from_shape(_sheet("crowded")), MeshParams(tolerance=0.01, mesher="quality"))
    assert [f.meshed_by for f in crowded.mesh.faces] == ["lattice"]  # a spread rows can take (median 1.8) stays one
