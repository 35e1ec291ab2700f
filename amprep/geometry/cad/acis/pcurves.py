"""The curves in a face's parameter space that ACIS stores (`pcurve` records of type 0, `exppc` B-splines), put on
the edges of B-spline faces, whose (u,v) is OCCT's own (the same knots and poles). ACIS parametrises a pcurve by
its coedge, so it is the edge's curve parameter or its negation: the one whose points land on the edge is taken,
checked at five parameters; a pcurve that fits neither (or any other face's) is left to OCCT's healing to compute.
"""

from __future__ import annotations

import numpy as np
from OCP.BRep import BRep_Builder, BRep_Tool
from OCP.Geom import Geom_BSplineSurface
from OCP.Geom2d import Geom2d_BSplineCurve
from OCP.gp import gp_Pnt2d
from OCP.TColgp import TColgp_Array1OfPnt2d
from OCP.TColStd import TColStd_Array1OfInteger, TColStd_Array1OfReal
from OCP.TopoDS import TopoDS_Edge, TopoDS_Face

from amprep.geometry.cad.acis.entities import Model
from amprep.geometry.cad.acis.splines import BSplineData, find_block, read_block
from amprep.geometry.cad.occt_arrays import to_array1

#: a stored pcurve is used when its points lie this close (× the edge's length, plus round-off) to the edge
FIT = 1e-4


def bspline_2d(d: BSplineData, negate: bool = False) -> Geom2d_BSplineCurve:
    """The 2D B-spline of d; with `negate`, parametrised by −t (c(t) = d(−t): knots negated and reversed)."""
    knots, mults, poles = d.knots[0], d.mults[0], d.poles
    weights = d.weights
    if negate:
        knots, mults, poles = -knots[::-1], mults[::-1], poles[::-1]
        weights = None if weights is None else weights[::-1]
    arr = TColgp_Array1OfPnt2d(1, len(poles))
    for i, (u, v) in enumerate(poles.tolist(), 1):
        arr.SetValue(i, gp_Pnt2d(u, v))
    k, m = to_array1(knots, TColStd_Array1OfReal), to_array1(mults, TColStd_Array1OfInteger)
    if weights is None:
        return Geom2d_BSplineCurve(arr, k, m, d.degrees[0])
    return Geom2d_BSplineCurve(arr, to_array1(weights, TColStd_Array1OfReal), k, m, d.degrees[0])


def stored_pcurve(model: Model, i: int) -> BSplineData | None:
    """The exppc B-spline of pcurve record i, None for any other kind (a pcurve derived from a surface curve)."""
    c = model.cursor(i, "pcurve")
    if c.peek() not in (0, "0"):
        return None
    c.num()
    c.flag("reversed", "forward")
    nxt = c.peek()
    if nxt != "{":
        return None
    tokens = c.subtype()
    if not tokens or tokens[0] != "exppc":
        return None
    k = find_block(tokens, surface=False)
    return None if k is None else read_block(tokens, k, False, c.where, dim=2)


def attach(edge: TopoDS_Edge, face: TopoDS_Face, surface: Geom_BSplineSurface, data: BSplineData) -> bool:
    """Put the stored pcurve on the edge for this face when it fits the edge (as t or −t); True when it did."""
    curve = BRep_Tool.Curve_s(edge, 0.0, 0.0)
    if curve is None:
        return False
    a, b = BRep_Tool.Range_s(edge)
    ts = np.linspace(a, b, 5)
    pts = np.array([curve.Value(float(t)).Coord() for t in ts])
    length = float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum())
    lo, hi = float(data.knots[0][0]), float(data.knots[0][-1])
    for negate in (False, True):
        s = -ts if negate else ts
        if s.min() < lo - 1e-9 * (1 + abs(lo)) or s.max() > hi + 1e-9 * (1 + abs(hi)):
            continue
        c2d = bspline_2d(data, negate)
        on = np.array([surface.Value(*c2d.Value(float(t)).Coord()).Coord() for t in ts])
        if np.linalg.norm(on - pts, axis=1).max() <= FIT * length + 1e-7 * (1 + np.abs(pts).max()):
            BRep_Builder().UpdateEdge(edge, c2d, face, max(BRep_Tool.Tolerance_s(edge), 1e-7))
            return True
    return False
