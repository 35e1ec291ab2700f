"""Pcurves a period apart. A face on a periodic surface whose edges' curves in (u,v) meet end to start only modulo
the period (KiCad's THT transformer model: a surface of revolution whose seam's two pcurves lie at u = −2π and
u = +2π, its circles' from 0 to −2π and from 0 to 2π) has no closed loop in (u,v): OCCT's BRepMesh leaves it with no
triangulation and a (u,v) mesher meshes a polygon that is not the face (750× the tolerance on a cylinder so broken).
OCCT's STEP healing leaves it, and ShapeFix_Wire.FixShifted swaps such a seam's pcurves into another open loop;
here each wire is walked edge to edge through its vertices and each pcurve moved by the whole periods that make its
start its predecessor's end, kept only where the loop then closes. The STEP healing may first have closed such a
loop with "degenerated" edges whose pcurves run whole periods along a circle of non-zero radius (the transformer's
sixth such face: two of them, each 2 periods long, so the face's (u,v) spans 3 periods and its mesh covers the band
3 times over); an edge flagged degenerate whose points on the surface are not its vertex is dropped from the wire
before the walk, kept only where the loop then closes.
"""

from __future__ import annotations

import numpy as np
from OCP.BRep import BRep_Builder, BRep_Tool
from OCP.BRepAdaptor import BRepAdaptor_Surface
from OCP.gp import gp_Vec2d
from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE, TopAbs_FORWARD, TopAbs_REVERSED, TopAbs_WIRE
from OCP.TopExp import TopExp
from OCP.TopoDS import TopoDS, TopoDS_Edge, TopoDS_Face, TopoDS_Shape, TopoDS_Wire

from amprep.geometry.cad.topology import explore

#: a wire of more edges is not walked (the walk is quadratic in them): left as it is
MAX_EDGES = 1000
#: a loop is open by a period where an edge's (u,v) end is farther than this share of the period from its successor's
#: start, and closed where every end is within it
GAP_SHARE = 0.25
#: a degenerated edge is false where a point of its pcurve lies on the surface farther than this × its vertex's
#: tolerance (and 1e-6 mm) from its vertex
FALSE_DEGENERATE = 10.0


def fix_shifted_pcurves(shape: TopoDS_Shape) -> int:
    """The number of wires of `shape`'s faces on a U- or V-periodic surface whose pcurves were moved onto one closed
    loop (shift_wire); the edges' pcurves on that face are replaced in place, so every face of `shape` holds them."""
    fixed = 0
    for face in explore(shape, TopAbs_FACE, TopoDS.Face_s):
        if BRep_Tool.Surface_s(face) is None:  # a tessellated-only face: no (u,v)
            continue
        surface = BRepAdaptor_Surface(face, False)
        period = np.array([surface.UPeriod() if surface.IsUPeriodic() else 0.0,
                           surface.VPeriod() if surface.IsVPeriodic() else 0.0])
        if not period.any():
            continue
        for wire in explore(face, TopAbs_WIRE, TopoDS.Wire_s):
            # the loop closed without false degenerated edges is shifted already; else the wire is shifted as it is
            fixed += without_false_degenerates(face, wire, surface, period) or shift_wire(face, wire, period)
    return fixed


def _false_degenerate(face: TopoDS_Face, edge: TopoDS_Edge, surface: BRepAdaptor_Surface) -> bool:
    """True for an edge flagged degenerated whose pcurve's points (9 of them) on the surface lie farther than
    FALSE_DEGENERATE × its vertex's tolerance from the vertex: a loop closed in (u,v) by an edge that is no point."""
    if not BRep_Tool.Degenerated_s(edge):
        return False
    pcurve = BRep_Tool.CurveOnSurface_s(edge, face, 0.0, 0.0)
    if pcurve is None:
        return False
    vertex = TopExp.FirstVertex_s(edge)
    at = np.array(BRep_Tool.Pnt_s(vertex).Coord())
    a, b = BRep_Tool.Range_s(edge)
    pts = np.array([surface.Value(*pcurve.Value(float(t)).Coord()).Coord() for t in np.linspace(a, b, 9)])
    far = max(FALSE_DEGENERATE * BRep_Tool.Tolerance_s(vertex), 1e-6)
    return bool(np.linalg.norm(pts - at, axis=1).max() > far)


def without_false_degenerates(face: TopoDS_Face, wire: TopoDS_Wire, surface: BRepAdaptor_Surface,
                              period: np.ndarray) -> bool:
    """True when `wire` had false degenerated edges (_false_degenerate) and the loop of its other edges closes with
    whole-period shifts: the face then holds a new wire of those edges, shifted (shift_wire); False, face untouched."""
    edges = explore(wire, TopAbs_EDGE, TopoDS.Edge_s)
    keep = [e for e in edges if not _false_degenerate(face, e, surface)]
    if len(keep) == len(edges) or not keep:
        return False
    ends = _all_ends(face, keep)
    if ends is None or _walk(face, keep, ends, period, GAP_SHARE * period[period > 0].min()) is None:
        return False
    builder = BRep_Builder()
    new = TopoDS_Wire()
    builder.MakeWire(new)
    for edge in keep:
        builder.Add(new, edge)
    new.Orientation(wire.Orientation())
    free = face.Free()
    face.Free(True)
    builder.Remove(face, wire)
    builder.Add(face, new)
    face.Free(free)
    shift_wire(face, new, period)
    return True


