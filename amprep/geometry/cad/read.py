"""Read STEP, IGES and BREP into an OCCT shape in millimetres, with the unit the file declared."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from OCP.BinTools import BinTools
from OCP.BRep import BRep_Builder, BRep_Tool
from OCP.BRepBuilderAPI import BRepBuilderAPI_Sewing
from OCP.BRepTools import BRepTools
from OCP.IFSelect import IFSelect_RetDone
from OCP.IGESControl import IGESControl_Reader
from OCP.Interface import Interface_Static
from OCP.Message import Message
from OCP.Resource import Resource_DataMapOfAsciiStringAsciiString
from OCP.STEPControl import STEPControl_Reader
from OCP.TCollection import TCollection_AsciiString
from OCP.TColStd import TColStd_SequenceOfAsciiString
from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE, TopAbs_SHELL, TopAbs_SOLID
from OCP.TopExp import TopExp
from OCP.TopoDS import TopoDS, TopoDS_Face, TopoDS_Shape
from OCP.TopTools import TopTools_IndexedDataMapOfShapeListOfShape, TopTools_IndexedMapOfShape
from OCP.XSControl import XSControl_Reader

from amprep.errors import AmprepError, ErrorCode, is_occt_failure
from amprep.geometry.cad.creases import split_at_creases
from amprep.geometry.cad.locations import bake_scaled_locations
from amprep.geometry.cad.pcurve_shifts import fix_shifted_pcurves
from amprep.geometry.cad.topology import compound, explore
from amprep.geometry.cad.wire_crossings import crossing_faces
from amprep.geometry.core.formats import ACIS_FORMATS, sniff_path


@dataclass(frozen=True, eq=False)
class CadModel:
    """A B-rep read from a file, in mm: `faces[i]` is CAD face i, `face_solid[i]` its solid index (-1: none)."""

    shape: TopoDS_Shape
    format: str
    units: str  # the length unit the file declared ("none" when it declares none)
    faces: tuple[TopoDS_Face, ...]
    face_solid: tuple[int, ...]
    solids: int
    sewn: bool = False
    notes: tuple[str, ...] = ()  # what the reader left out or changed, for the report (ACIS sheets, skipped faces)
    unsupported: tuple[dict, ...] = ()  # faces with no exact or stored geometry: {"face", "surface", "why"}


_UNIT_NAMES = {
    "millimetre": "mm", "millimeter": "mm", "mm": "mm", "inch": "inch", "in": "inch",
    "metre": "m", "meter": "m", "m": "m", "centimetre": "cm", "centimeter": "cm", "cm": "cm",
    "foot": "ft", "ft": "ft", "micrometre": "um", "micron": "um", "um": "um",
}


def _unit_name(raw: str) -> str:
    return _UNIT_NAMES.get(raw.strip().strip("'.").lower(), raw.strip().lower() or "none")


def _crossing_repair(reader: XSControl_Reader, on: bool) -> None:
    """Turn OCCT's repair of a wire's crossing edges on (its default, -1) or off; bound after ReadFile, since the
    transfer actor reads it then, and IGES's actor is shared by every reader of the process."""
    params = Resource_DataMapOfAsciiStringAsciiString()
    params.Bind(TCollection_AsciiString("FixShape.FixNonAdjacentIntersectingEdgesMode"),
                TCollection_AsciiString("-1" if on else "0"))
    reader.SetShapeFixParameters(params)


def _transfer(reader: XSControl_Reader, parse_again: Callable[[], XSControl_Reader]) -> TopoDS_Shape:
    """OCCT's transfer and shape healing, less its repair of a wire's crossing edges unless a face needs it.

    That repair rebuilds a face once per wire (O(wires^2): most of a 1,600-hole plate's read) and changes
    nothing where no edges of a face meet that should not; when `crossing_faces` finds a face where some do (in
    one wire or, should a later repair have split the wire, in two), or cannot tell, the file is transferred
    again with OCCT's default healing, so the shape is always the one OCCT's reader gives.
    """
    _crossing_repair(reader, False)
    try:
        reader.TransferRoots()
    finally:
        _crossing_repair(reader, True)
    shape = reader.OneShape()
    try:
        clean = shape.IsNull() or not crossing_faces(shape)
    except Exception as exc:  # noqa: BLE001 - an OCCT failure in the check: let OCCT's own repair decide
        if not is_occt_failure(exc):
            raise
        clean = False
    if clean:
        return shape
    reader = parse_again()
    _crossing_repair(reader, True)
    reader.TransferRoots()
    return reader.OneShape()


