import numpy as np
import pytest

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.cad.read import read_cad
from amprep.geometry.meshing.pipeline import bbox_diagonal
from tests.conftest import corpus


def _extent(model):
    from OCP.Bnd import Bnd_Box
    from OCP.BRepBndLib import BRepBndLib

    box = Bnd_Box()
    BRepBndLib.AddOptimal_s(model.shape, box, False, False)
    x0, y0, z0, x1, y1, z1 = box.Get()
    return np.array([x1 - x0, y1 - y0, z1 - z0])


def test_inch_step_is_read_in_mm():
    m = read_cad(corpus("featuretype_inch_ap214.step"))
    assert m.units == "inch"
    np.testing.assert_allclose(_extent(m), [127, 63.5, 34.925], atol=0.01)


def test_metre_conversion_unit_reads_as_25_mm_not_25_m():
    m = read_cad(corpus("cq_cube_cylinder_colors.step"))
    assert m.solids == 2
    np.testing.assert_allclose(_extent(m), [25, 10, 10], atol=0.01)


def test_assembly_keeps_every_solid():
    m = read_cad(corpus("as1_assembly_ap214.stp"))
    assert m.solids == 18 and len(m.faces) == 160
    assert all(s >= 0 for s in m.face_solid)


def test_brep_declares_no_unit():
    m = read_cad(corpus("occt_top_invalid.brep"))
    assert m.units == "none" and len(m.faces) == 324


def test_open_iges_is_sewn_not_rejected():
    m = read_cad(corpus("sunglasses_lens_inch.igs"))
    assert m.units == "inch" and m.solids == 0 and m.sewn
    assert bbox_diagonal(m) > 25  # inches became mm


@pytest.mark.parametrize("content,code", [
    (b"ISO-10303-21;\nHEADER;\nthis is broken\n", ErrorCode.UNREADABLE_CAD),
    (b"DBRep_DrawableShape\n\ngarbage garbage\n", ErrorCode.UNREADABLE_CAD),
])
def test_corrupt_cad_has_a_stable_code(tmp_path, content, code):
    p = tmp_path / "bad.step"
    p.write_bytes(content)
    with pytest.raises(AmprepError) as err:
        read_cad(p)
    assert err.value.code in (code, ErrorCode.EMPTY_MODEL)


def test_reading_iges_prints_nothing_and_keeps_occt_printers(capfd):
    from OCP.IGESControl import IGESControl_Reader
    from OCP.Message import Message, Message_PrinterOStream

    messenger = Message.DefaultMessenger_s()
    added = Message_PrinterOStream()
    messenger.AddPrinter(added)  # a printer to stdout, whatever earlier tests did to the default messenger
    try:
        IGESControl_Reader().ReadFile(str(corpus("bspline_45_faces.iges")))  # control: OCCT's reader prints
        assert "loaded entities" in capfd.readouterr().out
        m = read_cad(corpus("bspline_45_faces.iges"))
        assert len(m.faces) == 45
        assert capfd.readouterr().out == ""
        printers = messenger.Printers()
        assert any(printers.Value(i) is added or printers.Value(i) == added for i in range(1, printers.Length() + 1))
    finally:
        messenger.RemovePrinter(added)


def _one_shell_per_face(solid):
    """A compound of open shells, one per face of `solid`, each face a copy with its own edges (as some STEP surface
    models store a part: nothing shared, every edge free)."""
    from OCP.BRep import BRep_Builder
    from OCP.BRepBuilderAPI import BRepBuilderAPI_Copy
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopoDS import TopoDS, TopoDS_Compound, TopoDS_Shell

    from amprep.geometry.cad.topology import explore

    b = BRep_Builder()
    comp = TopoDS_Compound()
    b.MakeCompound(comp)
    for face in explore(solid, TopAbs_FACE, TopoDS.Face_s):
        shell = TopoDS_Shell()
        b.MakeShell(shell)
        b.Add(shell, TopoDS.Face_s(BRepBuilderAPI_Copy(face).Shape()))
        b.Add(comp, shell)
    return comp


