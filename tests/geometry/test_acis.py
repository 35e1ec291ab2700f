"""ACIS input (SAT, SAB, DXF 3DSOLID): every corpus file converts through the STEP pipeline, closed where it is a
solid, its volume equal to one computed another way (closed forms from the dimensions in the file, ezdxf's own
reading of a polyhedron, the polygon of a prism's cap); producer and version layouts the corpus lacks are forced by
rewriting corpus files, and the B-spline curve and surface records by a file written here."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.cad.read import read_cad
from amprep.geometry.core.edges import edge_incidence
from amprep.geometry.core.formats import sniff_path
from amprep.geometry.meshing.params import MeshParams
from amprep.jobs.convert import convert
from tests.conftest import corpus

SAT = "sat/"


def _volume(mesh) -> float:
    v, t = mesh.vertices, mesh.triangles
    return float(np.einsum("ij,ij->i", v[t[:, 0]], np.cross(v[t[:, 1]], v[t[:, 2]])).sum() / 6)


def _area(mesh) -> float:
    v, t = mesh.vertices, mesh.triangles
    return float(np.linalg.norm(np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]]), axis=1).sum() / 2)


def _ezdxf_polyhedron_volume(path: Path) -> float:
    """Volume of a flat-faced ACIS body as ezdxf (an independent reader) meshes it: Σ fan triangles' det / 6."""
    from ezdxf.acis import api as acis

    data = path.read_bytes()
    total = 0.0
    for body in acis.load(data if data.startswith(b"ACIS BinaryFile") else data.decode()):
        for m in acis.mesh_from_body(body):
            v = np.asarray(m.vertices, float)
            for f in m.faces:
                for k in range(1, len(f) - 1):
                    total += float(np.dot(v[f[0]], np.cross(v[f[k]], v[f[k + 1]]))) / 6
    return total


def _wall_volume(path: Path) -> float:
    """AutoCAD's 3DSOLID: a 4-high wall round a triangle; its cap is the outer triangle less the inner one, both
    read from the file's point records by a regular expression."""
    pts = np.array([[float(x) for x in m.split()]
                    for m in re.findall(r"^point \$-1 ([^#]*)#", path.read_text(), re.M)])
    top = pts[pts[:, 2] > 2][:, :2]
    hull = ConvexHull(top)
    inner = np.delete(top, hull.vertices, axis=0)
    return 4.0 * (hull.volume - ConvexHull(inner).volume)


def _rounded_cube_with_cavity() -> float:
    """Cubit's testgeom: a 10 mm cube, edges and corners rounded r = 0.2, a spherical cavity R = 3 opened to each
    face by a hole r = 1 (2√2 from the centre to where the hole meets the sphere)."""
    a, r = 9.6, 0.2
    box = a**3 + 6 * a * a * r + 3 * math.pi * r * r * a + 4 / 3 * math.pi * r**3
    cap_h = 3 - 2 * math.sqrt(2)
    cavity = 4 / 3 * math.pi * 27 - 6 * math.pi * cap_h**2 * (9 - cap_h) / 3
    return box - cavity - 6 * math.pi * (5 - 2 * math.sqrt(2))


def _three_hole_cube() -> float:
    """MeshKit's unit cube with three orthogonal through holes r = 0.1: inclusion–exclusion with the Steinmetz
    solids (two cylinders 16r³/3, three 8(2 − √2)r³)."""
    r = 0.1
    return 1 - (3 * math.pi * r * r - 3 * 16 / 3 * r**3 + 8 * (2 - math.sqrt(2)) * r**3)


#: name → (tolerance mm, expected volume or a function of the path computing it another way)
SOLIDS = {
    "acad_example_2000_3DSOLID_v400.sat": (0.01, _wall_volume),
    "acad_example_2013_3DSOLID_acis_binary.sab": (0.01, lambda p: _wall_volume(corpus(SAT + "acad_example_2000_3DSOLID_v400.sat"))),
    "cgma_testgeom_v1600_cubit.sat": (0.002, lambda p: _rounded_cube_with_cavity()),
    "dagmc_sample01_v1900_cubit.sat": (0.005, lambda p: 4 / 3 * math.pi * 20**3 + 55**3 - 50**3),  # a ball, a hollow box
    "ezdxf_prism_v700_oda.sat": (0.01, _ezdxf_polyhedron_volume),
    "meshkit_threeholecube_v1600_cubit.sat": (0.0005, lambda p: _three_hole_cube()),
    "oda_3dsolids_A5_cyl_v700.sat": (0.002, lambda p: 1000 - math.pi * 25 * 5 / 4),  # a cube less a quarter cylinder
}


