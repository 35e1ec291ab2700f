"""Solids built here with cadquery for bench/real_parts.py --built: the features that trouble meshers and that the
corpus has few of (helix-swept threads ending on a plane, engraved text, twisted and lofted B-splines, a torus
thinner than a coarse tolerance, holes smaller than it, a crescent pinched to a point, a parametric surface), each
written four ways: BREP, STEP, IGES solids (BRep mode) and IGES trimmed surfaces (no topology: sewn on reading)."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import cadquery as cq
from OCP.IGESControl import IGESControl_Writer


def _thread(pitch: float, height: float, radius: float, size: float) -> cq.Shape:
    helix = cq.Wire.makeHelix(pitch=pitch, height=height, radius=radius)
    swept = cq.Workplane("XZ").center(radius, 0).polygon(3, size).sweep(cq.Workplane().add(helix), isFrenet=True)
    return cq.Workplane().circle(radius).extrude(height).union(swept).val()


def _knurl() -> cq.Shape:
    body = cq.Workplane().circle(8).extrude(10)
    for i in range(24):
        a = 2 * math.pi * i / 24
        cut = cq.Workplane().transformed(offset=(8 * math.cos(a), 8 * math.sin(a), 0), rotate=(0, 0, math.degrees(a) + 45))
        body = body.cut(cut.rect(0.6, 0.6).extrude(10))
    return body.val()


def _sphere_holes() -> cq.Shape:
    body = cq.Workplane().sphere(10)
    for plane in ("YZ", "XZ", "XY"):
        body = body.cut(cq.Workplane(plane).circle(2.5).extrude(12, both=True))
    return body.val()


def _param_surface() -> cq.Shape:
    face = cq.Workplane().parametricSurface(
        lambda u, v: cq.Vector(u * 20, v * 20, 2 * math.sin(u * 6) * math.cos(v * 5)), N=12).val()
    return cq.Solid.extrudeLinear(face, cq.Vector(0, 0, -5))


PARTS: dict[str, Callable[[], cq.Shape]] = {
    "thread": lambda: _thread(1.5, 12, 5, 1.2),
    "fine_thread": lambda: _thread(0.8, 6, 3, 0.6),
    "text": lambda: cq.Workplane().box(40, 15, 4).faces(">Z").workplane().text("AmPrep 3D", 6, -1.5, combine="cut").val(),
    "revolved_spline": lambda: cq.Workplane("XZ").moveTo(0, 0).lineTo(2, 0)
    .spline([(6, 3), (4, 8), (7, 14), (3, 18), (2, 20)], includeCurrent=True).lineTo(0, 20).close()
    .revolve(360, (0, 0, 0), (0, 1, 0)).val(),
    "revolved_270": lambda: cq.Workplane("XZ").moveTo(5, 0).lineTo(9, 0).lineTo(9, 3).threePointArc((7, 6), (5, 3))
    .close().revolve(270, (0, 0, 0), (0, 1, 0)).val(),
    "shelled_box": lambda: cq.Workplane().box(30, 20, 15).edges("|Z").fillet(4).faces(">Z").shell(-1.5).edges()
    .fillet(0.5).val(),
    "twisted": lambda: cq.Workplane().rect(10, 4).twistExtrude(20, 90).val(),
    "sphere_in_box": lambda: cq.Workplane().sphere(10).intersect(cq.Workplane().box(16, 16, 16)).val(),
    "sphere_holes": _sphere_holes,
    "thin_torus": lambda: cq.Solid.makeTorus(30, 0.4),
    "knurl": _knurl,
    "loft_square_round": lambda: cq.Workplane().rect(20, 20).workplane(offset=15).circle(6).loft().faces(">Z")
    .fillet(1).val(),
    "loft_four": lambda: cq.Workplane().circle(5).workplane(offset=4).rect(6, 6).workplane(offset=4).polygon(6, 8)
    .workplane(offset=4).circle(3).loft(ruled=False).val(),
    "chamfered_holes": lambda: cq.Workplane().box(50, 30, 8).faces(">Z").workplane().rarray(8, 8, 5, 3).hole(3)
    .edges(">Z").chamfer(0.8).val(),
    "tiny_holes": lambda: cq.Workplane().box(10, 10, 2).faces(">Z").workplane().rarray(2, 2, 3, 3).hole(0.1).val(),
    "cone_on_pin": lambda: cq.Solid.makeCone(8, 0, 15).fuse(cq.Solid.makeCylinder(3, 20, cq.Vector(0, 0, -5))),
    "filleted_union": lambda: cq.Workplane().box(20, 20, 10).union(cq.Workplane().workplane(offset=5).circle(6)
                                                                   .extrude(8)).edges().fillet(1.2).val(),
    "nut": lambda: cq.Workplane().polygon(6, 20).extrude(8).faces(">Z").workplane().hole(10).edges("not |Z")
    .chamfer(0.6).val(),
    "pinched_crescent": lambda: cq.Workplane().circle(10).extrude(3).cut(cq.Workplane().center(4, 0).circle(6)
                                                                         .extrude(3))
    .union(cq.Workplane().center(-3, 0).circle(7).extrude(5)).val(),
    "spline_plate": lambda: cq.Workplane().spline([(0, 0), (10, 5), (20, -3), (30, 4), (40, 0)]).lineTo(40, -10)
    .lineTo(0, -10).close().extrude(2).faces(">Z").edges().fillet(0.8).val(),
    "parametric_surface": _param_surface,
}


def _iges(shape: cq.Shape, path: Path, mode: int) -> None:
    writer = IGESControl_Writer("MM", mode)
    writer.AddShape(shape.wrapped)
    writer.ComputeModel()
    writer.Write(str(path))


def write_built_parts(into: Path) -> list[Path]:
    """Every part of PARTS written into `into` as name.brep, name.step, name.igs (IGES solids) and name_faces.igs
    (IGES trimmed surfaces)."""
    into.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, build in PARTS.items():
        shape = build()
        shape.exportBrep(str(into / f"{name}.brep"))
        cq.exporters.export(cq.Workplane().add(shape), str(into / f"{name}.step"))
        _iges(shape, into / f"{name}.igs", 1)
        _iges(shape, into / f"{name}_faces.igs", 0)
        paths += [into / f"{name}{suffix}" for suffix in (".brep", ".step", ".igs", "_faces.igs")]
    return paths