@contextmanager
def occt_messages_muted() -> Iterator[None]:
    """OCCT's default messenger without its printers inside the block (its readers print progress lines such as
    IGES's "Total number of loaded entities" on stdout); the printers are put back after."""
    messenger = Message.DefaultMessenger_s()
    printers = messenger.Printers()
    held = [printers.Value(i) for i in range(1, printers.Length() + 1)]
    for printer in held:
        messenger.RemovePrinter(printer)
    try:
        yield
    finally:
        for printer in held:
            messenger.AddPrinter(printer)


def _parsed(reader: XSControl_Reader, path: Path, name: str) -> XSControl_Reader:
    Interface_Static.SetCVal_s("xstep.cascade.unit", "MM")
    if reader.ReadFile(str(path)) != IFSelect_RetDone:
        raise AmprepError(ErrorCode.UNREADABLE_CAD, f"the {name} file could not be parsed")
    return reader


def _read_step(path: Path) -> tuple[TopoDS_Shape, str]:
    reader = _parsed(STEPControl_Reader(), path, "STEP")
    lengths, angles, solids = (TColStd_SequenceOfAsciiString() for _ in range(3))
    reader.FileUnits(lengths, angles, solids)
    units = _unit_name(lengths.Value(1).ToCString()) if lengths.Length() else "none"
    return _transfer(reader, lambda: _parsed(STEPControl_Reader(), path, "STEP")), units


def _read_iges(path: Path) -> tuple[TopoDS_Shape, str]:
    reader = _parsed(IGESControl_Reader(), path, "IGES")
    units = _unit_name(reader.IGESModel().GlobalSection().UnitName().ToCString())
    return _transfer(reader, lambda: _parsed(IGESControl_Reader(), path, "IGES")), units


def _read_brep(path: Path) -> tuple[TopoDS_Shape, str]:
    shape = TopoDS_Shape()
    with path.open("rb") as fh:
        binary = fh.read(64).lstrip().startswith(b"Open CASCADE Topology")
    try:
        ok = BinTools.Read_s(shape, str(path)) if binary else BRepTools.Read_s(shape, str(path), BRep_Builder())
    except Exception as exc:  # noqa: BLE001 - OCCT raises Standard_Failure subclasses on corrupt input
        if not is_occt_failure(exc):
            raise
        ok = False
    if not ok:
        raise AmprepError(ErrorCode.UNREADABLE_CAD, "the BREP file could not be parsed")
    return shape, "none"


def _indexed(shape: TopoDS_Shape, kind: int) -> TopTools_IndexedMapOfShape:
    m = TopTools_IndexedMapOfShape()
    TopExp.MapShapes_s(shape, kind, m)
    return m


def _sew(shape: TopoDS_Shape, tolerance: float) -> TopoDS_Shape:
    """Join loose faces (IGES trimmed surfaces) into shells through shared B-rep edges."""
    sewing = BRepBuilderAPI_Sewing(tolerance)
    sewing.Add(shape)
    sewing.Perform()
    sewn = sewing.SewedShape()
    return sewn if not sewn.IsNull() else shape


#: gap (mm) within which sewing joins two loose faces' edges
SEW_TOLERANCE = 1e-3


def free_edge_count(shape: TopoDS_Shape) -> int:
    """Edges of a shape bounding one face only (degenerated edges, the poles, not counted)."""
    faces_of = TopTools_IndexedDataMapOfShapeListOfShape()
    TopExp.MapShapesAndAncestors_s(shape, TopAbs_EDGE, TopAbs_FACE, faces_of)
    return sum(1 for i in range(1, faces_of.Extent() + 1)
               if faces_of.FindFromIndex(i).Extent() == 1 and not BRep_Tool.Degenerated_s(TopoDS.Edge_s(faces_of.FindKey(i))))


def sew_loose_faces(shape: TopoDS_Shape, tolerance: float = SEW_TOLERANCE) -> tuple[TopoDS_Shape, bool]:
    """(shape, sewn): the faces outside any solid (in open shells, one shell per face as some STEP surface models
    have, or in no shell, as IGES has them) sewn together when they have a surface and leave edges free (one face
    too: a closed surface written as one trimmed surface, a torus, has its seams as free edge pairs); solids are
    kept as they are. Unchanged, False, when there is nothing to sew."""
    loose = explore(shape, TopAbs_SHELL, TopoDS.Shell_s, avoid=TopAbs_SOLID)
    loose += explore(shape, TopAbs_FACE, TopoDS.Face_s, avoid=TopAbs_SHELL)
    part = compound(loose)
    faces = explore(part, TopAbs_FACE, TopoDS.Face_s)
    if not faces or any(BRep_Tool.Surface_s(f) is None for f in faces) or free_edge_count(part) == 0:
        return shape, False
    solids = explore(shape, TopAbs_SOLID, TopoDS.Solid_s)
    sewn = _sew(part, tolerance)
    return (compound([*solids, sewn]) if solids else sewn), True