@pytest.mark.parametrize("mesher", ["occt", "quality"])
@pytest.mark.parametrize("name", sorted(SOLIDS))
def test_corpus_acis_solid_is_closed_with_the_volume_computed_another_way(name, mesher):
    path = corpus(SAT + name)
    tol, expected = SOLIDS[name]
    r = convert(path, MeshParams(tolerance=tol, mesher=mesher))
    assert r.checks.closed, r.notes
    assert r.meshing.max_error <= tol * (1 + 1e-9)
    exact = expected(path)
    # each triangle lies within tol of its face: the volume is within area × tol of the exact one
    assert abs(_volume(r.mesh) - exact) <= _area(r.mesh) * tol, (_volume(r.mesh), exact)
    assert r.input["format"] == path.suffix[1:] and r.input["unsupported_geometry"] == []


@pytest.mark.parametrize("name,sheets", [("acad_2004_Surface_LOFTED_v20800.sat", 1),
                                         ("acad_2004_Surface_REVOLVED_v20800.sat", 1),
                                         ("libredwg_example_2013.dxf", 2)])
def test_acis_sheets_convert_open_and_say_so(name, sheets):
    results = [convert(corpus(SAT + name), MeshParams(tolerance=0.05, mesher=m)) for m in ("occt", "quality")]
    for r in results:
        assert not r.checks.closed and r.checks.boundary_edges > 0
        assert any(f"{sheets} ACIS body part(s) are open sheets" in n for n in r.notes), r.notes
        assert r.meshing.max_error <= 0.05 * (1 + 1e-9)
    # the open edges are the sheets' own free edges, cut differently: as long in both meshes (a crack between two
    # faces would add its length twice), each within the tolerance of its curve
    lengths = [_open_length(r.mesh) for r in results]
    assert lengths[1] == pytest.approx(lengths[0], rel=1e-3), lengths


def _open_length(mesh) -> float:
    """Σ the lengths of the sides one triangle alone holds."""
    inc = edge_incidence(mesh.triangles)
    open_ = inc.edges[inc.count == 1]
    return float(np.linalg.norm(mesh.vertices[open_[:, 0]] - mesh.vertices[open_[:, 1]], axis=1).sum())


def test_dxf_3dsolid_is_the_solid_its_sab_holds():
    model = read_cad(corpus(SAT + "libredwg_example_2013.dxf"))
    assert model.format == "dxf" and model.units == "mm" and model.solids == 1  # $INSUNITS 4; two REGIONs are sheets
    solid = read_cad(corpus(SAT + "acad_example_2013_3DSOLID_acis_binary.sab"))
    assert len(model.faces) == len(solid.faces) + 2


@pytest.mark.parametrize("name,fmt", [("cgma_testgeom_v1600_cubit.sat", "sat"),
                                      ("acad_example_2013_3DSOLID_acis_binary.sab", "sab"),
                                      ("libredwg_example_2013.dxf", "dxf")])
def test_acis_formats_are_recognised_from_bytes(name, fmt, tmp_path):
    renamed = tmp_path / "upload.bin"
    renamed.write_bytes(corpus(SAT + name).read_bytes())
    assert sniff_path(renamed) == fmt


def _rewrite(src: Path, dst: Path, fn) -> Path:  # type: ignore[no-untyped-def]
    dst.write_text(fn(src.read_text()))
    return dst


def _mesh_volume(path: Path, tol: float = 0.002) -> float:
    r = convert(path, MeshParams(tolerance=tol))
    assert r.checks.closed, r.notes
    return _volume(r.mesh)


@pytest.mark.parametrize("unit,name,scale", [("25.4", "inch", 25.4), ("10", "cm", 10.0), ("-1", "none", 1.0)])
def test_header_unit_scale_reads_in_mm(tmp_path, unit, name, scale):
    src = corpus(SAT + "oda_3dsolids_A5_cyl_v700.sat")
    lines = src.read_text().split("\n")
    lines[2] = unit + " " + " ".join(lines[2].split()[1:])
    path = tmp_path / "scaled.sat"
    path.write_text("\n".join(lines))
    assert read_cad(path).units == name
    assert _mesh_volume(path, 0.002 * scale) == pytest.approx(_mesh_volume(src) * scale**3, rel=2e-3)


