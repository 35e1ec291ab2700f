"""Instances of one part placed by translations, rotations, mirrors, nested locations and a scaling location: every
instance closed, pointing outward, of the part's own volume (OCCT's mass properties of the part, scaled), and
within the tolerance by OCCT's BRepExtrema in the output's coordinates; in memory, through a BREP file (the CLI's
forked read) and through a STEP assembly in metres."""

from __future__ import annotations

import numpy as np
import pytest
from OCP.BRep import BRep_Builder
from OCP.BRepGProp import BRepGProp
from OCP.BRepTools import BRepTools
from OCP.gp import gp_Ax1, gp_Ax2, gp_Dir, gp_Pnt, gp_Trsf, gp_Vec
from OCP.GProp import GProp_GProps
from OCP.Interface import Interface_Static
from OCP.STEPControl import STEPControl_AsIs, STEPControl_Writer
from OCP.TopLoc import TopLoc_Location
from OCP.TopoDS import TopoDS_Compound

from amprep.geometry.cad.read import model_from_shape, read_cad
from amprep.geometry.core.checks import check_mesh, shell_labels, signed_volume
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.pipeline import mesh_file, mesh_model
from tests.geometry.test_independent_distance import _worst_distance


def _part():
    """A plate with rounded corners, a hole and a lofted B-spline boss: planes, cylinders, B-splines."""
    import cadquery as cq

    loft = (cq.Workplane("XY").circle(8).workplane(offset=10).rect(10, 6).workplane(offset=10).circle(5)
            .loft(combine=True))
    return (cq.Workplane().box(30, 20, 6).edges("|Z").fillet(3).faces(">Z").workplane().hole(5)
            .union(loft.translate((0, 0, 3)))).val().wrapped


def _moved(dx=0.0, dy=0.0, dz=0.0, axis=None, angle=0.0, mirror=None, scale=1.0) -> gp_Trsf:
    t = gp_Trsf()
    if scale != 1.0:
        t.SetScale(gp_Pnt(0, 0, 0), scale)
    if axis is not None:
        r = gp_Trsf()
        r.SetRotation(gp_Ax1(gp_Pnt(0, 0, 0), gp_Dir(*axis)), angle)
        t = r.Multiplied(t)
    if mirror is not None:
        m = gp_Trsf()
        m.SetMirror(gp_Ax2(gp_Pnt(*mirror[0]), gp_Dir(*mirror[1])))
        t = m.Multiplied(t)
    move = gp_Trsf()
    move.SetTranslation(gp_Vec(dx, dy, dz))
    return move.Multiplied(t)


def _compound(shapes):
    b, c = BRep_Builder(), TopoDS_Compound()
    b.MakeCompound(c)
    for s in shapes:
        b.Add(c, s)
    return c


def _assembly(part, scaled: bool):
    """(compound, scale³ of each instance): the part as is, moved, rotated, mirrored, a sub-assembly (itself placed)
    holding a mirrored and rotated instance, and optionally one scaled ×2 (a STEP file cannot say that)."""
    placed = [gp_Trsf(), _moved(dx=60), _moved(dy=70, dz=5, axis=(1, 1, 0.3), angle=0.61),
              _moved(mirror=((-40, 0, 0), (1, 0.2, 0)))]
    inner = part.Located(TopLoc_Location(_moved(axis=(0, 0, 1), angle=1.1, mirror=((0, 0, 0), (0, 1, 0)))), False)
    sub = _compound([inner]).Located(TopLoc_Location(_moved(dx=-50, dy=-60, axis=(0, 1, 0), angle=0.4)), False)
    shapes = [part.Located(TopLoc_Location(t), False) for t in placed] + [sub]
    factors = [1.0] * len(shapes)
    if scaled:
        shapes.append(part.Located(TopLoc_Location(_moved(dx=120, scale=2.0)), False))
        factors.append(8.0)
    return _compound(shapes), factors


def _volume(shape) -> float:
    props = GProp_GProps()
    BRepGProp.VolumeProperties_s(shape, props)
    return props.Mass()