def model_from_shape(shape: TopoDS_Shape, fmt: str = "brep", units: str = "none", sewn: bool = False,
                     notes: tuple[str, ...] = (), unsupported: tuple[dict, ...] = ()) -> CadModel:
    """Index the faces and solids of a shape (faces in TopExp order; an assembly's instances are distinct), after
folding any scaling location into the geometry (locations.py)."""
    if shape is None or shape.IsNull():
        raise AmprepError(ErrorCode.EMPTY_MODEL, "the file holds no shape")
    shape, _ = bake_scaled_locations(shape)
    faces_map = _indexed(shape, TopAbs_FACE)
    if faces_map.Extent() == 0:
        raise AmprepError(ErrorCode.EMPTY_MODEL, "the file holds no faces")
    solids_map = _indexed(shape, TopAbs_SOLID)
    face_solid = [-1] * faces_map.Extent()
    for s in range(1, solids_map.Extent() + 1):
        for f in _iter_map(_indexed(solids_map.FindKey(s), TopAbs_FACE)):
            i = faces_map.FindIndex(f)
            if i > 0 and face_solid[i - 1] < 0:
                face_solid[i - 1] = s - 1
    faces = tuple(TopoDS.Face_s(faces_map.FindKey(i)) for i in range(1, faces_map.Extent() + 1))
    return CadModel(shape, fmt, units, faces, tuple(face_solid), solids_map.Extent(), sewn, notes, unsupported)


def _iter_map(m: TopTools_IndexedMapOfShape):  # type: ignore[no-untyped-def]
    return (m.FindKey(i) for i in range(1, m.Extent() + 1))


def read_shape(path: str | Path, fmt: str) -> tuple[TopoDS_Shape, str]:
    """The shape OCCT's reader transfers from a STEP, IGES or BREP file (in mm), and the unit the file declared;
    OCCT prints nothing meanwhile (occt_messages_muted)."""
    readers = {"step": _read_step, "iges": _read_iges, "brep": _read_brep}
    if fmt not in readers:
        raise AmprepError(ErrorCode.UNSUPPORTED_FORMAT, f"{fmt} is not a CAD format")
    try:
        with occt_messages_muted():  # parse, transfer and any second parse alike
            shape, units = readers[fmt](Path(path))
    except AmprepError:
        raise
    except Exception as exc:  # noqa: BLE001 - OCCT failures surface as assorted exception types
        if not is_occt_failure(exc):
            raise
        raise AmprepError(ErrorCode.UNREADABLE_CAD, f"OCCT could not read the {fmt.upper()} file ({type(exc).__name__})") from None
    if shape.IsNull():
        raise AmprepError(ErrorCode.EMPTY_MODEL, f"the {fmt.upper()} file holds no shape OCCT can transfer")
    return shape, units


def read_cad(path: str | Path, fmt: str | None = None) -> CadModel:
    """Read a STEP, IGES, BREP or ACIS (SAT, SAB, DXF) file into a CadModel in mm; faces outside solids are sewn
    (sew_loose_faces) except ACIS's, whose faces share their edges already; wires open by a period in (u,v) are
    shifted onto one (fix_shifted_pcurves)."""
    fmt = fmt or sniff_path(Path(path))
    if fmt in ACIS_FORMATS:
        from amprep.geometry.cad.acis import read_acis_file

        with occt_messages_muted():
            acis = read_acis_file(path, fmt)
            shape, split = split_at_creases(acis.shape)
        return model_from_shape(shape, fmt, acis.units, False, tuple(acis.notes()) + _split_note(split),
                                tuple(acis.skipped))
    shape, units = read_shape(path, fmt)
    with occt_messages_muted():
        shifted = fix_shifted_pcurves(shape)
    shape, sewn = sew_loose_faces(shape)
    with occt_messages_muted():
        shape, split = split_at_creases(shape)
    notes = (f"{shifted} face boundar{'y' if shifted == 1 else 'ies'} in (u,v) a period apart: moved onto one period",
             ) if shifted else ()
    return model_from_shape(shape, fmt, units, sewn, notes + _split_note(split))


def _split_note(split: int) -> tuple[str, ...]:
    return (f"{split} face{'' if split == 1 else 's'} split along {'its' if split == 1 else 'their'} creases (a "
            "B-spline's C0 knot lines where the surface turns), so that the mesh has edges on them",) if split else ()
