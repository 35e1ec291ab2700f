"""Surfaces swept from a curve, evaluated in numpy: revolution S(u,v) = A + Rot_k(u)(C(v) − A) and linear extrusion
S(u,v) = C(u) + v·D, for basis curves that are lines, circles, ellipses, Bézier or rational B-spline curves."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from OCP.GeomAbs import GeomAbs_BezierCurve, GeomAbs_BSplineCurve, GeomAbs_Circle, GeomAbs_Ellipse, GeomAbs_Line
from OCP.GeomConvert import GeomConvert

from amprep.geometry.cad.bspline import basis_functions, find_span
from amprep.geometry.cad.occt_arrays import array1, vec
from amprep.geometry.core.vectors import cross

Curve = Callable[[np.ndarray], np.ndarray]  # (N,) parameters → (N, 3) points


def bspline_curve(geom) -> Curve:  # type: ignore[no-untyped-def]
    """C(t) = Σ N_i(t) w_i P_i / Σ N_i(t) w_i of a Geom_BSplineCurve (periodic ones wrapped into their period)."""
    period = (geom.FirstParameter(), geom.LastParameter()) if geom.IsPeriodic() else None
    if geom.IsPeriodic():
        geom = geom.Copy()
        geom.SetNotPeriodic()
    n, deg = geom.NbPoles(), geom.Degree()
    poles = np.array([vec(geom.Pole(i)) for i in range(1, n + 1)])
    weights = np.array([geom.Weight(i) for i in range(1, n + 1)]) if geom.IsRational() else np.ones(n)
    knots = array1(geom.KnotSequence())
    pw = np.concatenate([poles * weights[:, None], weights[:, None]], axis=1)  # (n, 4)

    def c(t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        if period is not None:
            t = period[0] + np.mod(t - period[0], period[1] - period[0])
        span = find_span(knots, deg, t)
        basis = basis_functions(knots, deg, t, span)  # (N, deg+1)
        idx = (span - deg)[:, None] + np.arange(deg + 1)[None, :]
        h = np.einsum("nk,nkd->nd", basis, pw[idx])
        return h[:, :3] / h[:, 3:4]
    return c


def curve_of(adaptor) -> Curve | None:  # type: ignore[no-untyped-def]
    """A vectorised evaluator of an Adaptor3d_Curve, or None for kinds without one (offset and other curves)."""
    kind = adaptor.GetType()
    if kind == GeomAbs_Line:
        lin = adaptor.Line()
        p, d = vec(lin.Location()), vec(lin.Direction())
        return lambda t: p + np.asarray(t, float)[:, None] * d
    if kind in (GeomAbs_Circle, GeomAbs_Ellipse):
        conic = adaptor.Circle() if kind == GeomAbs_Circle else adaptor.Ellipse()
        pos = conic.Position()
        o, x, y = vec(pos.Location()), vec(pos.XDirection()), vec(pos.YDirection())
        a = conic.Radius() if kind == GeomAbs_Circle else conic.MajorRadius()
        b = conic.Radius() if kind == GeomAbs_Circle else conic.MinorRadius()
        return lambda t: o + a * np.cos(np.asarray(t, float))[:, None] * x + b * np.sin(np.asarray(t, float))[:, None] * y
    if kind == GeomAbs_BSplineCurve:
        return bspline_curve(adaptor.BSpline())
    if kind == GeomAbs_BezierCurve:
        return bspline_curve(GeomConvert.CurveToBSplineCurve_s(adaptor.Bezier()))
    return None


def revolution(axis_point: np.ndarray, axis_dir: np.ndarray, curve: Curve) -> Callable[[np.ndarray], np.ndarray]:
    """S(u,v) = A + p cos u + (k × p) sin u + k (k·p)(1 − cos u), p = C(v) − A (Rodrigues' rotation about k by u)."""
    k = axis_dir / np.linalg.norm(axis_dir)

    def f(uv: np.ndarray) -> np.ndarray:
        p = curve(uv[:, 1]) - axis_point
        cu, su = np.cos(uv[:, :1]), np.sin(uv[:, :1])
        return axis_point + p * cu + cross(k, p) * su + k * (p @ k)[:, None] * (1 - cu)
    return f


def extrusion(direction: np.ndarray, curve: Curve) -> Callable[[np.ndarray], np.ndarray]:
    """S(u,v) = C(u) + v·D."""
    d = direction / np.linalg.norm(direction)
    return lambda uv: curve(uv[:, 0]) + uv[:, 1:2] * d
