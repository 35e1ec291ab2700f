"""Locations that scale, folded into the geometry: OCCT meshes a shape in its own frame, so an instance placed by
a location with a scale factor (a STEP product in other units than the assembly's, a scaled instance) would be
meshed at the tolerance times that factor and evaluated on parameters the scale does not carry."""

from __future__ import annotations

from OCP.BRepBuilderAPI import BRepBuilderAPI_Transform
from OCP.gp import gp_Pnt, gp_Trsf
from OCP.TopAbs import TopAbs_FACE, TopAbs_SHELL, TopAbs_SOLID
from OCP.TopLoc import TopLoc_Location
from OCP.TopoDS import TopoDS, TopoDS_Shape

from amprep.geometry.cad.topology import compound, explore

#: a location whose |scale factor| differs from 1 by more than this scales
SCALE_EPS = 1e-9


def scale_of(shape: TopoDS_Shape) -> float:
    """|scale factor| of a shape's location (1.0 for none)."""
    loc = shape.Location()
    return 1.0 if loc.IsIdentity() else abs(loc.Transformation().ScaleFactor())


def scales(shape: TopoDS_Shape) -> bool:
    """True when some face of the shape is placed by a scaling location (composed from the root)."""
    return any(abs(scale_of(f) - 1.0) > SCALE_EPS for f in explore(shape, TopAbs_FACE, TopoDS.Face_s))


def _parts(shape: TopoDS_Shape) -> list[TopoDS_Shape]:
    """The solids, the shells outside solids and the faces outside shells, with their composed locations."""
    return (explore(shape, TopAbs_SOLID, TopoDS.Solid_s)
            + explore(shape, TopAbs_SHELL, TopoDS.Shell_s, avoid=TopAbs_SOLID)
            + explore(shape, TopAbs_FACE, TopoDS.Face_s, avoid=TopAbs_SHELL))


def _scaled_copy(part: TopoDS_Shape, trsf: gp_Trsf) -> TopoDS_Shape:
    """The part's geometry transformed by `trsf` (copied, its own location and any inside folded in)."""
    return BRepBuilderAPI_Transform(part, trsf, True).Shape()


def bake_scaled_locations(shape: TopoDS_Shape) -> tuple[TopoDS_Shape, bool]:
    """(shape, changed): every part (solid, loose shell or face) placed by a location that scales rebuilt with the
    scale in its geometry and placed by the rest of the location (rotation, mirror, translation), one copy per
    shape and scale so instances stay instances; unchanged, False, when nothing scales."""
    if not scales(shape):
        return shape, False
    copies: dict[tuple[int, float], list[tuple[TopoDS_Shape, TopoDS_Shape]]] = {}
    out = []
    for part in _parts(shape):
        s = scale_of(part)
        if abs(s - 1.0) <= SCALE_EPS:
            out.append(part if not scales(part) else _scaled_copy(part, gp_Trsf()))
            continue
        full = part.Location().Transformation()
        scale = gp_Trsf()
        scale.SetScale(gp_Pnt(0, 0, 0), s)
        rigid = full.Multiplied(scale.Inverted())  # full = rigid ∘ scale
        bare = part.Located(TopLoc_Location())
        same = copies.setdefault((hash(bare), round(s, 12)), [])
        copy = next((c for b, c in same if b.IsEqual(bare)), None)
        if copy is None:
            copy = _scaled_copy(bare, scale)
            same.append((bare, copy))
        out.append(copy.Moved(TopLoc_Location(rigid), False))
    return compound(out), True
