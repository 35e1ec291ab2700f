"""Find the edges that meet in a face's (u,v) where they should not: in one wire, or in two wires of the face.

OCCT's STEP and IGES readers run ShapeFix_IntersectionTool::FixSelfIntersectWire on every wire of every face;
before it looks at a wire it rebuilds the whole face through its re-shape context, so a face with W holes costs
O(W^2) (a 1,600-hole plate: 10–17 s of a 12–20 s read). `cad.py` reads with that repair off, asks `crossing_faces`
whether any face has edges it would have repaired, or edges of two wires that meet (what a crossing wire becomes
if a later repair splits it), and reads again with OCCT's default healing when one does.
"""

from __future__ import annotations

from functools import cache

import numpy as np
from OCP.Bnd import Bnd_Box2d
from OCP.BndLib import BndLib_Add2dCurve
from OCP.BRep import BRep_Tool
from OCP.Geom2dAdaptor import Geom2dAdaptor_Curve
from OCP.Geom2dInt import Geom2dInt_GInter
from OCP.IntRes2d import IntRes2d_Domain
from OCP.Precision import Precision
from OCP.ShapeExtend import ShapeExtend_WireData
from OCP.TopAbs import TopAbs_FACE, TopAbs_WIRE
from OCP.TopoDS import TopoDS, TopoDS_Edge, TopoDS_Face, TopoDS_Shape, TopoDS_Wire

from amprep.geometry.cad.topology import explore

_TOL = 1.0e-10  # the intersection tolerance FixSelfIntersectWire uses
_Curve = tuple[Geom2dAdaptor_Curve, float, float, tuple[float, float, float, float]]
_FEW = 16  # wires with at most this many edges test all their pairs, longer ones only those whose boxes overlap


def _pcurve_box(edge: TopoDS_Edge, face: TopoDS_Face) -> _Curve | None:
    """The edge's pcurve on the face as an adaptor over its range, and its (u,v) box (umin, vmin, umax, vmax)."""
    if BRep_Tool.Degenerated_s(edge):
        return None
    curve = BRep_Tool.CurveOnSurface_s(edge, face, 0.0, 0.0)
    if curve is None:
        return None
    a, b = BRep_Tool.Range_s(edge, face)
    adaptor = Geom2dAdaptor_Curve(curve, a, b)
    box = Bnd_Box2d()
    BndLib_Add2dCurve.Add_s(adaptor, Precision.Confusion_s(), box)
    return adaptor, a, b, box.Get()


def _overlap(p: tuple[float, ...], q: tuple[float, ...]) -> bool:
    return p[0] <= q[2] and q[0] <= p[2] and p[1] <= q[3] and q[1] <= p[3]


def _meet(c1: _Curve, c2: _Curve) -> bool:
    """True when two pcurves have an intersection point or segment (Geom2dInt_GInter at 1e-10)."""
    (g1, a1, b1, _), (g2, a2, b2, _) = c1, c2
    d1 = IntRes2d_Domain(g1.Value(a1), a1, _TOL, g1.Value(b1), b1, _TOL)
    d2 = IntRes2d_Domain(g2.Value(a2), a2, _TOL, g2.Value(b2), b2, _TOL)
    inter = Geom2dInt_GInter()
    inter.Perform(g1, d1, g2, d2, _TOL, _TOL)
    return inter.IsDone() and (inter.NbPoints() > 0 or inter.NbSegments() > 0)


@cache
def _pairs(n: int) -> tuple[tuple[int, int], ...]:
    """FixSelfIntersectWire's pairs of an n-edge wire, 0-based: (i, j), j >= i + 2, less (0, n - 1)."""
    return tuple((i, j) for i in range(n) for j in range(i + 2, n) if (i, j) != (0, n - 1))


_EMPTY = (np.inf, np.inf, -np.inf, -np.inf)  # the box of no pcurve: it overlaps nothing


def overlapping_boxes(box: np.ndarray) -> list[tuple[int, int]]:
    """Pairs (a, b) of (n, 4) boxes [umin, vmin, umax, vmax] that overlap, a sweep along u (empty: inf, -inf)."""
    order = np.argsort(box[:, 0], kind="stable")
    b = box[order]
    n = len(b)
    starts = np.arange(1, n + 1)
    counts = np.maximum(np.searchsorted(b[:, 0], b[:, 2], side="right") - starts, 0)
    i = np.repeat(np.arange(n), counts)
    j = np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts) + np.repeat(starts, counts)
    keep = (b[i, 1] <= b[j, 3]) & (b[j, 1] <= b[i, 3])
    return list(zip(order[i[keep]].tolist(), order[j[keep]].tolist()))


