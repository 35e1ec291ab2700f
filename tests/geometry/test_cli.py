"""The `amprep` command as a user runs it: a real subprocess, real files."""

import json
import os
import struct
import subprocess
import sys

import numpy as np
import pytest

from amprep.geometry.core.edges import edge_incidence
from amprep.geometry.io.stl import read_stl
from tests.conftest import corpus


def run(*args, cwd=None):
    env = {**os.environ, "PYTHONUTF8": "1"}
    return subprocess.run([sys.executable, "-m", "amprep", *args], capture_output=True, encoding="utf-8",
                          errors="replace", cwd=cwd, timeout=300, env=env)


def test_inch_step_gives_mm_stl_with_provenance_header(tmp_path):
    out = tmp_path / "part.stl"
    report = tmp_path / "r.json"
    r = run("convert", str(corpus("featuretype_inch_ap214.step")), "-o", str(out), "--tolerance", "0.05",
            "--report", str(report))
    assert r.returncode == 0, r.stderr
    assert "inch" in r.stdout and "closed" in r.stdout
    mesh = read_stl(out)
    lo, hi = mesh.bbox()
    np.testing.assert_allclose(hi - lo, [127, 63.5, 34.925], atol=0.01)
    header = out.read_bytes()[:80].decode()
    assert "amprep" in header and "occt 7." in header and "tol 0.05mm" in header
    summary = json.loads(report.read_text())
    assert summary["input"]["units"] == "inch"
    assert summary["mesh"]["watertight"] is True
    assert summary["meshing"]["max_chordal_error"] <= 0.05
    assert summary["provenance"]["params"]["tolerance"] == 0.05


def test_3mf_output_and_ascii_output(tmp_path):
    r = run("convert", str(corpus("voron_vhb_din_mount.step")), "-o", str(tmp_path / "p.3mf"), "--quiet")
    assert r.returncode == 0 and r.stdout == "", r.stderr
    r = run("convert", str(corpus("voron_vhb_din_mount.step")), "-o", str(tmp_path / "p.stl"), "--ascii")
    assert r.returncode == 0
    assert (tmp_path / "p.stl").read_text().startswith("solid amprep")


def test_stl_passthrough_reports_defects(tmp_path):
    r = run("convert", str(corpus("triangle_soup.stl")), "-o", str(tmp_path / "s.stl"))
    assert r.returncode == 0
    assert "OPEN" in r.stdout and "300 boundary" in r.stdout


@pytest.mark.parametrize("content,code", [
    (b"", "empty_model"),
    (b"just some words\n", "unsupported_format"),
    (b"ISO-10303-21;\nHEADER;\nbroken", "unreadable_cad"),
    (b"\0" * 80 + struct.pack("<I", 0), "unsupported_format"),
])
def test_bad_input_one_line_stable_code_exit_2(tmp_path, content, code):
    p = tmp_path / "input.step"
    p.write_bytes(content)
    r = run("convert", str(p), "-o", str(tmp_path / "o.stl"))
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and f"[{code}]" in lines[0], r.stderr
    assert "Traceback" not in r.stderr


def test_bad_output_extension_and_parameter(tmp_path):
    r = run("convert", str(corpus("voron_vhb_din_mount.step")), "-o", str(tmp_path / "o.obj"))
    assert r.returncode == 2 and "[invalid_parameter]" in r.stderr
    r = run("convert", str(corpus("voron_vhb_din_mount.step")), "-o", str(tmp_path / "o.stl"), "--tolerance", "-1")
    assert r.returncode == 2 and "[invalid_parameter]" in r.stderr


def test_occt_edges_gives_occts_count_and_the_default_fewer(tmp_path):
    """cadquery's cube + cylinder: OCCT discretises the cylinder's circles at half the tolerance; by default they are
    at the tolerance (fewer triangles, still closed and within tolerance), --occt-edges keeps OCCT's, and the report
    says which was used."""
    counts = {}
    for flag in ([], ["--occt-edges"]):
        out, report = tmp_path / f"p{len(flag)}.stl", tmp_path / f"r{len(flag)}.json"
        r = run("convert", str(corpus("cq_cube_cylinder_colors.step")), "-o", str(out), "--report", str(report), *flag)
        assert r.returncode == 0, r.stderr
        summary = json.loads(report.read_text())
        assert summary["mesh"]["watertight"] is True and summary["meshing"]["max_chordal_error"] <= 0.1
        assert summary["provenance"]["params"]["occt_edges"] is bool(flag)
        counts[bool(flag)] = read_stl(out).n_triangles
    assert counts[False] < 0.8 * counts[True]