def _write_step(shape, path):
    from OCP.STEPControl import STEPControl_AsIs, STEPControl_Writer

    w = STEPControl_Writer()
    w.Transfer(shape, STEPControl_AsIs)
    w.Write(str(path))
    return path


def test_step_surface_model_with_a_shell_per_face_is_sewn_closed(tmp_path):
    """A block with a through hole stored as 10 one-face shells (a real IDF part library's SOT23.stp is such a file,
    its IGES twin loose faces): the faces outside solids are sewn, as IGES faces are, and the part meshes closed."""
    import cadquery as cq
    from OCP.TopAbs import TopAbs_SHELL

    from amprep.geometry.cad.read import _indexed, free_edge_count, read_shape
    from amprep.geometry.core.checks import check_mesh, manifold3d_accepts
    from amprep.geometry.meshing.params import MeshParams
    from amprep.geometry.meshing.pipeline import mesh_model

    block = cq.Workplane("XY").box(20, 12, 6).faces(">Z").workplane().hole(5).val().wrapped
    path = _write_step(_one_shell_per_face(block), tmp_path / "shells.step")
    raw, _ = read_shape(path, "step")
    assert _indexed(raw, TopAbs_SHELL).Extent() == 7 and free_edge_count(raw) > 0  # the control: all apart as stored
    m = read_cad(path)
    assert m.sewn and m.solids == 0 and len(m.faces) == 7 and free_edge_count(m.shape) == 0
    r = mesh_model(m, MeshParams(tolerance=0.05))
    c = check_mesh(r.mesh)
    assert c.closed and c.boundary_edges == 0 and manifold3d_accepts(r.mesh) and r.max_error <= 0.05


def test_loose_faces_are_sewn_and_solids_beside_them_kept(tmp_path):
    """A solid and, beside it, a surface model (one-face shells): the loose faces are sewn among themselves, the
    solid is kept as it is; two solids alone (an assembly) are never sewn."""
    import cadquery as cq
    from OCP.BRep import BRep_Builder
    from OCP.TopoDS import TopoDS_Compound

    from amprep.geometry.cad.read import free_edge_count

    solid = cq.Workplane("XY").box(10, 10, 10).val().wrapped
    loose = _one_shell_per_face(cq.Workplane("XY").cylinder(8, 3).translate((30, 0, 0)).val().wrapped)
    b = BRep_Builder()
    comp = TopoDS_Compound()
    b.MakeCompound(comp)
    b.Add(comp, solid)
    b.Add(comp, loose)
    m = read_cad(_write_step(comp, tmp_path / "mixed.step"))
    assert m.sewn and m.solids == 1 and len(m.faces) == 9 and free_edge_count(m.shape) == 0
    assert sum(s == 0 for s in m.face_solid) == 6
    assert not read_cad(corpus("as1_assembly_ap214.stp")).sewn


def test_only_occt_failures_become_unreadable_cad(monkeypatch):
    """OCCT's exceptions (OCP's classes, pybind11's RuntimeError) become unreadable_cad; anything else raised while
    a file is read — a job's soft time limit arrives as an exception at the first Python line after OCCT returns —
    passes unchanged (it was reported as unreadable_cad, and the job failed with the wrong code)."""
    from OCP.gp import gp_Dir

    from amprep.errors import is_occt_failure
    from amprep.geometry.cad import read as cad

    with pytest.raises(Exception) as occt:
        gp_Dir(0, 0, 0)
    assert is_occt_failure(occt.value) and is_occt_failure(RuntimeError("c++"))

    class TimeLimit(Exception):
        pass

    assert not is_occt_failure(TimeLimit()) and not is_occt_failure(ValueError())

    def interrupted(path):
        raise TimeLimit()

    monkeypatch.setattr(cad, "_read_step", interrupted)
    with pytest.raises(TimeLimit):
        cad.read_shape(corpus("cq_cube_cylinder_colors.step"), "step")

    def occt_fails(path):
        gp_Dir(0, 0, 0)

    monkeypatch.setattr(cad, "_read_step", occt_fails)
    with pytest.raises(AmprepError) as err:
        cad.read_shape(corpus("cq_cube_cylinder_colors.step"), "step")
    assert err.value.code == ErrorCode.UNREADABLE_CAD