def _ends(face: TopoDS_Face, edge: TopoDS_Edge) -> tuple[np.ndarray, np.ndarray] | None:
    """(start, end) (2,) each in (u,v) of the edge as the wire runs it; None with no pcurve on the face."""
    pcurve = BRep_Tool.CurveOnSurface_s(edge, face, 0.0, 0.0)
    if pcurve is None:
        return None
    a, b = BRep_Tool.Range_s(edge)
    if edge.Orientation() == TopAbs_REVERSED:
        a, b = b, a
    return np.array(pcurve.Value(a).Coord()), np.array(pcurve.Value(b).Coord())


def _walk(face: TopoDS_Face, edges: list[TopoDS_Edge], ends: list[tuple[np.ndarray, np.ndarray]], period: np.ndarray,
          gap: float) -> list[tuple[int, np.ndarray]] | None:
    """The edges in the order the wire runs them (each starting at its predecessor's last vertex; of several, one
    that is not its predecessor's seam run back, then the one whose start lies nearest its predecessor's end modulo
    the period (2,), 0 where not periodic) with the shift (2,) that puts its start there; None where the walk or the
    loop does not close within `gap` in (u,v)."""
    first = [TopExp.FirstVertex_s(e, True) for e in edges]
    last = [TopExp.LastVertex_s(e, True) for e in edges]
    p = np.where(period > 0, period, 1.0)
    order, used, at = [(0, np.zeros(2))], {0}, ends[0][1]
    while len(order) < len(edges):
        prev = order[-1][0]
        best = None
        for i in range(len(edges)):
            if i in used or not first[i].IsSame(last[prev]):
                continue
            shift = np.where(period > 0, np.round((at - ends[i][0]) / p) * p, 0.0)
            miss = float(np.linalg.norm(ends[i][0] + shift - at))
            rank = (edges[i].IsSame(edges[prev]), miss)  # a seam's other use, straight back along it, last
            if miss <= gap and (best is None or rank < best[0]):
                best = (rank, i, shift)
        if best is None:
            return None
        order.append((best[1], best[2]))
        used.add(best[1])
        at = ends[best[1]][1] + best[2]
    return order if np.linalg.norm(at - ends[0][0]) <= gap else None


def _all_ends(face: TopoDS_Face, edges: list[TopoDS_Edge]) -> list[tuple[np.ndarray, np.ndarray]] | None:
    """_ends of every edge; None when one has no pcurve on the face or there are more than MAX_EDGES."""
    if not edges or len(edges) > MAX_EDGES:
        return None
    ends = [_ends(face, e) for e in edges]
    return None if any(x is None for x in ends) else ends  # type: ignore[return-value]


def ordered_edges(face: TopoDS_Face, wire: TopoDS_Wire) -> list[TopoDS_Edge] | None:
    """The wire's oriented edges in the order it runs them on the face, by vertices and, of several, the start nearest
    in (u,v) (_walk, no shift; the loop closing within GAP_SHARE of the face's (u,v) box diagonal); None when it does
    not close. For wires OCCT's BRepTools_WireExplorer stops in: it takes the next edge only within the vertex's
    tolerance in (u,v), and a seam 1e-5 off on a torus of small radii (a KiCad inductor's lead) ends its walk."""
    edges = explore(wire, TopAbs_EDGE, TopoDS.Edge_s)
    ends = _all_ends(face, edges)
    if ends is None:
        return None
    uv = np.array(ends).reshape(-1, 2)
    gap = GAP_SHARE * float(np.linalg.norm(uv.max(axis=0) - uv.min(axis=0)))
    order = _walk(face, edges, ends, np.zeros(2), gap)
    return None if order is None else [edges[i] for i, _ in order]


def shift_wire(face: TopoDS_Face, wire: TopoDS_Wire, period: np.ndarray) -> bool:
    """Move the wire's pcurves on the face by whole periods (period (2,): u and v, 0 where not periodic) so that the
    loop closes in (u,v) (_walk); True when one moved. A seam's two pcurves are moved apart as their uses need."""
    edges = explore(wire, TopAbs_EDGE, TopoDS.Edge_s)
    ends = _all_ends(face, edges)
    if ends is None:
        return False
    gap = GAP_SHARE * period[period > 0].min()
    uv = np.array(ends)  # (n, 2, 2): each edge's start and end
    if (np.linalg.norm(uv[:, None, 1] - uv[None, :, 0], axis=2).min(axis=1) <= gap).all():
        return False  # closed already: every end is some edge's start
    order = _walk(face, edges, ends, period, gap)
    if order is None or not any(np.any(s != 0) for _, s in order):
        return False
    builder = BRep_Builder()
    seams: list[tuple[TopoDS_Edge, dict]] = []  # type: ignore[type-arg]  # a seam edge, its moved pcurve per use
    for i, shift in order:
        edge = edges[i]
        curve = BRep_Tool.CurveOnSurface_s(edge, face, 0.0, 0.0)
        moved = curve.Translated(gp_Vec2d(*shift)) if np.any(shift != 0) else curve
        if BRep_Tool.IsClosed_s(edge, face):
            entry = next((x for x in seams if x[0].IsSame(edge)), None)
            if entry is None:
                entry = (edge, {})
                seams.append(entry)
            entry[1][edge.Orientation()] = moved
        elif np.any(shift != 0):
            builder.UpdateEdge(edge, moved, face, BRep_Tool.Tolerance_s(edge))
    for edge, curves in seams:
        if TopAbs_FORWARD in curves and TopAbs_REVERSED in curves:
            builder.UpdateEdge(TopoDS.Edge_s(edge.Oriented(TopAbs_FORWARD)), curves[TopAbs_FORWARD],
                               curves[TopAbs_REVERSED], face, BRep_Tool.Tolerance_s(edge))
    return True