def test_large_torus_faces_are_ours_unless_no_own_large_faces(tmp_path):
    """A torus R20 r5 STEP at 0.01 mm: its face is meshed by us (fallback reason large_curved, fewer triangles);
    --no-own-large-faces leaves it to BRepMesh; both closed and within tolerance, and the report says which."""
    import cadquery as cq

    step = tmp_path / "torus.step"
    cq.exporters.export(cq.Workplane().add(cq.Solid.makeTorus(20, 5)), str(step))
    counts = {}
    for flag in ([], ["--no-own-large-faces"]):
        out, report = tmp_path / f"t{len(flag)}.stl", tmp_path / f"t{len(flag)}.json"
        r = run("convert", str(step), "-o", str(out), "--tolerance", "0.01", "--report", str(report), *flag)
        assert r.returncode == 0, r.stderr
        summary = json.loads(report.read_text())
        assert summary["mesh"]["watertight"] is True and summary["meshing"]["max_chordal_error"] <= 0.01
        assert summary["provenance"]["params"]["own_large_faces"] is (not flag)
        assert summary["meshing"]["fallback_faces"] == ({} if flag else {"0": "large_curved"})
        counts[bool(flag)] = read_stl(out).n_triangles
    assert counts[False] < 0.9 * counts[True]


def test_a_bug_of_ours_is_one_line_internal_error_exit_2(tmp_path):
    """An unexpected exception (forced here by replacing convert with one that divides by zero) is one line with
    the internal_error code and exit status 2; AMPREP_DEBUG=1 shows the traceback."""
    code = ("import sys, amprep.jobs.convert as c\n"
            "c.convert = lambda *a, **k: 1 / 0\n"
            "from amprep.cli import main\n"
            "sys.exit(main(sys.argv[1:]))\n")
    args = [sys.executable, "-c", code, "convert", str(corpus("voron_vhb_din_mount.step")), "-o", str(tmp_path / "o.stl")]
    r = subprocess.run(args, capture_output=True, text=True, timeout=120)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and "[internal_error]" in lines[0] and "ZeroDivisionError" in lines[0]
    r = subprocess.run(args, capture_output=True, text=True, timeout=120, env={**os.environ, "AMPREP_DEBUG": "1"})
    assert r.returncode != 0 and "Traceback" in r.stderr


def test_refine_an_stl_alone_by_butterfly(tmp_path):
    """`amprep refine IN.stl --method butterfly`: no CAD, 16× the triangles at 2 levels, closed, a report that says
    what was refined; a CAD input with butterfly is refused with its reason."""
    src = corpus("voron_vhb_din_mount.stl")
    out, report = tmp_path / "fine.stl", tmp_path / "r.json"
    r = run("refine", str(src), "--method", "butterfly", "--levels", "2", "-o", str(out), "--report", str(report),
            "--no-compare")
    assert r.returncode == 0, r.stderr
    assert read_stl(out).n_triangles == 16 * read_stl(src).n_triangles
    rep = json.loads(report.read_text())
    assert rep["method"] == "butterfly" and rep["mesh"]["watertight"]
    assert rep["butterfly"]["levels"] == 2 and rep["butterfly"]["nodes"]["curve"] > 0
    assert "self_intersections" not in [i["code"] for i in rep["issues"]]
    bad = run("refine", str(corpus("voron_vhb_din_mount.step")), "--method", "butterfly", "-o", str(out))
    assert bad.returncode == 2 and "invalid_parameter" in bad.stderr and "STL alone" in bad.stderr


def test_butterfly_to_an_edge_length_or_a_triangle_budget(tmp_path):
    """`--max-edge MM` re-meshes on the limit surface until no edge is longer; `--levels 0 --max-triangles N` takes
    as many levels as fit N."""
    src = corpus("voron_vhb_din_mount.stl")
    n = read_stl(src).n_triangles
    out, report = tmp_path / "edge.stl", tmp_path / "r.json"
    r = run("refine", str(src), "--method", "butterfly", "--max-edge", "1.5", "-o", str(out), "--report", str(report))
    assert r.returncode == 0, r.stderr
    mesh = read_stl(out)
    e = edge_incidence(mesh.triangles)
    assert np.linalg.norm(mesh.vertices[e.edges[:, 0]] - mesh.vertices[e.edges[:, 1]], axis=1).max() <= 1.5 + 1e-5
    rep = json.loads(report.read_text())
    assert rep["mesh"]["watertight"] and rep["butterfly"]["max_edge"] == 1.5 and rep["butterfly"]["longest_edge"] <= 1.5
    assert 0 < rep["butterfly"]["moved"]["mean"] < rep["butterfly"]["moved"]["max"] < 0.5  # off the input's facets
    assert "re-meshed to edges ≤ 1.5 mm" in r.stdout
    r = run("refine", str(src), "--method", "butterfly", "--levels", "0", "--max-triangles", str(20 * n), "-o", str(out))
    assert r.returncode == 0, r.stderr
    assert read_stl(out).n_triangles == 16 * n  # 2 levels fit 20n, 3 do not
    r = run("refine", str(src), "--method", "butterfly", "--max-edge", "0.001", "-o", str(out))
    assert r.returncode == 2 and "output_too_large" in r.stderr
