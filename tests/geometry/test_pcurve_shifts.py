"""Pcurves a period apart, forced: a cylinder whose seam's two pcurves are moved 4π apart and its top circle's by a
period (the pattern of KiCad's THT transformer model, where OCCT's BRepMesh gave no triangulation and both meshers
went 3–30× over the tolerance): read, the loop is closed again and both meshers give what the sound cylinder gives,
within tolerance by OCCT's distance."""

from __future__ import annotations

import numpy as np
import pytest
from OCP.BRep import BRep_Builder, BRep_Tool
from OCP.BRepTools import BRepTools
from OCP.gp import gp_Vec2d
from OCP.TopAbs import TopAbs_FACE, TopAbs_FORWARD
from OCP.TopoDS import TopoDS

from amprep.geometry.cad import read
from amprep.geometry.cad.pcurve_shifts import fix_shifted_pcurves
from amprep.geometry.cad.topology import explore, face_edges
from amprep.geometry.core.checks import check_mesh
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.pipeline import mesh_model
from tests.conftest import corpus
from tests.geometry.test_independent_distance import _worst_distance


def _cylinder_with_moved_pcurves(seam, top: gp_Vec2d):  # type: ignore[no-untyped-def]
    """A cylinder r 5, h 10 and its side face, whose seam's two pcurves c1, c2 (edge range starting at a) are replaced
    by seam(c1, c2, a) and whose top circle's pcurve is moved by `top`."""
    import cadquery as cq

    solid = cq.Solid.makeCylinder(5, 10).wrapped
    face = next(f for f in explore(solid, TopAbs_FACE, TopoDS.Face_s) if BRep_Tool.Surface_s(f).IsUPeriodic())
    builder = BRep_Builder()
    for e in face_edges(face):
        a, b = BRep_Tool.Range_s(e)
        if BRep_Tool.IsClosed_s(e, face):
            if e.Orientation() == TopAbs_FORWARD:
                c1 = BRep_Tool.CurveOnSurface_s(e, face, a, b)
                c2 = BRep_Tool.CurveOnSurface_s(TopoDS.Edge_s(e.Reversed()), face, a, b)
                builder.UpdateEdge(e, *seam(c1, c2, a), face, BRep_Tool.Tolerance_s(e))
        elif abs(BRep_Tool.CurveOnSurface_s(e, face, a, b).Value(a).Y() - 10) < 1e-9:  # the top circle
            builder.UpdateEdge(e, BRep_Tool.CurveOnSurface_s(e, face, a, b).Translated(top), face,
                               BRep_Tool.Tolerance_s(e))
    return solid, face


def _shifted_cylinder(path) -> None:  # type: ignore[no-untyped-def]
    shift = gp_Vec2d(-2 * np.pi, 0)
    solid, _ = _cylinder_with_moved_pcurves(lambda c1, c2, a: (c1, c2.Translated(shift)), shift)
    BRepTools.Write_s(solid, str(path))


@pytest.mark.parametrize("mesher", ["occt", "quality"])
def test_a_loop_open_by_a_period_is_closed_on_reading(tmp_path, monkeypatch, mesher):
    import cadquery as cq

    _shifted_cylinder(tmp_path / "shifted.brep")
    model = read.read_cad(tmp_path / "shifted.brep")
    assert any("a period apart" in n for n in model.notes)
    r = mesh_model(model, MeshParams(tolerance=0.01, mesher=mesher))
    checks = check_mesh(r.mesh)
    assert checks.closed and r.unmeshed_faces == ()
    assert _worst_distance(model, r.mesh, samples=300) <= 0.01 * 1.001
    BRepTools.Write_s(cq.Solid.makeCylinder(5, 10).wrapped, str(tmp_path / "sound.brep"))
    sound = mesh_model(read.read_cad(tmp_path / "sound.brep"), MeshParams(tolerance=0.01, mesher=mesher))
    assert r.mesh.n_triangles == sound.mesh.n_triangles

    monkeypatch.setattr(read, "fix_shifted_pcurves", lambda shape: 0)  # as read before: open, or far off the surface
    r = mesh_model(read.read_cad(tmp_path / "shifted.brep"), MeshParams(tolerance=0.01, mesher=mesher))
    assert not check_mesh(r.mesh).closed or _worst_distance(model, r.mesh, samples=300) > 0.1


