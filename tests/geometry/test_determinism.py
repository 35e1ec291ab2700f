"""Same input, same bytes out: no output may depend on whether numba's kernels happen to be loaded (a worker preloads
them, the CLI warms them beside the reading child), on timing or on the output format's random identifiers."""

from __future__ import annotations

import hashlib
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from amprep.geometry.cad import bspline
from amprep.geometry.core.compiled import compiled, use_compiled
from tests.conftest import corpus

ROOT = Path(__file__).resolve().parents[2]
#: the CLI with the compiled kernels loaded before it starts, as in a worker
PRELOADED = ("import sys\nfrom amprep.geometry.measure.chordal import load_kernels\nload_kernels()\n"
             "from amprep.cli import main\nsys.exit(main(sys.argv[1:]))\n")


def _convert(args: list[str], out: Path, preload: bool) -> str:
    head = [sys.executable, "-c", PRELOADED] if preload else [sys.executable, "-m", "amprep"]
    r = subprocess.run([*head, "convert", *args, "-o", str(out), "--quiet"], capture_output=True, text=True,
                       timeout=600, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    return hashlib.sha256(out.read_bytes()).hexdigest()


@pytest.mark.parametrize("name, tol, mesher", [("voron_hotend_mount_dragon.step", "0.01", "occt"),
                                               ("bspline_45_faces.iges", "0.1", "occt"),
                                               ("occt_top_invalid.brep", "0.1", "occt"),
                                               ("bspline_45_faces.iges", "0.01", "quality")])
def test_the_mesh_does_not_depend_on_the_kernels_being_loaded(tmp_path, name, tol, mesher):
    """Small parts are measured in numpy, large ones by the kernels, by the part's size alone: a fresh CLI and one
    whose kernels were loaded first write the same bytes (these parts, B-spline fillets and faces near the
    tolerance, came out different before; the quality mesher decides again on its own estimate)."""
    args = [str(corpus(name)), "--tolerance", tol, "--mesher", mesher]
    fresh = _convert(args, tmp_path / "a.stl", preload=False)
    assert _convert(args, tmp_path / "b.stl", preload=True) == fresh
    assert _convert(args, tmp_path / "c.stl", preload=False) == fresh


def test_a_3mf_is_the_same_bytes_every_time(tmp_path):
    """lib3mf draws random UUIDs for objects, build items and the build; ours come from the mesh."""
    args = [str(corpus("as1_assembly_ap214.stp"))]
    assert _convert(args, tmp_path / "a.3mf", preload=False) == _convert(args, tmp_path / "b.3mf", preload=False)


def test_the_evaluator_is_the_computations_choice(monkeypatch):
    """Inside compiled(False) even a large call runs numpy; inside compiled(True) even a small one runs the kernel;
    outside, the call's own size decides. Both evaluators agree to rounding."""
    assert not use_compiled(10, 100) and use_compiled(100, 100)
    with compiled(False):
        assert not use_compiled(10**9, 100)
        with compiled(True):
            assert use_compiled(1, 100)
        assert not use_compiled(10**9, 100)
    rng = np.random.default_rng(1)
    poles, weights = rng.normal(size=(5, 6, 3)), rng.uniform(0.5, 2, size=(5, 6))
    knots_u, knots_v = np.r_[0, 0, 0, 0, 0.5, 1, 1, 1, 1], np.r_[0, 0, 0, 0, 0.3, 0.7, 1, 1, 1, 1]
    uv = rng.uniform(0, 1, size=(1000, 2))
    with compiled(False):
        a = bspline.eval_surface(poles, weights, knots_u, knots_v, 3, 3, uv)
    with compiled(True):
        b = bspline.eval_surface(poles, weights, knots_u, knots_v, 3, 3, uv)
    assert np.allclose(a, b, rtol=0, atol=1e-12)
