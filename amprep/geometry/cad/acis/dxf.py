"""The ACIS data of a DXF drawing's model-space solids, through ezdxf (it reads DXF's tags, text and binary)."""

from __future__ import annotations

from pathlib import Path

from amprep.errors import AmprepError, ErrorCode

#: DXF entities that carry ACIS data (SAT lines before R2013, SAB bytes from R2013)
ACIS_ENTITIES = ("3DSOLID", "BODY", "REGION", "SURFACE", "EXTRUDEDSURFACE", "LOFTEDSURFACE", "REVOLVEDSURFACE",
                 "SWEPTSURFACE", "PLANESURFACE", "NURBSURFACE")
#: $INSUNITS code → mm per drawing unit (0: unitless)
INSUNITS_MM = {1: 25.4, 2: 304.8, 3: 1609344.0, 4: 1.0, 5: 10.0, 6: 1000.0, 7: 1e6, 8: 25.4e-6, 9: 0.0254,
               10: 914.4, 11: 1e-7, 12: 1e-6, 13: 1e-3, 14: 100.0, 15: 1e4, 16: 1e5, 17: 1e12, 18: 1.495978707e14,
               19: 9.4607304725808e18, 20: 3.0856776e19, 21: 304.80061, 22: 25.400051, 23: 914.40183, 24: 1609347.2}
INSUNITS_NAME = {1: "inch", 2: "ft", 4: "mm", 5: "cm", 6: "m", 13: "um"}


def acis_entities(path: str | Path) -> tuple[list[tuple[str, str, bytes]], float, str]:
    """([(DXF type, handle, SAT or SAB bytes)] of the model space in drawing order, mm per drawing unit, unit name
    ("none" when $INSUNITS is unset or unitless: read as mm))."""
    import ezdxf
    from ezdxf.lldxf.const import DXFError

    try:
        doc = ezdxf.readfile(str(path))
    except (DXFError, OSError, UnicodeDecodeError, ValueError, IndexError, KeyError, TypeError) as exc:
        raise AmprepError(ErrorCode.UNREADABLE_CAD, f"the DXF file could not be parsed ({type(exc).__name__})") from None
    code = doc.header.get("$INSUNITS", 0)
    code = code if isinstance(code, int) else 0
    unit = INSUNITS_MM.get(code, 1.0)
    name = INSUNITS_NAME.get(code, f"{unit:g} mm" if code in INSUNITS_MM else "none")
    out = []
    for e in doc.modelspace():
        kind = e.dxftype()
        if kind not in ACIS_ENTITIES:
            continue
        if getattr(e, "has_binary_data", False):
            data = bytes(e.sab or b"")
        else:
            data = "\n".join(e.sat or []).encode("utf-8", "replace")
        if data:
            out.append((kind, str(e.dxf.handle), data))
    return out, unit, name
