import numpy as np
import pytest

from amprep.geometry.cad import read_cad
from amprep.geometry.errors import AmprepError, ErrorCode
from amprep.geometry.mesher import bbox_diagonal
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
