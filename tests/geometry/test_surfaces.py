"""Our numpy surface evaluators against OCCT's own (the reference) on every face of real parts."""

import numpy as np
import pytest
from OCP.BRepAdaptor import BRepAdaptor_Surface
from OCP.BRepTools import BRepTools

from amprep.geometry.cad.read import read_cad
from amprep.geometry.cad.surfaces import surface_of
from tests.conftest import corpus


@pytest.mark.parametrize("name", ["nist_ctc02_ap242.stp", "occt_top_invalid.brep", "voron_hotend_mount_dragon.step",
                                  "bspline_45_faces.iges", "as1_assembly_ap214.stp"])
def test_every_face_matches_occt_to_1e9_relative(name):
    rng = np.random.default_rng(7)
    model = read_cad(corpus(name))
    seen = set()
    for face in model.faces:
        s = surface_of(face)
        seen.add(s.surface_type)
        u0, u1, v0, v1 = BRepTools.UVBounds_s(face)
        uv = rng.random((40, 2)) * [u1 - u0, v1 - v0] + [u0, v0]
        ad = BRepAdaptor_Surface(face, True)
        ref = np.array([ad.Value(u, v).Coord() for u, v in uv])
        got = s.evaluate(uv)
        scale = max(1.0, float(np.abs(ref).max()))
        assert np.isfinite(got).all()
        assert np.abs(got - ref).max() <= 1e-9 * scale, (s.surface_type, np.abs(got - ref).max())
    assert seen  # the part had faces


def test_closed_forms_cover_the_analytic_types():
    model = read_cad(corpus("nist_ctc02_ap242.stp"))
    kinds = {surface_of(f).surface_type: surface_of(f).exact_numpy for f in model.faces}
    assert {"plane", "cylinder", "cone", "sphere", "torus", "bspline"} <= set(kinds)
    assert all(kinds.values())


def test_numpy_and_compiled_bspline_paths_agree():
    """Small calls run numpy, large ones the numba kernel: both give the same points."""
    from amprep.geometry.cad import bspline

    model = read_cad(corpus("nist_ctc02_bspline_ap203.stp"))
    rng = np.random.default_rng(3)
    for face in model.faces[:60]:
        s = surface_of(face)
        if s.surface_type != "bspline":
            continue
        d = s.data
        u0, u1, v0, v1 = BRepTools.UVBounds_s(face)
        uv = rng.random((500, 2)) * [u1 - u0, v1 - v0] + [u0, v0]
        from amprep.geometry.cad.surfaces import wrap_periodic

        uv = wrap_periodic(uv, d["uperiod"], d["vperiod"])
        pw = np.concatenate([d["poles"] * d["weights"][..., None], d["weights"][..., None]], axis=2)
        ref = bspline._eval_surface_numpy(pw, d["uknots"], d["vknots"], d["udeg"], d["vdeg"], uv)
        from amprep.geometry.cad._bspline_kernel import eval_surface_kernel

        out = np.empty_like(ref)
        ub, vb = bspline.kernel_bases({}, d["uknots"], d["udeg"], d["vknots"], d["vdeg"], pw.shape[:2])
        eval_surface_kernel(np.ascontiguousarray(pw), ub, vb, d["udeg"], d["vdeg"], uv, out)
        np.testing.assert_allclose(out, ref, rtol=0, atol=1e-9 * max(1.0, np.abs(ref).max()))


@pytest.mark.parametrize("degree", [1, 3, 7, 12, 25])
def test_the_compiled_kernels_bernstein_spans_keep_any_degree_exact(degree):
    """The compiled kernel evaluates each span's basis from its Bernstein form (_bspline_kernel.span_bernstein); on a
    rational surface of degree up to 25 in u, with random knots and a double one, it gives the numpy path's
    Cox–de Boor points to 1e-13 of the poles' size: no loss of digits with the degree."""
    from amprep.geometry.cad import bspline
    from amprep.geometry.core.compiled import compiled

    rng = np.random.default_rng(degree)
    n = degree + 9
    inner = np.sort(rng.uniform(0, 1, n - degree - 1))
    inner[3] = inner[2]
    uknots = np.r_[[0.0] * (degree + 1), inner, [1.0] * (degree + 1)]
    vknots = np.r_[[0.0] * 4, 0.2, 0.5, 0.8, [1.0] * 4]
    poles, weights = rng.normal(size=(n, 7, 3)) * 1000, rng.uniform(0.5, 2, (n, 7))
    uv = np.concatenate([rng.uniform(0, 1, (20000, 2)), np.stack(np.meshgrid(inner, vknots), -1).reshape(-1, 2)])
    with compiled(False):
        ref = bspline.eval_surface(poles, weights, uknots, vknots, degree, 3, uv)
    with compiled(True):
        out = bspline.eval_surface(poles, weights, uknots, vknots, degree, 3, uv)
    np.testing.assert_allclose(out, ref, rtol=0, atol=1e-13 * np.abs(poles).max())