def test_fusion_smt_preamble_and_end_of_asm_marker(tmp_path):
    """Fusion's .smt: lines before the SAT header, End-of-ASM-data at the end."""
    text = corpus(SAT + "oda_3dsolids_A5_cyl_v700.sat").read_text().replace("End-of-ACIS-data", "End-of-ASM-data")
    path = tmp_path / "part.smt"
    path.write_text("ShapeManager text written by a CAM tool\nASM-data-follows\n" + text)
    assert sniff_path(path) == "sat"
    assert _mesh_volume(path) == pytest.approx(1000 - math.pi * 25 * 5 / 4, rel=1e-3)


def test_pre_400_layout_with_numeric_flags(tmp_path):
    """ACIS 1.x/2.x (106, 201): the 4.0 layout with senses written 0/1 and no intervals on the cone (none here)."""
    src = corpus(SAT + "acad_example_2000_3DSOLID_v400.sat")

    def old(text: str) -> str:
        head, body = text.split("\n", 3)[:3], text.split("\n", 3)[3]
        head[0] = "106" + head[0][3:]
        for word, flag in (("forward_v", "0"), ("reversed", "1"), ("forward", "0"), ("single", "0")):
            body = re.sub(rf"\b{word}\b", flag, body)
        return "\n".join([*head, body])

    path = _rewrite(src, tmp_path / "v106.sat", old)
    assert _mesh_volume(path, 0.01) == pytest.approx(_wall_volume(src), rel=1e-9)


def test_spatial_acis_10_layout_and_asm_extra_integers(tmp_path):
    """Spatial's ACIS 10+ adds an integer after the history to topology and geometry (as Cubit writes); later
    ASM versions add integers before a vertex's point and a coedge's pcurve. The same solid reads the same."""
    src = corpus(SAT + "oda_3dsolids_A5_cyl_v700.sat")
    topo_geo = r"(body|lump|shell|face|loop|coedge|edge|vertex|point|[a-z_]+-surface|[a-z_]+-curve)"

    def spatial(text: str) -> str:
        head, body = text.split("\n", 3)[:3], text.split("\n", 3)[3]
        head[0] = "1600" + head[0][3:]
        body = re.sub(rf"(?m)^{topo_geo} (\$-?\d+) (-?\d+) ", r"\1 \2 \3 -1 ", body)
        return "\n".join([*head, body])

    def asm(text: str) -> str:
        head, body = text.split("\n", 3)[:3], text.split("\n", 3)[3]
        head[0] = "22700" + head[0][3:]
        head[1] = head[1].replace("@12 ACIS 32.0 NT", "@12 ASM 227.0.0 ")
        body = re.sub(r"(?m)^(vertex (?:\S+ ){4})(\$-?\d+ #)", r"\1 7 \2", body)
        body = re.sub(r"(?m)^(coedge (?:\S+ ){9})(\$-?\d+ #)", r"\1 3 \2", body)
        return "\n".join([*head, body])

    expected = _mesh_volume(src)
    assert _mesh_volume(_rewrite(src, tmp_path / "v1600.sat", spatial)) == pytest.approx(expected, rel=1e-9)
    assert _mesh_volume(_rewrite(src, tmp_path / "v22700.sat", asm)) == pytest.approx(expected, rel=1e-9)


