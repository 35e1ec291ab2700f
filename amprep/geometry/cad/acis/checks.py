"""Sanity of what was read: an edge's vertices on its curve, a face's vertices on its surface, to 1 % of the
edge's or face's size. A record misread, or a procedural subtype's stored approximation that is not the surface of
the face, fails here as `Unsupported` (the face is listed), never as a wrong face in the output."""

from __future__ import annotations

import math

from OCP.Bnd import Bnd_Box
from OCP.BRep import BRep_Tool
from OCP.BRepBndLib import BRepBndLib
from OCP.Geom import Geom_Curve, Geom_Plane, Geom_Surface
from OCP.GeomAPI import GeomAPI_ProjectPointOnSurf
from OCP.gp import gp_Pnt
from OCP.TopAbs import TopAbs_VERTEX
from OCP.TopExp import TopExp_Explorer
from OCP.TopoDS import TopoDS, TopoDS_Face


class Unsupported(Exception):
    """A surface or curve with no exact or stored form (kind: its ACIS class)."""

    def __init__(self, kind: str, detail: str = "") -> None:
        super().__init__(kind)
        self.kind, self.detail = kind, detail


def _off(d: float, ref: float, p: gp_Pnt) -> bool:
    """True when a vertex lies `d` from its curve or surface, beyond 1 % of `ref` (the edge's chord, the face's
    extent) plus round-off: a misread record, or a procedural approximation that is not the face's surface."""
    return d > 0.01 * ref + 1e-6 * (1 + abs(p.X()) + abs(p.Y()) + abs(p.Z()))


def check_on_curve(curve: Geom_Curve, a: float, b: float, p1: gp_Pnt, p2: gp_Pnt, i: int) -> None:
    """An edge's vertices at its curve's parameters a and b within 1 % of its chord (of the curve's size when closed)
    of the vertices' own positions, else Unsupported."""
    chord = p1.Distance(p2)
    if chord == 0:
        period = curve.Period() if curve.IsPeriodic() else curve.LastParameter() - curve.FirstParameter()
        chord = p1.Distance(curve.Value(a + period / 2)) if math.isfinite(period) else 1.0
    d = max(curve.Value(a).Distance(p1), curve.Value(b).Distance(p2))
    if _off(d, chord, p1):
        raise Unsupported("curve", f"edge ${i}'s vertices lie {d:.3g} off its curve")


def check_vertices_on(surface: Geom_Surface, face: TopoDS_Face, kind: str, i: int) -> None:
    """Every vertex of a face within 1 % of the face's extent of its surface, else Unsupported."""
    box = Bnd_Box()
    BRepBndLib.Add_s(face, box, False)
    if box.IsVoid():
        return
    extent = math.sqrt(box.SquareExtent())
    plane = surface.Pln() if isinstance(surface, Geom_Plane) else None
    ex = TopExp_Explorer(face, TopAbs_VERTEX)
    while ex.More():
        p = BRep_Tool.Pnt_s(TopoDS.Vertex_s(ex.Current()))
        if plane is not None:
            d = plane.Distance(p)
        else:
            proj = GeomAPI_ProjectPointOnSurf(p, surface)
            d = proj.LowerDistance() if proj.NbPoints() else 0.0  # no foot: a singular point (apex, pole), let be
        if _off(d, extent, p):
            raise Unsupported(kind, f"face ${i}'s vertices lie {d:.3g} off its surface")
        ex.Next()
