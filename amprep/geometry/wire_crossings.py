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
from OCP.TopExp import TopExp_Explorer
from OCP.TopoDS import TopoDS, TopoDS_Edge, TopoDS_Face, TopoDS_Shape, TopoDS_Wire

_TOL = 1.0e-10  # the intersection tolerance FixSelfIntersectWire uses
_Curve = tuple[Geom2dAdaptor_Curve, float, float, tuple[float, float, float, float]]
_FEW = 16  # wires with at most this many edges test their pairs one by one, longer ones filter boxes in numpy


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


def _box_pairs(curves: list[_Curve | None]) -> list[tuple[int, int]]:
    """`_pairs` of a long wire whose edges both have a pcurve and whose boxes overlap, found in numpy."""
    n = len(curves)
    live = np.array([c is not None for c in curves])
    box = np.array([c[3] if c is not None else (np.inf, np.inf, -np.inf, -np.inf) for c in curves])
    i, j = np.triu_indices(n, 2)
    keep = ~((i == 0) & (j == n - 1)) & live[i] & live[j]
    keep &= (box[i, 0] <= box[j, 2]) & (box[j, 0] <= box[i, 2]) & (box[i, 1] <= box[j, 3]) & (box[j, 1] <= box[i, 3])
    return list(zip(i[keep].tolist(), j[keep].tolist()))


def wire_crosses(wire: TopoDS_Wire, face: TopoDS_Face) -> bool:
    """True when two non-adjacent, distinct, non-degenerated edges of the wire meet in the face's (u,v).

    The pairs are FixSelfIntersectWire's (`_pairs`); a pair is intersected only when its (u,v) boxes overlap.
    A wire of fewer than 4 edges has no such pair.
    """
    data = ShapeExtend_WireData(wire)
    n = data.NbEdges()
    if n < 4:
        return False
    edges = [data.Edge(i) for i in range(1, n + 1)]
    curves: list[_Curve | None] = [None] * n
    if n > _FEW:
        curves = [_pcurve_box(e, face) for e in edges]
        pairs = _box_pairs(curves)
    else:
        pairs = list(_pairs(n))
    seen = [n > _FEW] * n
    for a, b in pairs:
        if edges[a].IsSame(edges[b]):
            continue
        for k in (a, b):
            if not seen[k]:
                curves[k], seen[k] = _pcurve_box(edges[k], face), True
        ca, cb = curves[a], curves[b]
        if ca is not None and cb is not None and _overlap(ca[3], cb[3]) and _meet(ca, cb):
            return True
    return False


def _box_union(curves: list[_Curve | None]) -> tuple[float, float, float, float]:
    boxes = [c[3] for c in curves if c is not None]
    if not boxes:
        return (np.inf, np.inf, -np.inf, -np.inf)
    b = np.array(boxes)
    return (b[:, 0].min(), b[:, 1].min(), b[:, 2].max(), b[:, 3].max())


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


def wires_cross(wires: list[TopoDS_Wire], face: TopoDS_Face) -> bool:
    """True when an edge of one of the face's wires meets an edge of another in the face's (u,v).

    FixIntersectingWires' test: pairs of wires whose boxes overlap, pairs of their distinct, non-degenerated
    edges whose boxes overlap, intersected by Geom2dInt_GInter.
    """
    edges = []
    for wire in wires:
        data = ShapeExtend_WireData(wire)
        edges.append([data.Edge(i) for i in range(1, data.NbEdges() + 1)])
    curves = [[_pcurve_box(e, face) for e in es] for es in edges]
    boxes = np.array([_box_union(cs) for cs in curves]).reshape(-1, 4)
    for a, b in overlapping_boxes(boxes):
        for ea, ca in zip(edges[a], curves[a]):
            if ca is None:
                continue
            for eb, cb in zip(edges[b], curves[b]):
                if cb is not None and not ea.IsSame(eb) and _overlap(ca[3], cb[3]) and _meet(ca, cb):
                    return True
    return False


def crossing_faces(shape: TopoDS_Shape) -> list[int]:
    """Indices (TopExp_Explorer order, repeats counted) of the faces with a wire for which `wire_crosses` holds
    or with two wires for which `wires_cross` does."""
    found = []
    faces = TopExp_Explorer(shape, TopAbs_FACE)
    k = 0
    while faces.More():
        face = TopoDS.Face_s(faces.Current())
        wires = []
        explorer = TopExp_Explorer(face, TopAbs_WIRE)
        while explorer.More():
            wires.append(TopoDS.Wire_s(explorer.Current()))
            explorer.Next()
        if any(wire_crosses(w, face) for w in wires) or (len(wires) > 1 and wires_cross(wires, face)):
            found.append(k)
        faces.Next()
        k += 1
    return found