def _spline_sheet() -> str:
    """A planar sheet written here: a bilinear spline-surface (exactsur, z = 0) bounded by three lines and a
    quadratic intcurve (exactcur) from (10, 10) over (5, 14) to (0, 10): area 100 + ⅔ · 10 · 2."""
    recs = [
        "body $-1 -1 $-1 $1 $-1 $-1 #",
        "lump $-1 -1 $-1 $-1 $2 $0 #",
        "shell $-1 -1 $-1 $-1 $-1 $3 $-1 $1 #",
        "face $-1 -1 $-1 $-1 $4 $2 $-1 $5 forward single #",
        "loop $-1 -1 $-1 $-1 $6 $3 #",
        "spline-surface $-1 -1 $-1 forward { exactsur nubs 1 1 open open none none 2 2 -1 1 11 1 -1 1 15 1 "
        "-1 -1 0 11 -1 0 -1 15 0 11 15 0 0 F 0 F 0 F 0 F 0 } I I I I #",
    ]
    pts = [(0, 0, 0), (10, 0, 0), (10, 10, 0), (0, 10, 0)]
    # coedges 6..9, edges 10..13, vertices 14..17, points 18..21, curves 22..25
    for k in range(4):
        recs.append(f"coedge $-1 -1 $-1 ${6 + (k + 1) % 4} ${6 + (k - 1) % 4} $-1 ${10 + k} forward $4 $-1 #")
    for k in range(4):
        recs.append(f"edge $-1 -1 $-1 ${14 + k} 0 ${14 + (k + 1) % 4} 1 ${6 + k} ${22 + k} forward @7 unknown #")
    for k in range(4):
        recs.append(f"vertex $-1 -1 $-1 ${10 + k} ${18 + k} #")
    for p in pts:
        recs.append(f"point $-1 -1 $-1 {p[0]} {p[1]} {p[2]} #")
    for k in range(4):
        a, b = np.array(pts[k], float), np.array(pts[(k + 1) % 4], float)
        if k == 2:
            recs.append("intcurve-curve $-1 -1 $-1 forward { exactcur nubs 2 open 2 0 2 1 2 10 10 0 5 14 0 0 10 0 "
                        "0 null_surface null_surface nullbs nullbs } I I #")
        else:
            d = (b - a) / np.linalg.norm(b - a)
            recs.append(f"straight-curve $-1 -1 $-1 {a[0]} {a[1]} {a[2]} {d[0]} {d[1]} {d[2]} I I #")
    head = "700 0 1 0\n@4 test @12 ACIS 32.0 NT @24 Mon Nov 23 10:00:00 2026\n1 9.9999999999999995e-007 1e-010\n"
    return head + "\n".join(recs) + "\nEnd-of-ACIS-data\n"


def test_spline_surface_and_intcurve_are_built_exactly(tmp_path):
    path = tmp_path / "sheet.sat"
    path.write_text(_spline_sheet())
    r = convert(path, MeshParams(tolerance=0.001))
    assert r.checks.boundary_edges > 0 and r.input["unsupported_geometry"] == []
    assert _area(r.mesh) == pytest.approx(100 + 2 / 3 * 10 * 2, abs=10 * 2 * 0.001 + 1e-6)
    assert np.allclose(r.mesh.vertices[:, 2], 0, atol=1e-9)


def test_a_face_with_no_stored_geometry_is_listed_not_a_silent_hole(tmp_path):
    text = _spline_sheet().replace("{ exactsur nubs 1 1 open open none none 2 2 -1 1 11 1 -1 1 15 1 "
                                   "-1 -1 0 11 -1 0 -1 15 0 11 15 0 0 F 0 F 0 F 0 F 0 }",
                                   "{ rbblnsur 0 nullbs }")
    path = tmp_path / "blend.sat"
    path.write_text(text)
    with pytest.raises(AmprepError) as err:  # its only face cannot be built: nothing is left
        read_cad(path)
    assert err.value.code == ErrorCode.EMPTY_MODEL
    solid = corpus(SAT + "oda_3dsolids_A5_cyl_v700.sat").read_text()
    cone = re.search(r"(?m)^cone-surface .*#$", solid).group(0)
    broken = solid.replace(cone, "spline-surface $-1 -1 $-1 forward { rbblnsur 0 nullbs } I I I I #")
    path.write_text(broken)
    model = read_cad(path)
    assert [f["surface"] for f in model.unsupported] == ["spline-surface (rbblnsur)"]
    assert any("unsupported_geometry" in n for n in model.notes)
    r = convert(path, MeshParams(tolerance=0.01))
    assert not r.checks.closed and r.input["unsupported_geometry"][0]["surface"] == "spline-surface (rbblnsur)"


def test_a_surface_its_vertices_do_not_lie_on_is_listed(tmp_path):
    """A plane moved 3 mm off its face's vertices (a misread record, or an approximation of another surface) is
    not meshed as a wrong face: the face is listed with the distance."""
    text = corpus(SAT + "oda_3dsolids_A5_cyl_v700.sat").read_text()
    plane = re.search(r"(?m)^plane-surface \$-1 -1 \$-1 50 10 4.9999999999999991 .*#$", text).group(0)
    path = tmp_path / "moved.sat"
    path.write_text(text.replace(plane, plane.replace("50 10 4.9999999999999991", "50 10 7.9999999999999991")))
    model = read_cad(path)
    assert len(model.unsupported) == 1 and "off its surface" in model.unsupported[0]["why"]
    assert model.unsupported[0]["surface"] == "plane-surface"