class _Wire:
    """A wire's edges in its order (ShapeExtend_WireData's, as OCCT's repairs take them) and their pcurves on the
    face, each read once, when first asked for."""

    def __init__(self, wire: TopoDS_Wire, face: TopoDS_Face) -> None:
        data = ShapeExtend_WireData(wire)
        self.face = face
        self.edges = [data.Edge(i) for i in range(1, data.NbEdges() + 1)]
        self._curves: dict[int, _Curve | None] = {}

    def curve(self, k: int) -> _Curve | None:
        if k not in self._curves:
            self._curves[k] = _pcurve_box(self.edges[k], self.face)
        return self._curves[k]

    def boxes(self) -> np.ndarray:
        """(n, 4) every edge's (u,v) box (_EMPTY without a pcurve)."""
        return np.array([c[3] if c is not None else _EMPTY
                         for c in map(self.curve, range(len(self.edges)))], float).reshape(-1, 4)


def _edges_meet(w1: _Wire, k1: int, w2: _Wire, k2: int) -> bool:
    """True when the two edges are distinct, both have a pcurve, their boxes overlap and the pcurves meet."""
    if w1.edges[k1].IsSame(w2.edges[k2]):
        return False
    c1, c2 = w1.curve(k1), w2.curve(k2)
    return c1 is not None and c2 is not None and _overlap(c1[3], c2[3]) and _meet(c1, c2)


def _crosses_itself(w: _Wire) -> bool:
    n = len(w.edges)
    if n < 4:
        return False
    if n <= _FEW:
        pairs = list(_pairs(n))
    else:
        pairs = [(a, b) if a < b else (b, a) for a, b in overlapping_boxes(w.boxes())]
        pairs = [(a, b) for a, b in pairs if b >= a + 2 and (a, b) != (0, n - 1)]
    return any(_edges_meet(w, a, w, b) for a, b in pairs)


def _wires_meet(ws: list[_Wire]) -> bool:
    boxes = [w.boxes() for w in ws]
    union = np.array([(*b[:, :2].min(axis=0, initial=np.inf), *b[:, 2:].max(axis=0, initial=-np.inf)) for b in boxes])
    return any(_edges_meet(ws[a], ka, ws[b], kb)
               for a, b in overlapping_boxes(union.reshape(-1, 4))
               for ka in range(len(ws[a].edges)) for kb in range(len(ws[b].edges)))


def wire_crosses(wire: TopoDS_Wire, face: TopoDS_Face) -> bool:
    """True when two non-adjacent, distinct, non-degenerated edges of the wire meet in the face's (u,v).

    The pairs are FixSelfIntersectWire's (`_pairs`); a pair is intersected only when its (u,v) boxes overlap.
    A wire of fewer than 4 edges has no such pair.
    """
    return _crosses_itself(_Wire(wire, face))


def wires_cross(wires: list[TopoDS_Wire], face: TopoDS_Face) -> bool:
    """True when an edge of one of the face's wires meets an edge of another in the face's (u,v).

    FixIntersectingWires' test: pairs of wires whose boxes overlap, pairs of their distinct, non-degenerated
    edges whose boxes overlap, intersected by Geom2dInt_GInter.
    """
    return _wires_meet([_Wire(w, face) for w in wires])


def crossing_faces(shape: TopoDS_Shape) -> list[int]:
    """Indices (TopExp_Explorer order, repeats counted) of the faces with a wire for which `wire_crosses` holds
    or with two wires for which `wires_cross` does (each edge's pcurve read once for both)."""
    found = []
    for k, face in enumerate(explore(shape, TopAbs_FACE, TopoDS.Face_s)):
        ws = [_Wire(w, face) for w in explore(face, TopAbs_WIRE, TopoDS.Wire_s)]
        if any(_crosses_itself(w) for w in ws) or (len(ws) > 1 and _wires_meet(ws)):
            found.append(k)
    return found
