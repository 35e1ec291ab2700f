import numpy as np
import pytest

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.cad.read import model_from_shape
from amprep.geometry.core.checks import check_mesh
from amprep.geometry.io.stl import read_stl, stl_bytes, write_stl
from amprep.geometry.io.threemf import read_3mf_objects, write_3mf
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.pipeline import mesh_model
from tests.conftest import STL_FILES, corpus


@pytest.fixture(scope="module")
def torus_mesh(reference_solids):
    return mesh_model(model_from_shape(reference_solids["torus"]), MeshParams(tolerance=0.05)).mesh


@pytest.mark.parametrize("ascii", [False, True])
def test_stl_round_trip_keeps_topology(torus_mesh, tmp_path, ascii):
    p = tmp_path / "t.stl"
    write_stl(torus_mesh, p, ascii=ascii, header="amprep test")
    back = read_stl(p)
    assert back.n_triangles == torus_mesh.n_triangles
    assert check_mesh(back).closed  # distinct vertices stay distinct in float32 / %.9e
    tol = 1e-5 * 25 if not ascii else 1e-7 * 25  # binary STL is float32
    np.testing.assert_allclose(back.vertices[back.triangles], torus_mesh.corners, atol=tol)


def test_binary_header_never_starts_with_solid(torus_mesh):
    assert not stl_bytes(torus_mesh, header="solid trouble")[:5].lower() == b"solid"


@pytest.mark.parametrize("name", STL_FILES)
def test_corpus_stl_reads(name):
    """Vertices are the file's distinct coordinate triples, in sorted order, as np.unique(axis=0) finds them."""
    m = read_stl(corpus(name))
    assert m.n_triangles > 0 and np.isfinite(m.vertices).all()
    raw = corpus(name).read_bytes()
    if 84 + 50 * int(np.frombuffer(raw, "<u4", 1, 80)[0]) == len(raw):
        corners = np.frombuffer(raw, np.dtype([("n", "<f4", 3), ("c", "<f4", (3, 3)), ("a", "<u2")]), offset=84)["c"]
        verts, inverse = np.unique(corners.reshape(-1, 3).astype(np.float64), axis=0, return_inverse=True)
        np.testing.assert_array_equal(m.vertices, verts)
        np.testing.assert_array_equal(m.triangles, inverse.reshape(-1, 3))


def test_stl_vertices_join_identical_coordinates_only(tmp_path):
    """Two facets share a vertex only where their coordinates are equal (−0.0 equals 0.0), never by distance: a
    corner one float32 step away stays its own vertex."""
    step = float(np.nextafter(np.float32(1), np.float32(2)))
    corners = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[-0.0, 0, 0], [0, 1, 0], [0, 0, 1]],
                        [[step, 0, 0], [0, 0, 1], [0, 1, 0]]], float)
    p = tmp_path / "s.stl"
    p.write_bytes(b"\0" * 80 + np.uint32(3).tobytes() + np.array(
        [(np.zeros(3), c, 0) for c in corners],
        dtype=np.dtype([("n", "<f4", 3), ("c", "<f4", (3, 3)), ("a", "<u2")])).tobytes())
    m = read_stl(p)
    assert m.n_vertices == 5
    t = m.triangles
    assert t[0, 0] == t[1, 0] and t[2, 0] not in (t[0, 1], t[0, 0])
    np.testing.assert_array_equal(m.vertices[t], corners)


def test_corpus_stl_defects_are_counted():
    assert check_mesh(read_stl(corpus("voron_rear_skirt_nonmanifold.stl"))).nonmanifold_edges == 6083
    assert check_mesh(read_stl(corpus("triangle_soup.stl"))).boundary_edges == 300
    assert check_mesh(read_stl(corpus("voron_vhb_din_mount.stl"))).closed


def test_truncated_stl_is_a_clean_error(tmp_path):
    p = tmp_path / "bad.stl"
    p.write_bytes(b"solid x\nfacet normal 0 0 1\n outer loop\n vertex 0 0 nope\n")
    with pytest.raises(AmprepError) as err:
        read_stl(p)
    assert err.value.code in (ErrorCode.UNREADABLE_MESH, ErrorCode.EMPTY_MODEL)


def test_3mf_objects_closed_with_face_ids(tmp_path, reference_solids):
    import cadquery as cq
    import lib3mf
    two = cq.Compound.makeCompound([cq.Shape.cast(reference_solids["torus"]),
                                    cq.Shape.cast(reference_solids["cylinder"]).translate(cq.Vector(60, 0, 0))])
    mesh = mesh_model(model_from_shape(two.wrapped), MeshParams(tolerance=0.05)).mesh
    p = tmp_path / "two.3mf"
    verdicts = write_3mf(mesh, p, {"generator": "amprep test"})
    assert verdicts == [True, True]
    objects = read_3mf_objects(p)
    assert len(objects) == 2 and all(o[3] for o in objects)
    assert sum(len(o[2]) for o in objects) == mesh.n_triangles
    model = lib3mf.get_wrapper().CreateModel()
    model.QueryReader("3mf").ReadFromFile(str(p))
    assert model.GetUnit() == lib3mf.ModelUnit.MilliMeter
    it = model.GetMeshObjects()
    sets = 0
    while it.MoveNext():
        sets += it.GetCurrentMeshObject().GetTriangleSetCount()
    assert sets == len(mesh.faces)  # one triangle set per CAD face


def test_3mf_write_and_read_leave_the_process_locale_as_they_found_it(torus_mesh, tmp_path):
    """lib3mf sets every locale category to "C": a worker's later jobs would open text files as ASCII."""
    import locale
    saved = locale.setlocale(locale.LC_ALL)
    try:
        locale.setlocale(locale.LC_ALL, "C.UTF-8")  # not "C", whatever the machine's own, so a change shows
        before = locale.setlocale(locale.LC_ALL)
        write_3mf(torus_mesh, tmp_path / "t.3mf")
        assert locale.setlocale(locale.LC_ALL) == before
        read_3mf_objects(tmp_path / "t.3mf")
        assert locale.setlocale(locale.LC_ALL) == before
        assert locale.getpreferredencoding(False).lower().replace("-", "") == "utf8"
    finally:
        locale.setlocale(locale.LC_ALL, saved)