def test_sound_parts_are_left_as_they_are():
    """No wire of the corpus's periodic faces is open by a period: nothing is moved (one circle of a cylinder, whose
    start and end differ by a period, is a closed loop, not a shifted one)."""
    for name in ("nist_ctc02_ap242.stp", "occt_top_invalid.brep", "voron_hotend_mount_dragon.step"):
        shape, _ = read.read_shape(corpus(name), name.rsplit(".", 1)[1].replace("stp", "step"))
        assert fix_shifted_pcurves(shape) == 0, name


def _torus_with_a_seam_off(path, off: float) -> None:  # type: ignore[no-untyped-def]
    """A quarter torus whose seam's two pcurves are moved `off` along u, off its circles' ends by more than the
    vertices' tolerance in (u,v) (KiCad's Fastron inductor lead: 1e-5 on a torus of radii 0.45)."""
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeTorus

    solid = BRepPrimAPI_MakeTorus(20, 5, np.pi / 2).Shape()
    face = next(f for f in explore(solid, TopAbs_FACE, TopoDS.Face_s) if BRep_Tool.Surface_s(f).IsVPeriodic())
    for e in face_edges(face):
        if BRep_Tool.IsClosed_s(e, face) and e.Orientation() == TopAbs_FORWARD:
            a, b = BRep_Tool.Range_s(e)
            c1 = BRep_Tool.CurveOnSurface_s(e, face, a, b)
            c2 = BRep_Tool.CurveOnSurface_s(TopoDS.Edge_s(e.Reversed()), face, a, b)
            BRep_Builder().UpdateEdge(e, c1.Translated(gp_Vec2d(off, 0)), c2.Translated(gp_Vec2d(off, 0)), face,
                                      BRep_Tool.Tolerance_s(e))
    BRepTools.Write_s(solid, str(path))


def _explorer_edges(face, wire):  # type: ignore[no-untyped-def]
    from OCP.BRepTools import BRepTools_WireExplorer

    found, wexp = [], BRepTools_WireExplorer(wire, face)
    while wexp.More():
        found.append(TopoDS.Edge_s(wexp.Current()))
        wexp.Next()
    return found


@pytest.mark.parametrize("mesher", ["occt", "quality"])
def test_a_wire_occts_explorer_stops_in_is_walked_whole(tmp_path, monkeypatch, mesher):
    """OCCT's wire explorer takes a seam 1e-5 off in (u,v) as the end of the wire (one edge of four): every face is
    still meshed from its whole loop, closed and within tolerance by OCCT's distance; with the explorer alone the
    face's loop is one edge and the mesh is open."""
    from OCP.TopAbs import TopAbs_EDGE, TopAbs_WIRE

    from amprep.geometry.meshing import face_mesher

    _torus_with_a_seam_off(tmp_path / "torus.brep", 1e-5)
    model = read.read_cad(tmp_path / "torus.brep")
    torus = next(f for f in model.faces if BRep_Tool.Surface_s(f).IsVPeriodic())
    wire = explore(torus, TopAbs_WIRE, TopoDS.Wire_s)[0]
    assert len(_explorer_edges(torus, wire)) < len(explore(wire, TopAbs_EDGE, TopoDS.Edge_s)) == 4
    # with the default mesher, a tolerance OCCT's own mesh of the torus misses: the face is meshed again by ours
    params = MeshParams(tolerance=0.01 if mesher == "quality" else 0.002, mesher=mesher)
    r = mesh_model(model, params)
    assert model.faces.index(torus) in r.fallback_faces
    assert check_mesh(r.mesh).closed and r.unmeshed_faces == ()
    assert _worst_distance(model, r.mesh, samples=300) <= params.tolerance * 1.001

    monkeypatch.setattr(face_mesher, "wire_edges", _explorer_edges)
    r = mesh_model(read.read_cad(tmp_path / "torus.brep"), params)
    assert not check_mesh(r.mesh).closed or r.unmeshed_faces != ()