def _model(how: str, tmp_path):
    part = _part()
    shape, factors = _assembly(part, scaled=how != "step")
    if how == "memory":
        return model_from_shape(shape), factors, _volume(part), None
    if how == "brep":
        path = tmp_path / "assembly.brep"
        BRepTools.Write_s(shape, str(path))
        return None, factors, _volume(part), path
    Interface_Static.SetCVal_s("write.step.unit", "M")
    Interface_Static.SetIVal_s("write.step.assembly", 1)
    writer = STEPControl_Writer()
    writer.Transfer(shape, STEPControl_AsIs)
    path = tmp_path / "assembly.step"
    writer.Write(str(path))
    Interface_Static.SetCVal_s("write.step.unit", "MM")
    return read_cad(path), factors, _volume(part), None


@pytest.mark.parametrize("tol", [0.1, 0.01])
@pytest.mark.parametrize("how", ["memory", "brep", "step"])
def test_instances_closed_outward_and_within_tolerance(tmp_path, how, tol):
    model, factors, part_volume, path = _model(how, tmp_path)
    if path is not None:
        model, result = mesh_file(path, "brep", MeshParams(tolerance=tol))
    else:
        result = mesh_model(model, MeshParams(tolerance=tol))
    mesh = result.mesh
    checks = check_mesh(mesh)
    assert checks.closed and checks.inside_out_shells == 0
    n, labels = shell_labels(mesh)
    volumes = sorted(signed_volume(mesh.corners[labels == s]) for s in range(n))
    expected = sorted(part_volume * f for f in factors)
    assert n == len(factors)
    # a closed mesh within t of its surface holds the volume to about area × t
    assert np.allclose(volumes, expected, rtol=0.02)
    assert _worst_distance(model, mesh, samples=500) <= tol * 1.001
    assert result.max_error <= tol * 1.001


def test_instances_meshed_once_or_each_give_the_same_solids(tmp_path):
    """The placed template (instances.py) against meshing every instance: both closed, outward, every solid's
    volume the same to the tolerance's share."""
    model, factors, part_volume, _ = _model("memory", tmp_path)
    out = []
    for once in (True, False):
        mesh = mesh_model(model, MeshParams(tolerance=0.05, mesh_instances_once=once)).mesh
        checks = check_mesh(mesh)
        assert checks.closed and checks.inside_out_shells == 0
        n, labels = shell_labels(mesh)
        out.append(sorted(signed_volume(mesh.corners[labels == s]) for s in range(n)))
    assert np.allclose(out[0], out[1], rtol=2e-3)


def _boxes(levels: int):
    """2**levels unit boxes: one box placed by nested compounds of two, each level a translation along x, y or z."""
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox

    shape = BRepPrimAPI_MakeBox(1, 1, 1).Shape()
    for level in range(levels):
        step = [0.0, 0.0, 0.0]
        step[level % 3] = 2.0 ** (level // 3 + 1)
        shape = _compound([shape, shape.Moved(TopLoc_Location(_moved(*step)), False)])
    return shape


def test_many_placed_boxes_are_meshed_once_and_placed(tmp_path):
    """1,024 placed boxes from a BREP of a few KB (the CLI's path): one box meshed, 1,024 closed unit cubes out,
    every face id and solid that of the whole assembly."""
    from amprep.geometry.cad.instances import find_instancing

    path = tmp_path / "boxes.brep"
    BRepTools.Write_s(_boxes(10), str(path))
    assert path.stat().st_size < 10_000
    model, result = mesh_file(path, "brep", MeshParams(tolerance=0.1))
    inst = find_instancing(model)
    assert inst is not None and len(inst.template.faces) == 6 and len(model.faces) == 6 * 1024
    mesh = result.mesh
    checks = check_mesh(mesh)
    assert checks.closed and checks.triangles == 12 * 1024 and checks.inside_out_shells == 0
    n, labels = shell_labels(mesh)
    assert n == 1024
    assert np.allclose([signed_volume(mesh.corners[labels == s]) for s in range(n)], 1.0)
    # each face's triangles lie on that face of the assembly, by OCCT
    assert _worst_distance(model, mesh, samples=300) < 1e-9
    assert sorted(set(mesh.face_ids.tolist())) == list(range(6 * 1024))
    solid_of_tri = np.array(model.face_solid)[mesh.face_ids]
    assert all(len(set(solid_of_tri[labels == s].tolist())) == 1 for s in range(0, n, 97))