def _swept_solids():
    import cadquery as cq

    profile = [(5, 0), (8, 5), (6, 10), (9, 15), (5, 20)]
    rev = cq.Workplane("XZ").spline(profile).lineTo(0, 20).lineTo(0, 0).close().revolve(360, (0, 0, 0), (0, 1, 0)).val()
    arc = cq.Workplane("XZ").moveTo(4, 0).threePointArc((7, 10), (4, 20)).lineTo(0, 20).lineTo(0, 0).close()
    rev_arc = arc.revolve(270, (0, 0, 0), (0, 1, 0)).val()  # a circle revolved off its centre: a revolution surface
    ext = (cq.Workplane("XY").spline([(0, 0), (10, 5), (20, -3), (30, 4)]).lineTo(30, -10).lineTo(0, -10).close()
           .extrude(12).val())
    moved = cq.Location(cq.Vector(100, 50, -20), cq.Vector(1, 1, 0), 30)
    return {"revolved spline": rev, "revolved arc": rev_arc, "extruded spline": ext,
            "revolved spline, moved": rev.moved(moved), "extruded spline, moved": ext.moved(moved)}


@pytest.mark.parametrize("name", list(_swept_solids()))
def test_surfaces_of_revolution_and_extrusion_are_evaluated_in_numpy_and_match_occt(name):
    """Swept surfaces (a revolved or extruded spline, a revolved arc; located copies too): closed-form evaluation
    from the basis curve, no OCCT point loop, equal to OCCT's evaluator to 1e-9; and a conversion of the solid is
    closed and within tolerance."""
    from amprep.geometry.cad.read import model_from_shape
    from amprep.geometry.core.checks import check_mesh
    from amprep.geometry.meshing.params import MeshParams
    from amprep.geometry.meshing.pipeline import mesh_model

    model = model_from_shape(_swept_solids()[name].wrapped)
    rng = np.random.default_rng(3)
    kinds = set()
    for face in model.faces:
        s = surface_of(face)
        if s.surface_type not in ("revolution", "extrusion"):
            continue
        kinds.add(s.surface_type)
        assert s.exact_numpy
        u0, u1, v0, v1 = BRepTools.UVBounds_s(face)
        uv = rng.random((200, 2)) * [u1 - u0, v1 - v0] + [u0, v0]
        ad = BRepAdaptor_Surface(face, True)
        ref = np.array([ad.Value(u, v).Coord() for u, v in uv])
        assert np.abs(s.evaluate(uv) - ref).max() <= 1e-9 * max(1.0, float(np.abs(ref).max()))
    assert kinds == ({"extrusion"} if "extruded" in name else {"revolution"})
    res = mesh_model(model, MeshParams(tolerance=0.01))
    c = check_mesh(res.mesh)
    assert c.closed and c.degenerate_triangles == 0 and res.max_error <= 0.01


@pytest.mark.parametrize("degree", [0, 1, 2, 3, 5, 9])
def test_basis_functions_match_the_recursive_definition(degree):
    """Cox–de Boor's recursion, N_{i,0} = [k_i ≤ t < k_{i+1}], N_{i,p} = (t − k_i)/(k_{i+p} − k_i)·N_{i,p−1} +
    (k_{i+p+1} − t)/(k_{i+p+1} − k_{i+1})·N_{i+1,p−1} (0/0 = 0), evaluated point by point, against the
    vectorised triangle, on a clamped knot vector with a double knot and at the knots themselves."""
    from amprep.geometry.cad.bspline import basis_functions, find_span

    rng = np.random.default_rng(degree)
    inner = np.sort(rng.random(12))
    inner[4] = inner[5]
    knots = np.concatenate([np.zeros(degree + 1), inner, np.ones(degree + 1)])

    def n(i: int, p: int, t: float) -> float:
        if p == 0:
            return float(knots[i] <= t < knots[i + 1])
        a = (t - knots[i]) / (knots[i + p] - knots[i]) if knots[i + p] > knots[i] else 0.0
        b = (knots[i + p + 1] - t) / (knots[i + p + 1] - knots[i + 1]) if knots[i + p + 1] > knots[i + 1] else 0.0
        return a * n(i, p - 1, t) + b * n(i + 1, p - 1, t)

    t = np.concatenate([rng.random(40), inner[:-1]])
    span = find_span(knots, degree, t)
    got = basis_functions(knots, degree, t, span)
    want = np.array([[n(s - degree + a, degree, x) for a in range(degree + 1)] for x, s in zip(t, span, strict=True)])
    assert np.allclose(got, want, rtol=0, atol=1e-12)
    assert np.allclose(got.sum(axis=1), 1.0, atol=1e-12)