def _cylinder_closed_by_false_degenerates(path) -> None:  # type: ignore[no-untyped-def]
    """The cylinder's lateral face spanning 2 periods in (u,v), its loop closed as STEP healing closed KiCad's
    transformer's: the seam's up pcurve and the top circle's moved a period on, two edges flagged degenerated (each at
    a seam vertex, each one period along a circle) joining them."""
    from OCP.Geom2d import Geom2d_Line
    from OCP.gp import gp_Dir2d, gp_Pnt2d
    from OCP.TopAbs import TopAbs_REVERSED, TopAbs_WIRE
    from OCP.TopExp import TopExp
    from OCP.TopoDS import TopoDS_Edge

    builder, period = BRep_Builder(), 2 * np.pi
    shift = gp_Vec2d(period, 0)

    def up_a_period(c1, c2, a):  # type: ignore[no-untyped-def]  # the seam's pcurve at u = 2π moves to 4π
        return (c1.Translated(shift), c2) if c1.Value(a).X() > 1 else (c1, c2.Translated(shift))

    solid, face = _cylinder_with_moved_pcurves(up_a_period, shift)
    seam = next(e for e in face_edges(face) if BRep_Tool.IsClosed_s(e, face))
    wire = explore(face, TopAbs_WIRE, TopoDS.Wire_s)[0]
    wire.Free(True)
    for v, start, direction in ((0.0, period, 1.0), (10.0, period, -1.0)):
        vertex = next(x for x in (TopExp.FirstVertex_s(seam), TopExp.LastVertex_s(seam))
                      if abs(BRep_Tool.Pnt_s(x).Z() - v) < 1e-9)
        edge = TopoDS_Edge()
        builder.MakeEdge(edge)
        builder.UpdateEdge(edge, Geom2d_Line(gp_Pnt2d(start, v), gp_Dir2d(direction, 0)), face, 1e-7)
        builder.Range(edge, face, 0.0, period)
        builder.Degenerated(edge, True)
        builder.Add(edge, vertex.Oriented(TopAbs_FORWARD))
        builder.Add(edge, vertex.Oriented(TopAbs_REVERSED))
        builder.Add(wire, edge)
    BRepTools.Write_s(solid, str(path))


def _face_area(mesh, face_id: int) -> float:  # type: ignore[no-untyped-def]
    c = mesh.corners[mesh.face_ids == face_id]
    return float(0.5 * np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1).sum())


@pytest.mark.parametrize("mesher", ["occt", "quality"])
def test_a_loop_closed_by_false_degenerated_edges_is_one_period(tmp_path, monkeypatch, mesher):
    _cylinder_closed_by_false_degenerates(tmp_path / "wound.brep")
    model = read.read_cad(tmp_path / "wound.brep")
    side = next(i for i, f in enumerate(model.faces) if BRep_Tool.Surface_s(f).IsUPeriodic())
    r = mesh_model(model, MeshParams(tolerance=0.01, mesher=mesher))
    assert check_mesh(r.mesh).closed and r.unmeshed_faces == ()
    assert _face_area(r.mesh, side) == pytest.approx(2 * np.pi * 5 * 10, rel=2e-3)  # once round, not twice
    assert _worst_distance(model, r.mesh, samples=300) <= 0.01 * 1.001

    monkeypatch.setattr(read, "fix_shifted_pcurves", lambda shape: 0)  # as read before: the band meshed twice over
    r = mesh_model(read.read_cad(tmp_path / "wound.brep"), MeshParams(tolerance=0.01, mesher=mesher))
    assert _face_area(r.mesh, side) > 1.5 * 2 * np.pi * 5 * 10 or not check_mesh(r.mesh).closed
