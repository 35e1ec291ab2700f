"""ACIS input (SAT text, SAB binary, the ACIS data of DXF entities) as an OCCT shape in mm: records.py parses,
entities.py decodes, splines.py reads B-spline blocks, build.py makes the shape; docs/acis.md gives the reasoning."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from OCP.BRepBuilderAPI import BRepBuilderAPI_Transform
from OCP.gp import gp_Trsf
from OCP.ShapeFix import ShapeFix_Shape
from OCP.TopAbs import TopAbs_SHELL
from OCP.TopoDS import TopoDS, TopoDS_Shape

from amprep.errors import AmprepError, ErrorCode, is_occt_failure
from amprep.geometry.cad.acis.build import Builder, Built, bodies
from amprep.geometry.cad.acis.entities import Model, Transform
from amprep.geometry.cad.acis.records import Records, fail, parse
from amprep.geometry.cad.topology import compound, explore

#: unit scales ACIS headers carry (mm per model unit) and their names
UNIT_NAMES = {1.0: "mm", 10.0: "cm", 1000.0: "m", 25.4: "inch", 304.8: "ft", 0.001: "um", 1e6: "km"}


@dataclass
class AcisShape:
    """The shape in mm, the unit the header states ("none": unstated, read as mm), what was left out and why."""

    shape: TopoDS_Shape
    units: str
    version: int
    product: str
    solids: int = 0
    sheets: int = 0
    skipped: list[dict[str, object]] = field(default_factory=list)
    pcurves_used: int = 0  # stored pcurves put on B-spline faces' edges (the others computed by OCCT's healing)

    def notes(self) -> list[str]:
        out = []
        if self.sheets:
            out.append(f"{self.sheets} ACIS body part(s) are open sheets, not solids: converted as open surfaces")
        if self.skipped:
            kinds = sorted({str(s["surface"]) for s in self.skipped})
            out.append(f"{len(self.skipped)} face(s) on surfaces with no exact or stored form were left out "
                       f"(unsupported_geometry: {', '.join(kinds)})")
        return out


def _unit(records: Records, unit: tuple[float, str] | None = None) -> tuple[float, str]:
    """(mm per model unit, its name): the header's scale (≤ 0: unstated, mm), or the DXF drawing's `unit`."""
    if unit is not None:
        return unit
    u = records.header.unit_mm
    if not u > 0 or u != u:
        return 1.0, "none"
    name = next((n for s, n in UNIT_NAMES.items() if abs(u - s) <= 1e-9 * s), f"{u:g} mm")
    return u, name


def _placement(t: Transform | None, unit: float) -> gp_Trsf | None:
    """The body's transform then the unit scale as one gp_Trsf (None: identity); a shear is unreadable_cad."""
    trsf = gp_Trsf()
    if t is None:
        if unit == 1.0:
            return None
        trsf.SetScaleFactor(unit)
        return trsf
    m, (tx, ty, tz), s = t.rows, t.translation, t.scale * unit
    # p' = s·(p·M) + t: the matrix acting on column vectors is s·Mᵀ
    try:
        trsf.SetValues(s * m[0], s * m[3], s * m[6], tx * unit,
                       s * m[1], s * m[4], s * m[7], ty * unit,
                       s * m[2], s * m[5], s * m[8], tz * unit)
    except Exception as exc:  # noqa: BLE001 - OCCT refuses a matrix that is not a similarity
        if not is_occt_failure(exc):
            raise
        raise fail("a body transform with shear or non-uniform scale") from None
    return trsf


def _heal(shape: TopoDS_Shape, precision: float) -> TopoDS_Shape:
    fix = ShapeFix_Shape(shape)
    fix.SetPrecision(precision)
    fix.SetMaxTolerance(max(precision * 1e3, 1e-3))
    fix.Perform()
    return fix.Shape()


def build_shape(records: Records, unit_of: tuple[float, str] | None = None) -> AcisShape:
    """The bodies of parsed ACIS records as one compound: a solid per closed lump, open shells for sheets."""
    from amprep.geometry.cad.read import free_edge_count

    model = Model(records)
    unit, units = _unit(records, unit_of)
    builder = Builder(model)
    built = Built()
    body_ids = bodies(model)
    if not body_ids:
        raise AmprepError(ErrorCode.EMPTY_MODEL, "the ACIS file holds no body")
    for b in body_ids:
        builder.body(b, built)
    parts: list[TopoDS_Shape] = []
    solids = sheets = 0
    precision = 1e-6 * unit
    for b, solid in built.shapes:
        body = model.body(b)
        trsf = _placement(model.transform(body.transform) if body.transform != -1 else None, unit)
        shape = BRepBuilderAPI_Transform(solid, trsf, True).Shape() if trsf is not None else solid
        shape = _heal(shape, precision)
        if free_edge_count(shape) == 0:
            parts.append(shape)
            solids += 1
        else:  # an open body: its shells, not a solid
            parts.extend(explore(shape, TopAbs_SHELL, TopoDS.Shell_s))
            sheets += 1
    if not parts:
        raise AmprepError(ErrorCode.EMPTY_MODEL, "the ACIS file holds no face that can be built")
    return AcisShape(compound(parts), units, records.header.version, records.header.product, solids, sheets,
                     built.skipped, builder.pcurves_used)


def read_acis(data: bytes, unit: tuple[float, str] | None = None) -> AcisShape:
    """SAT or SAB bytes as an AcisShape; malformed data is unreadable_cad, a file with no body empty_model."""
    try:
        return build_shape(parse(data), unit)
    except AmprepError:
        raise
    except RecursionError:
        raise fail("the data nests too deeply") from None
    except Exception as exc:  # noqa: BLE001 - OCCT's construction errors on inconsistent geometry
        if not is_occt_failure(exc):
            raise
        raise fail(f"OCCT could not build the geometry ({type(exc).__name__})") from None


def read_dxf(path: str | Path) -> AcisShape:
    """Every ACIS entity of a DXF's model space (dxf.py), each built as its own bodies, in the drawing's unit."""
    from amprep.geometry.cad.acis.dxf import acis_entities

    entities, unit, units = acis_entities(path)
    if not entities:
        raise AmprepError(ErrorCode.EMPTY_MODEL, "the DXF file has no 3DSOLID, BODY, REGION or SURFACE entity")
    shapes: list[TopoDS_Shape] = []
    out = AcisShape(TopoDS_Shape(), units, 0, "")
    for kind, handle, data in entities:
        try:
            one = read_acis(data, (unit, units))
        except AmprepError as exc:
            raise AmprepError(exc.code, f"DXF {kind} {handle}: {exc.message}") from None
        shapes.append(one.shape)
        out.version = max(out.version, one.version)
        out.product = out.product or one.product
        out.solids += one.solids
        out.sheets += one.sheets
        out.skipped += [dict(s, entity=handle) for s in one.skipped]
        out.pcurves_used += one.pcurves_used
    out.shape = compound(shapes)
    return out


def read_acis_file(path: str | Path, fmt: str) -> AcisShape:
    """A SAT, SAB or DXF file as an AcisShape (fmt from formats.sniff_bytes)."""
    if fmt == "dxf":
        return read_dxf(path)
    return read_acis(Path(path).read_bytes())


__all__ = ["AcisShape", "build_shape", "read_acis", "read_acis_file", "read_dxf"]
