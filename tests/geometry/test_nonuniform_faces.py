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
from OCP.gp import gp_Pnt, gp_Vec
from OCP.TColgp import TColgp_Array2OfPnt

from amprep.geometry.cad.read import model_from_shape
from amprep.geometry.cad.surfaces import surface_of
from amprep.geometry.measure.angles import min_angles_at
from amprep.geometry.measure.regularity import regularity, summarize
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.pipeline import mesh_model
from amprep.geometry.meshing.uv_cdt import metric_uniform
from tests.geometry.test_independent_distance import _worst_distance

SHEETS = {  # x(s), y(t) of the fitted points at uniform parameters s, t in [0, 1]; the second one's fit overshoots:
    # x(u) < 0 by 1 µm just off u = 0, so its own normal turns over along that side
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
    default = mesh_model(model, MeshParams(tolerance=tol))
    q, q_default = (summarize(regularity(m.mesh.corners)) for m in (r, default))
    assert q.mean["angle"] >= max(0.58, q_default.mean["angle"] + 0.05), (q.mean, q_default.mean)
    assert q.bins["angle"][0] < 0.005 * r.mesh.n_triangles
    assert r.max_error <= tol
    assert _worst_distance(model, r.mesh, samples=150) <= tol * 1.001
    assert r.mesh.n_triangles <= 5 * default.mesh.n_triangles
    if name == "crowded":  # the degenerate sheet's fitted surface itself folds back (x < 0 by 1 µm near u = 0)
        assert _folded(model, r.mesh) == 0


def _folded(model, mesh) -> int:  # type: ignore[no-untyped-def]
    """Sampled triangles whose normal points against the face's surface normal S_u × S_v at their centroid's
    projection, where that normal is defined (|S_u × S_v| over 1 % of its median: not at a degenerate side)."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepAdaptor import BRepAdaptor_Surface
    from OCP.GeomAPI import GeomAPI_ProjectPointOnSurf
    from OCP.TopAbs import TopAbs_REVERSED

    face = model.faces[0]
    surface = BRep_Tool.Surface_s(face)
    c = mesh.corners
    normal = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
    found = []
    for k in range(0, len(c), max(1, len(c) // 400)):
        proj = GeomAPI_ProjectPointOnSurf(gp_Pnt(*map(float, c[k].mean(axis=0))), surface)
        u, v = proj.LowerDistanceParameters()
        d1u, d1v, p = gp_Vec(), gp_Vec(), gp_Pnt()
        BRepAdaptor_Surface(face).D1(u, v, p, d1u, d1v)
        n = np.cross([d1u.X(), d1u.Y(), d1u.Z()], [d1v.X(), d1v.Y(), d1v.Z()])
        if face.Orientation() == TopAbs_REVERSED:
            n = -n
        found.append((np.linalg.norm(n), np.dot(n, normal[k]) < 0))
    size, against = np.array(found).T
    return int((against.astype(bool) & (size > 0.01 * np.median(size))).sum())


def test_the_lattice_refuses_rows_that_cannot_take_one_step():
    """The degenerate sheet at 0.05 mm is a rectangle the lattice would take, its rows set by the corner that needs
    them closest: flat triangles everywhere else (mean angle regularity 0.15). It goes to the Delaunay path."""
    model = model_from_shape(_sheet("degenerate side"))
    r = mesh_model(model, MeshParams(tolerance=0.05, mesher="quality"))
    assert [f.meshed_by for f in r.mesh.faces] == ["quality"]
    assert summarize(regularity(r.mesh.corners)).mean["angle"] >= 0.6
    crowded = mesh_model(model_from_shape(_sheet("crowded")), MeshParams(tolerance=0.01, mesher="quality"))
    assert [f.meshed_by for f in crowded.mesh.faces] == ["lattice"]  # a spread rows can take (median 1.8) stays one


def test_smoothing_stops_when_a_round_gains_little(monkeypatch):
    """The smoothing rounds stop once one raises the mean smallest angle by under SMOOTH_GAIN: fewer node sets moved
    than with every round run, for a mean angle regularity within about that gain of theirs."""
    from amprep.geometry.meshing import lattice, local_refine

    model = model_from_shape(_sheet("crowded"))
    monkeypatch.setattr(lattice, "LATTICE_MIN", np.inf)  # the Delaunay path, which smooths, at any LATTICE_MIN
    sets, inner = [], local_refine._independent

    def counted(*args):  # type: ignore[no-untyped-def]
        sets[-1] += 1
        return inner(*args)

    monkeypatch.setattr(local_refine, "_independent", counted)
    q = {}
    for gain in (local_refine.SMOOTH_GAIN, -np.inf):
        monkeypatch.setattr(local_refine, "SMOOTH_GAIN", gain)
        sets.append(0)
        r = mesh_model(model, MeshParams(tolerance=0.05, mesher="quality"))
        q[gain] = summarize(regularity(r.mesh.corners)).mean["angle"]
    assert 0 < sets[0] < sets[1]
    assert q[-np.inf] - q[local_refine.SMOOTH_GAIN] < 0.02, q


def test_smoothing_leaves_nodes_whose_move_is_tiny(monkeypatch):
    """A node whose move is under SMOOTH_MIN_MOVE × its shortest side stays, and its star is not measured: with the
    bound at infinity no node moves and no triangle is measured; at its value fewer triangles are measured than with
    none, for a mean angle regularity within 0.002 and every triangle still within the tolerance."""
    from amprep.geometry.meshing import face_mesher, lattice, local_refine

    model = model_from_shape(_sheet("crowded"))
    monkeypatch.setattr(lattice, "LATTICE_MIN", np.inf)  # the Delaunay path, which smooths
    seen, inner = [], local_refine.smooth_on_surface
    monkeypatch.setattr(face_mesher, "smooth_on_surface", lambda patch, *a: seen.append((patch, a)) or inner(patch, *a))
    mesh_model(model, MeshParams(tolerance=0.05, mesher="quality"))
    patch, args = seen[0]
    measured, measure = [0], local_refine.triangle_chordal_error

    def counted(corners, *a, **k):  # type: ignore[no-untyped-def]
        measured[0] += len(corners)
        return measure(corners, *a, **k)

    monkeypatch.setattr(local_refine, "triangle_chordal_error", counted)
    out = {}
    for bound in (np.inf, 0.0, local_refine.SMOOTH_MIN_MOVE):
        monkeypatch.setattr(local_refine, "SMOOTH_MIN_MOVE", bound)
        measured[0] = 0
        smoothed = inner(patch, *args)
        out[bound] = (measured[0], smoothed)
    assert out[np.inf][0] == 0 and np.array_equal(out[np.inf][1].nodes, patch.nodes)
    assert 0 < out[local_refine.SMOOTH_MIN_MOVE][0] < out[0.0][0]
    angle = {b: min_angles_at(s.nodes, s.tris).mean() for b, (_, s) in out.items()}
    assert angle[0.0] > angle[np.inf]  # the smoothing does something here
    assert abs(angle[local_refine.SMOOTH_MIN_MOVE] - angle[0.0]) < np.radians(60) * 0.002, angle
    assert out[local_refine.SMOOTH_MIN_MOVE][1].error.max() <= 0.05