def test_a_procedural_surface_uses_its_own_approximation_not_a_nested_one(tmp_path):
    """An offset surface nests its progenitor (with the progenitor's B-spline); with no approximation of its own it
    is unsupported_geometry, not the progenitor's surface."""
    sheet = _spline_sheet()
    nested = re.search(r"\{ exactsur .*? \}", sheet).group(0)
    path = tmp_path / "offset.sat"
    path.write_text(sheet.replace(nested, "{ offsur spline forward " + nested + " 2.5 nullbs }"))
    with pytest.raises(AmprepError) as err:
        read_cad(path)  # its only face is left out: nothing remains
    assert err.value.code == ErrorCode.EMPTY_MODEL


def test_body_transforms_place_rotate_and_scale(tmp_path):
    """A body's transform (rows: the images of the axes, then the translation and a scale) moves it: DAGMC's two
    bodies turned 90° about z, doubled and moved by (10, 20, 30): 8× the volume, the box where it must be."""
    from OCP.Bnd import Bnd_Box
    from OCP.BRepBndLib import BRepBndLib

    src = corpus(SAT + "dagmc_sample01_v1900_cubit.sat")
    identity = "transform $-1 -1 1 0 0 0 1 0 0 0 1 0 0 0 1 no_rotate no_reflect no_shear #"
    moved = "transform $-1 -1 0 1 0 -1 0 0 0 0 1 10 20 30 2 rotate no_reflect no_shear #"
    path = tmp_path / "moved.sat"
    path.write_text(src.read_text().replace(identity, moved))
    box = Bnd_Box()
    BRepBndLib.AddOptimal_s(read_cad(path).shape, box, False, False)
    np.testing.assert_allclose(box.Get(), [-45, -35, -25, 65, 75, 85], atol=1e-6)
    assert _mesh_volume(path, 0.01) == pytest.approx(8 * (4 / 3 * math.pi * 20**3 + 55**3 - 50**3), rel=2e-3)


def _elliptical_frustum(top: float) -> str:
    """A frustum of an elliptical cone written here: base ellipse a = 10, b = 5 at z = 0, the top `top` × that at
    z = 10 (1: an elliptical cylinder); volume π a b h (1 + s + s²) / 3."""
    sine = -(1 - top) * 10 / math.hypot((1 - top) * 10, 10)
    cosine = 10 / math.hypot((1 - top) * 10, 10)
    recs = {
        0: "body $-1 -1 $-1 $1 $-1 $-1 #",
        1: "lump $-1 -1 $-1 $-1 $2 $0 #",
        2: "shell $-1 -1 $-1 $-1 $-1 $3 $-1 $1 #",
        3: "face $-1 -1 $-1 $4 $6 $2 $-1 $10 forward single #",
        4: "face $-1 -1 $-1 $5 $8 $2 $-1 $11 forward single #",
        5: "face $-1 -1 $-1 $-1 $9 $2 $-1 $12 forward single #",
        6: "loop $-1 -1 $-1 $7 $13 $3 #",
        7: "loop $-1 -1 $-1 $-1 $14 $3 #",
        8: "loop $-1 -1 $-1 $-1 $15 $4 #",
        9: "loop $-1 -1 $-1 $-1 $16 $5 #",
        10: f"cone-surface $-1 -1 $-1 0 0 0 0 0 1 10 0 0 0.5 I I {sine!r} {cosine!r} 10 forward I I I I #",
        11: "plane-surface $-1 -1 $-1 0 0 0 0 0 -1 1 0 0 forward_v I I I I #",
        12: "plane-surface $-1 -1 $-1 0 0 10 0 0 1 1 0 0 forward_v I I I I #",
        13: "coedge $-1 -1 $-1 $13 $13 $15 $17 forward $6 $-1 #",
        14: "coedge $-1 -1 $-1 $14 $14 $16 $18 reversed $7 $-1 #",
        15: "coedge $-1 -1 $-1 $15 $15 $13 $17 reversed $8 $-1 #",
        16: "coedge $-1 -1 $-1 $16 $16 $14 $18 forward $9 $-1 #",
        17: "edge $-1 -1 $-1 $19 0 $19 6.283185307179586 $13 $21 forward @7 unknown #",
        18: "edge $-1 -1 $-1 $20 0 $20 6.283185307179586 $14 $22 forward @7 unknown #",
        19: "vertex $-1 -1 $-1 $17 $23 #",
        20: "vertex $-1 -1 $-1 $18 $24 #",
        21: "ellipse-curve $-1 -1 $-1 0 0 0 0 0 1 10 0 0 0.5 I I #",
        22: f"ellipse-curve $-1 -1 $-1 0 0 10 0 0 1 {10 * top!r} 0 0 0.5 I I #",
        23: "point $-1 -1 $-1 10 0 0 #",
        24: f"point $-1 -1 $-1 {10 * top!r} 0 10 #",
    }
    head = "700 0 1 0\n@4 test @12 ACIS 32.0 NT @24 Mon Nov 23 10:00:00 2026\n1 9.9999999999999995e-007 1e-010\n"
    return head + "\n".join(recs[k] for k in range(len(recs))) + "\nEnd-of-ACIS-data\n"