@pytest.mark.parametrize("name", ["nist_ctc02_ap242.stp", "nist_ctc02_bspline_ap203.stp"])
def test_edge_curves_and_pcurves_in_bulk_match_occt_point_by_point(name):
    """curve_values' closed forms (lines, circles), its B-spline sums and its fallback give OCCT's own Value on every
    edge and pcurve of CTC-02 (lines, circles, B-splines) and of its twin (all B-splines)."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepAdaptor import BRepAdaptor_Curve
    from OCP.Geom2dAdaptor import Geom2dAdaptor_Curve
    from OCP.GeomAbs import GeomAbs_BSplineCurve
    from OCP.TopAbs import TopAbs_EDGE
    from OCP.TopoDS import TopoDS

    from amprep.geometry.cad.occt_arrays import curve_values
    from amprep.geometry.cad.topology import explore

    model = read_cad(corpus(name), "step")
    kinds, splines = set(), 0
    for face in model.faces[::3]:
        for edge in explore(face, TopAbs_EDGE, TopoDS.Edge_s):
            pcurve = BRep_Tool.CurveOnSurface_s(edge, face, 0.0, 0.0)
            for curve, raw in ((BRepAdaptor_Curve(edge), None), (Geom2dAdaptor_Curve(pcurve), pcurve)):
                spline = curve.GetType() == GeomAbs_BSplineCurve
                for n in (7, 4 * curve.NbPoles() + 1) if spline else (7,):  # the sums run from twice the poles
                    t = np.linspace(*BRep_Tool.Range_s(edge), n)
                    expected = np.array([(raw if raw is not None else curve).Value(float(x)).Coord() for x in t])
                    got = curve_values(curve, t)
                    assert got.shape == expected.shape
                    assert np.allclose(got, expected, rtol=0, atol=1e-9 * (1 + np.abs(expected).max()))
                kinds.add(curve.GetType())
                splines += spline
    assert (len(kinds) > 2) if "ap242" in name else splines > 100


class _CountingCurve:
    """A curve adaptor that counts its Value calls (curve_values asks only the ends when it sums a curve itself)."""

    def __init__(self, curve) -> None:  # type: ignore[no-untyped-def]
        self.curve, self.values = curve, 0

    def Value(self, t: float):  # type: ignore[no-untyped-def]  # noqa: N802
        self.values += 1
        return self.curve.Value(t)

    def __getattr__(self, name: str):  # type: ignore[no-untyped-def]
        return getattr(self.curve, name)


@pytest.mark.parametrize("dim", [2, 3])
def test_ellipses_and_periodic_bsplines_are_summed_in_bulk(dim):
    """An ellipse in closed form and a periodic B-spline on a non-periodic copy, asked over three periods: OCCT's own
    points, with Value asked at the two ends only, and the curve itself left periodic."""
    from OCP import Geom, Geom2d, Geom2dAdaptor, GeomAdaptor, gp
    from OCP.TColgp import TColgp_Array1OfPnt, TColgp_Array1OfPnt2d
    from OCP.TColStd import TColStd_Array1OfInteger, TColStd_Array1OfReal

    from amprep.geometry.cad.occt_arrays import curve_values

    pnt = (lambda x, y: gp.gp_Pnt2d(x, y)) if dim == 2 else (lambda x, y: gp.gp_Pnt(x, y, 0.3 * x * y))
    poles = (TColgp_Array1OfPnt2d if dim == 2 else TColgp_Array1OfPnt)(1, 7)
    for i in range(7):
        poles.SetValue(i + 1, pnt(3 * np.cos(i), 2 * np.sin(1.3 * i)))
    knots, mults = TColStd_Array1OfReal(1, 8), TColStd_Array1OfInteger(1, 8)
    for i in range(8):
        knots.SetValue(i + 1, 0.2 + 0.7 * i + 0.05 * i * i)
        mults.SetValue(i + 1, 1)
    if dim == 2:
        spline = Geom2d.Geom2d_BSplineCurve(poles, knots, mults, 3, True)
        ellipse = Geom2d.Geom2d_Ellipse(gp.gp_Ax22d(gp.gp_Pnt2d(1, 2), gp.gp_Dir2d(0.6, 0.8), True), 5.0, 2.0)
        adapt = Geom2dAdaptor.Geom2dAdaptor_Curve
    else:
        spline = Geom.Geom_BSplineCurve(poles, knots, mults, 3, True)
        ellipse = Geom.Geom_Ellipse(gp.gp_Ax2(gp.gp_Pnt(1, 2, 3), gp.gp_Dir(1, 1, 1)), 5.0, 2.0)
        adapt = GeomAdaptor.GeomAdaptor_Curve
    for geom in (spline, ellipse):
        curve = _CountingCurve(adapt(geom))
        t = np.linspace(-7.0, 11.0, 4 * curve.NbPoles() + 1 if geom is spline else 41)
        got = curve_values(curve, t)
        assert curve.values == 2
        want = np.array([geom.Value(float(x)).Coord() for x in t])
        assert np.allclose(got, want, rtol=0, atol=1e-12 * (1 + np.abs(want).max()))
    assert spline.IsPeriodic()


@pytest.mark.parametrize("name", ["nist_ctc02_ap242.stp", "nist_ctc02_bspline_ap203.stp"])
def test_the_compiled_projection_finds_the_feet_occt_finds(name):
    """project_settled's compiled loop (one call per face, _projection_kernel.py) against OCCT's own projection
    (GeomAPI_ProjectPointOnSurf) on two faces of each kind: points 0.05 mm off random points of the face, started a
    twentieth of the face's extent away; every settled point's distance is OCCT's, and the numpy loop's."""
    from OCP.BRep import BRep_Tool
    from OCP.GeomAPI import GeomAPI_ProjectPointOnSurf
    from OCP.gp import gp_Pnt

    from amprep.geometry.cad.surfaces import project_settled, surface_normals, uv_extent
    from amprep.geometry.core.compiled import compiled

    rng = np.random.default_rng(11)
    model = read_cad(corpus(name))
    per_kind: dict[str, int] = {}
    checked = tried = 0
    for face in model.faces:
        s = surface_of(face)
        if per_kind.get(s.surface_type, 0) >= 2 or (s.closed_form is None and s.data is None):
            continue
        per_kind[s.surface_type] = per_kind.get(s.surface_type, 0) + 1
        u0, u1, v0, v1 = BRepTools.UVBounds_s(face)
        uv = rng.random((60, 2)) * [u1 - u0, v1 - v0] + [u0, v0]
        off = rng.uniform(-0.05, 0.05, (60, 1))
        points = s.evaluate(uv) + off * surface_normals(s, uv)
        start = uv + rng.normal(0, 0.05, (60, 2)) * uv_extent(s)
        with compiled(True):
            got_uv, got, settled = project_settled(s, points, start, within=True, settle=1e-9)
        with compiled(False):
            _, numpy_dist, numpy_settled = project_settled(s, points, start, within=True, settle=1e-9)
        geom = BRep_Tool.Surface_s(face)
        tried += len(points)
        for i in np.flatnonzero(settled & numpy_settled):
            foot = GeomAPI_ProjectPointOnSurf(gp_Pnt(*points[i]), geom)
            assert foot.NbPoints() > 0
            occt = foot.LowerDistance()
            # a start across a ridge may settle on another local foot: never nearer than OCCT's nearest
            assert got[i] >= occt - 1e-9, (s.surface_type, got[i], occt)
            if abs(got[i] - abs(off[i, 0])) <= 1e-6:
                assert abs(got[i] - occt) <= 1e-9, (s.surface_type, got[i], occt)
                checked += 1
            assert abs(got[i] - numpy_dist[i]) <= 1e-9, (s.surface_type, got[i], numpy_dist[i])
        assert np.isfinite(got_uv).all()
    assert checked >= 0.8 * tried, (checked, tried)
    assert set(per_kind) >= ({"bspline"} if "bspline" in name else {"plane", "cylinder", "cone", "sphere", "torus"})
