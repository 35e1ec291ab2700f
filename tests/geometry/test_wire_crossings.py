"""The fast STEP/IGES read: OCCT's crossing-wire repair skipped only where no face needs it, same shapes."""

import math

import numpy as np
import pytest
from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace, BRepBuilderAPI_MakePolygon
from OCP.BRepTools import BRepTools
from OCP.gp import gp_Pnt
from OCP.IFSelect import IFSelect_RetDone
from OCP.IGESControl import IGESControl_Reader, IGESControl_Writer
from OCP.Interface import Interface_Static
from OCP.STEPControl import STEPControl_AsIs, STEPControl_Reader, STEPControl_Writer
from OCP.TopAbs import TopAbs_EDGE, TopAbs_WIRE
from OCP.TopExp import TopExp, TopExp_Explorer
from OCP.TopoDS import TopoDS
from OCP.TopTools import TopTools_IndexedMapOfShape

from amprep.geometry.cad.read import read_shape
from amprep.geometry.cad.wire_crossings import crossing_faces, overlapping_boxes, wire_crosses, wires_cross
from tests.conftest import corpus


def _polygon(points):
    poly = BRepBuilderAPI_MakePolygon()
    for x, y in points:
        poly.Add(gp_Pnt(x, y, 0.0))
    poly.Close()
    return poly.Wire()


def _polygon_face(points, *holes):
    make = BRepBuilderAPI_MakeFace(_polygon(points), True)
    for hole in holes:
        make.Add(TopoDS.Wire_s(_polygon(hole).Reversed()))
    return make.Face()


def _wires(face):
    out, explorer = [], TopExp_Explorer(face, TopAbs_WIRE)
    while explorer.More():
        out.append(TopoDS.Wire_s(explorer.Current()))
        explorer.Next()
    return out


def _star(n, step):
    return [(10 * math.cos(2 * math.pi * k * step / n), 10 * math.sin(2 * math.pi * k * step / n)) for k in range(n)]


BOWTIE = [(0, 0), (10, 10), (10, 0), (0, 10)]  # edges 1 and 3 cross at (5, 5)


@pytest.mark.parametrize("points,crosses", [
    (BOWTIE, True),
    ([(0, 0), (10, 0), (10, 10), (0, 10)], False),
    (_star(21, 2), True),    # 21 edges: the long-wire path, every edge crossing two others
    (_star(21, 1), False),   # the convex 21-gon
    ([(0, 0), (10, 0), (10, 10), (5, 0.0), (0, 10)], True),  # edge 3 ends on edge 1, a T-touch at (5, 0)
])
def test_wire_crosses_finds_non_adjacent_edges_that_meet(points, crosses):
    face = _polygon_face(points)
    assert wire_crosses(_wires(face)[0], face) is crosses


SQUARE = [(0, 0), (10, 0), (10, 10), (0, 10)]


def _square(x, y, side):
    return [(x, y), (x + side, y), (x + side, y + side), (x, y + side)]


@pytest.mark.parametrize("holes,crosses", [
    ([_square(2, 2, 2), _square(6, 6, 2)], False),
    ([_square(2, 2, 2), _square(8, 8, 4)], True),   # the second hole crosses the outer boundary
    ([_square(2, 2, 3), _square(4, 4, 3)], True),   # two holes overlap
    ([_square(2, 2, 2), _square(4, 2, 2)], True),   # two holes share a side (a segment)
])
def test_wires_cross_finds_edges_of_two_wires_that_meet(holes, crosses):
    face = _polygon_face(SQUARE, *holes)
    assert wires_cross(_wires(face), face) is crosses
    assert (crossing_faces(face) == [0]) is crosses


def test_overlapping_boxes_is_every_overlapping_pair():
    rng = np.random.default_rng(3)
    lo = rng.uniform(0, 10, (300, 2))
    box = np.hstack([lo, lo + rng.uniform(0, 1.5, (300, 2))])
    box[::37] = (np.inf, np.inf, -np.inf, -np.inf)  # wires without a pcurve
    brute = {(a, b) for a in range(300) for b in range(a + 1, 300)
             if box[a, 0] <= box[b, 2] and box[b, 0] <= box[a, 2] and box[a, 1] <= box[b, 3] and box[b, 1] <= box[a, 3]}
    found = {tuple(sorted(p)) for p in overlapping_boxes(box)}
    assert found == brute and len(found) > 100