@pytest.mark.parametrize("top", [0.5, 1.0], ids=["elliptical_cone", "elliptical_cylinder"])
def test_elliptical_cones_and_cylinders_are_exact(tmp_path, top):
    path = tmp_path / "frustum.sat"
    path.write_text(_elliptical_frustum(top))
    r = convert(path, MeshParams(tolerance=0.002))
    assert r.checks.closed and r.input["unsupported_geometry"] == [], r.notes
    exact = math.pi * 10 * 5 * 10 * (1 + top + top * top) / 3
    assert abs(_volume(r.mesh) - exact) <= _area(r.mesh) * 0.002, (_volume(r.mesh), exact)


def _one_face_solid(surface: str) -> str:
    recs = ["body $-1 -1 $-1 $1 $-1 $-1 #", "lump $-1 -1 $-1 $-1 $2 $0 #", "shell $-1 -1 $-1 $-1 $-1 $3 $-1 $1 #",
            "face $-1 -1 $-1 $-1 $-1 $2 $-1 $4 forward single #", surface]
    head = "700 0 1 0\n@4 test @12 ACIS 32.0 NT @24 Mon Nov 23 10:00:00 2026\n1 9.9999999999999995e-007 1e-010\n"
    return head + "\n".join(recs) + "\nEnd-of-ACIS-data\n"


def test_lemon_torus_solid_and_a_whole_sphere_face():
    """Faces with no loop: a lemon (major −3, minor 5: the arc of the profile beyond the axis, revolved; volume
    π ∫ (√(25 − z²) − 3)² dz over |z| ≤ 4) and a ball (a sphere face with no loop)."""
    import tempfile

    lemon = math.pi * (34 * 8 - 2 * 4**3 / 3 - 6 * (4 * 3 + 25 * math.asin(0.8)))
    cases = [("torus-surface $-1 -1 $-1 0 0 0 0 0 1 -3 5 1 0 0 forward_v I I I I #", lemon),
             ("sphere-surface $-1 -1 $-1 1 2 3 4 1 0 0 0 0 1 forward_v I I I I #", 4 / 3 * math.pi * 64)]
    with tempfile.TemporaryDirectory() as tmp:
        for record, exact in cases:
            path = Path(tmp) / "one.sat"
            path.write_text(_one_face_solid(record))
            r = convert(path, MeshParams(tolerance=0.001))
            assert r.checks.closed, (record, r.notes)
            assert abs(_volume(r.mesh) - exact) <= _area(r.mesh) * 0.001, (record, _volume(r.mesh), exact)


def test_stored_pcurves_are_used_on_spline_faces():
    """AutoCAD's lofted sheet stores exppc pcurves on its B-spline faces: those that fit their edges are used, and
    the faces mesh within tolerance through them."""
    from amprep.geometry.cad.acis import read_acis

    path = corpus(SAT + "acad_2004_Surface_LOFTED_v20800.sat")
    assert read_acis(path.read_bytes()).pcurves_used >= 8
    r = convert(path, MeshParams(tolerance=0.01))
    assert r.meshing.max_error <= 0.01 and r.checks.nonmanifold_edges == 0


def test_dxf_drawing_unit_scales_its_solids(tmp_path):
    """A DXF's ACIS data is in drawing units ($INSUNITS): the same drawing saved in inches reads 25.4× larger."""
    import ezdxf
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps

    doc = ezdxf.readfile(str(corpus(SAT + "libredwg_example_2013.dxf")))
    doc.header["$INSUNITS"] = 1
    path = tmp_path / "inch.dxf"
    doc.saveas(str(path))

    def volume(p: Path) -> float:
        props = GProp_GProps()
        BRepGProp.VolumeProperties_s(read_cad(p).shape, props)
        return props.Mass()

    model = read_cad(path)
    assert model.units == "inch"
    assert volume(path) == pytest.approx(volume(corpus(SAT + "libredwg_example_2013.dxf")) * 25.4**3, rel=1e-9)
