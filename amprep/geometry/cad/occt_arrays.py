"""numpy arrays from OCCT values (a point, vector or direction as (3,), a TColStd/TColgp 1-D array as (n,)), and
1-D OCCT arrays from numpy, and a curve's points at many params (a pcurve's too, and where it reaches given v)."""

from __future__ import annotations

import numpy as np
from OCP.BRep import BRep_Tool
from OCP.Geom2dAdaptor import Geom2dAdaptor_Curve
from OCP.GeomAbs import GeomAbs_BSplineCurve, GeomAbs_Circle, GeomAbs_Ellipse, GeomAbs_Line

from amprep.geometry.cad.bspline import eval_curve


def vec(p) -> np.ndarray:  # type: ignore[no-untyped-def]
    """(3,) X, Y, Z of a gp_Pnt, gp_Vec, gp_Dir or gp_XYZ."""
    return np.array([p.X(), p.Y(), p.Z()])


def to_array1(values: np.ndarray, cls):  # type: ignore[no-untyped-def]
    """A 1-D OCCT array of class `cls` (TColStd_Array1OfReal, …OfInteger) holding values (n,), indexed from 1."""
    out = cls(1, len(values))
    for i, v in enumerate(np.asarray(values).tolist(), 1):
        out.SetValue(i, v)
    return out


def array1(arr) -> np.ndarray:  # type: ignore[no-untyped-def]
    """(n,) float values of a 1-D OCCT array, Lower() to Upper()."""
    return np.array([arr.Value(i) for i in range(arr.Lower(), arr.Upper() + 1)], dtype=float)


#: a line, circle, ellipse or B-spline summed here must give OCCT's own points at its ends to this × (1 + |point|), else it is
#: asked of OCCT point by point
_CLOSED_FORM_RTOL = 1e-9


def curve_values(curve, t: np.ndarray) -> np.ndarray:  # type: ignore[no-untyped-def]
    """(n, d) the points at params t (n,) of a curve adaptor (BRepAdaptor_Curve: d = 3; Geom2dAdaptor_Curve: d = 2):
    a line (L + t D), circle (C + R (cos t X + sin t Y)) or ellipse (C + a cos t X + b sin t Y) in closed form, a
    B-spline asked at twice its poles or more by bspline.eval_curve (a periodic one made non-periodic on a copy, t
    taken into its first period), each checked against the adaptor's own Value at the first and last param; any other
    curve point by point."""
    t = np.asarray(t, float).ravel()
    kind = curve.GetType()
    out = None
    if len(t) > 2 and kind == GeomAbs_Line:
        line = curve.Line()
        out = _xy(line.Location()) + t[:, None] * _xy(line.Direction())
    elif len(t) > 2 and kind in (GeomAbs_Circle, GeomAbs_Ellipse):
        conic = curve.Circle() if kind == GeomAbs_Circle else curve.Ellipse()
        a, b = ((conic.Radius(),) * 2 if kind == GeomAbs_Circle else (conic.MajorRadius(), conic.MinorRadius()))
        centre, x, y = _xy(conic.Location()), _xy(conic.XAxis().Direction()), _xy(conic.YAxis().Direction())
        out = centre + a * np.cos(t)[:, None] * x + b * np.sin(t)[:, None] * y
    elif kind == GeomAbs_BSplineCurve and len(t) >= 2 * curve.NbPoles():
        out = _bspline_values(curve.BSpline(), t)
    if out is not None:
        ends = np.array([_xy(curve.Value(float(t[0]))), _xy(curve.Value(float(t[-1])))])
        if np.all(np.abs(out[[0, -1]] - ends) <= _CLOSED_FORM_RTOL * (1 + np.abs(ends))):
            return out
    return np.array([_xy(curve.Value(float(x))) for x in t], float).reshape(len(t), -1)


def _bspline_values(spline, t: np.ndarray) -> np.ndarray:  # type: ignore[no-untyped-def]
    """(n, d) a Geom or Geom2d B-spline curve's points at t (n,) by bspline.eval_curve; a periodic one on a
    non-periodic copy (the adaptor's may be the model's own curve), t taken into [first, first + period)."""
    if spline.IsPeriodic():
        first, period = spline.FirstParameter(), spline.Period()
        spline = spline.Copy()
        spline.SetNotPeriodic()
        t = first + np.mod(t - first, period)
    n = spline.NbPoles()
    poles = np.array([_xy(spline.Pole(i)) for i in range(1, n + 1)])
    weights = np.array([spline.Weight(i) for i in range(1, n + 1)]) if spline.IsRational() else np.ones(n)
    return eval_curve(poles, weights, array1(spline.KnotSequence()), spline.Degree(), t)


def _xy(p) -> np.ndarray:  # type: ignore[no-untyped-def]
    """(2,) or (3,) coordinates of a 2-D or 3-D gp point, vector or direction."""
    return np.array(p.Coord())


def pcurve_values(face, edge, params: np.ndarray) -> np.ndarray:  # type: ignore[no-untyped-def]
    """(n, 2) the (u,v) of the edge's pcurve on the face at its params (n,)."""
    return curve_values(Geom2dAdaptor_Curve(BRep_Tool.CurveOnSurface_s(edge, face, 0.0, 0.0)), params)


def params_at_v(face, edge, v: np.ndarray, samples: int) -> np.ndarray | None:  # type: ignore[no-untyped-def]
    """(k,) the edge's parameters where its pcurve on the face reaches each v (k,) from its start to its end, sorted:
    the pcurve sampled at `samples` points and v(t) inverted between them (exact where v is affine in t, as on analytic
    faces), the first and last the edge's range's; None when it has no pcurve or v is not monotone along it."""
    first, last = BRep_Tool.Range_s(edge)
    pc = BRep_Tool.CurveOnSurface_s(edge, face, 0.0, 0.0)
    if pc is None:
        return None
    ts = np.linspace(first, last, samples)
    vs = curve_values(Geom2dAdaptor_Curve(pc), ts)[:, 1]
    dv = np.diff(vs)
    if not ((dv > 0).all() or (dv < 0).all()):
        return None
    if dv[0] < 0:
        ts, vs = ts[::-1], vs[::-1]
    t = np.sort(np.interp(v, vs, ts))
    t[0], t[-1] = min(first, last), max(first, last)
    return t