def _default_occt(path, fmt):
    """What OCCT's reader gives with its default healing."""
    Interface_Static.SetCVal_s("xstep.cascade.unit", "MM")
    reader = STEPControl_Reader() if fmt == "step" else IGESControl_Reader()
    assert reader.ReadFile(str(path)) == IFSelect_RetDone
    reader.TransferRoots()
    return reader.OneShape()


def _brep_text(shape, tmp_path, name):
    p = tmp_path / f"{name}.brep"
    BRepTools.Write_s(shape, str(p))
    return p.read_text()


def _edges(shape):
    m = TopTools_IndexedMapOfShape()
    TopExp.MapShapes_s(shape, TopAbs_EDGE, m)
    return m.Extent()


def _write(face, path, fmt):
    if fmt == "step":
        w = STEPControl_Writer()
        w.Transfer(face, STEPControl_AsIs)
        assert w.Write(str(path)) == IFSelect_RetDone
    else:
        w = IGESControl_Writer("MM", 1)
        w.AddShape(face)
        w.ComputeModel()
        assert w.Write(str(path))


@pytest.mark.parametrize("fmt", ["step", "iges"])
@pytest.mark.parametrize("face,edges", [
    (_polygon_face(BOWTIE), 6),                             # OCCT splits the crossing edges at their crossing
    (_polygon_face(SQUARE, _square(8, 8, 4)), 12),          # and a hole's edges where they cross the outer wire
    (_polygon_face([(0, 0), (10, 0), (5, 5), (10, 10), (0, 10), (5, 5)]), None),  # a wire through a point twice
])
def test_a_crossing_face_is_read_with_occts_repairs(tmp_path, fmt, face, edges):
    path = tmp_path / f"crossing.{fmt}"
    _write(face, path, fmt)
    shape, _ = read_shape(path, fmt)
    default = _default_occt(path, fmt)
    assert edges is None or _edges(default) == edges
    assert _brep_text(shape, tmp_path, "ours") == _brep_text(default, tmp_path, "occt")


def _plate_with_holes(path):
    import cadquery as cq

    plate = cq.Workplane("XY").box(42, 42, 3).faces(">Z").workplane().rarray(5, 5, 8, 8).hole(2.5)
    plate = plate.edges("%CIRCLE").chamfer(0.3)
    cq.exporters.export(plate, str(path))
    return path


@pytest.mark.parametrize("name", [
    "nist_ctc02_ap242.stp", "nist_ctc02_bspline_ap203.stp", "as1_assembly_ap214.stp",
    "featuretype_inch_ap214.step", "voron_hotend_mount_dragon.step", "bspline_45_faces.iges", "plate",
])
def test_the_fast_read_gives_occts_shape(tmp_path, name):
    path = _plate_with_holes(tmp_path / "plate.step") if name == "plate" else corpus(name)
    fmt = "iges" if path.suffix.lower() in (".iges", ".igs") else "step"
    shape, _ = read_shape(path, fmt)
    assert crossing_faces(shape) == []  # so the fast transfer was the one kept
    assert _brep_text(shape, tmp_path, "ours") == _brep_text(_default_occt(path, fmt), tmp_path, "occt")


def test_without_the_repair_the_bowtie_differs(tmp_path):
    """The control: OCCT's transfer with the repair off keeps the crossing, and the comparison above sees it."""
    from OCP.Resource import Resource_DataMapOfAsciiStringAsciiString
    from OCP.TCollection import TCollection_AsciiString

    path = tmp_path / "bowtie.step"
    _write(_polygon_face(BOWTIE), path, "step")
    reader = STEPControl_Reader()
    assert reader.ReadFile(str(path)) == IFSelect_RetDone
    params = Resource_DataMapOfAsciiStringAsciiString()
    params.Bind(TCollection_AsciiString("FixShape.FixNonAdjacentIntersectingEdgesMode"), TCollection_AsciiString("0"))
    reader.SetShapeFixParameters(params)
    reader.TransferRoots()
    raw = reader.OneShape()
    assert _edges(raw) == 4 and crossing_faces(raw) == [0]
    assert _brep_text(raw, tmp_path, "raw") != _brep_text(_default_occt(path, "step"), tmp_path, "occt")
