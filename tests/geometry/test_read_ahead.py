"""Work in a forked child: results and errors come back; reading and meshing in a child gives the very mesh reading
and meshing here gives; the checks computed beside manifold3d equal the checks computed here."""

import os

import numpy as np
import pytest

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.meshing import read_ahead
from amprep.geometry.meshing.brepmesh import occt_pool_untouched, run_brepmesh
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.pipeline import mesh_prepared
from amprep.geometry.parallel.forked import Forked, fork_available
from amprep.jobs.convert import FORK_CHECKS_MIN, convert, output_checks
from tests.conftest import corpus

needs_fork = pytest.mark.skipif(not fork_available(), reason="no fork or a single core here")


@needs_fork
def test_a_forked_call_returns_its_value_and_its_errors():
    parent = os.getpid()
    job = Forked(lambda a, b: (os.getpid(), a + b), 2, 3)
    assert job.forked
    pid, total = job.result()
    assert total == 5 and pid != parent
    assert Forked(lambda: 7, fork=False).result() == 7  # inline

    def empty():
        raise AmprepError(ErrorCode.EMPTY_MODEL, "nothing")

    with pytest.raises(AmprepError) as exc:
        Forked(empty).result()
    assert exc.value.code == ErrorCode.EMPTY_MODEL and exc.value.message == "nothing"

    def crash():
        os._exit(3)

    with pytest.raises(AmprepError) as exc:
        Forked(crash, died=(ErrorCode.UNREADABLE_CAD, "it died")).result()
    assert exc.value.code == ErrorCode.UNREADABLE_CAD

    def bug():
        raise ValueError("a bug")

    with pytest.raises(AmprepError) as exc:
        Forked(bug).result()
    assert exc.value.code == ErrorCode.INTERNAL_ERROR


@needs_fork
@pytest.mark.parametrize("name, tol", [("nist_ctc02_ap242.stp", 0.1), ("featuretype_inch_ap214.step", 0.05)])
def test_reading_and_meshing_in_a_child_gives_the_same_mesh(monkeypatch, name, tol):
    """The shape comes back through OCCT's binary BREP with its triangulations and edge polygons: welded by topology
    it is the mesh of reading and meshing here, bit for bit, closed, with the unit and tolerance of the file."""
    params = MeshParams(tolerance=tol, parallel=False)
    here = read_ahead.read_and_prepare(corpus(name), "step", params)
    monkeypatch.setattr(read_ahead, "kernels_warm", lambda: False)  # the kernels warmed meanwhile, as a first job does
    calls = []
    real = read_ahead.Forked

    def counting(*args, **kwargs):
        job = real(*args, **kwargs)
        calls.append(job.forked)
        return job

    monkeypatch.setattr(read_ahead, "Forked", counting)
    there = read_ahead.read_and_prepare_ahead(corpus(name), "step", params)
    assert calls == [True]
    assert there.tolerance == here.tolerance and there.own == here.own
    assert there.model.units == here.model.units and len(there.model.faces) == len(here.model.faces)
    assert there.model.face_solid == here.model.face_solid
    a = mesh_prepared(here, params, None)
    b = mesh_prepared(there, params, None)
    assert np.array_equal(a.mesh.vertices, b.mesh.vertices)
    assert np.array_equal(a.mesh.triangles, b.mesh.triangles)
    assert a.fallback_faces == b.fallback_faces


@needs_fork
def test_an_unreadable_file_read_in_a_child_is_unreadable_cad(monkeypatch, tmp_path):
    bad = tmp_path / "bad.step"
    bad.write_text("ISO-10303-21;\nHEADER;\nENDSEC;\nDATA;\n#1=FOO(;\nENDSEC;\nEND-ISO-10303-21;\n")
    monkeypatch.setattr(read_ahead, "kernels_warm", lambda: False)
    with pytest.raises(AmprepError) as exc:
        read_ahead.read_and_prepare_ahead(bad, "step", MeshParams())
    assert exc.value.code in (ErrorCode.UNREADABLE_CAD, ErrorCode.EMPTY_MODEL)


def test_a_parallel_brepmesh_marks_the_thread_pool_used(reference_solids):
    """A child may not mesh in parallel once this process has (OCCT's pool would wait for the parent's threads)."""
    run_brepmesh(reference_solids["cylinder"], 0.1, MeshParams(tolerance=0.1, parallel=True))
    assert not occt_pool_untouched()


@needs_fork
def test_checks_beside_manifold3d_equal_the_checks_here():
    r = convert(corpus("nist_ctc02_ap242.stp"), MeshParams(tolerance=0.01))
    assert r.mesh.n_triangles >= FORK_CHECKS_MIN  # so convert computed them in a child
    checks, rounded, joined = output_checks(r.mesh)
    assert checks == r.checks and rounded == r.float32_degenerate and joined[1] == 0
    assert r.checks.closed and r.manifold3d


def _forked_in_child(queue):
    from amprep.geometry.parallel.face_pool import can_fork
    from amprep.geometry.parallel.forked import Forked

    job = Forked(os.getpid)
    queue.put((job.forked, job.result() == os.getpid(), can_fork()))


@needs_fork
def test_a_daemonic_process_does_its_work_itself():
    """A Celery prefork child is daemonic: its siblings use the other cores, so nothing is forked there."""
    import multiprocessing as mp

    ctx = mp.get_context("fork")
    queue = ctx.Queue()
    proc = ctx.Process(target=_forked_in_child, args=(queue,), daemon=True)
    proc.start()
    forked, same_process, pool = queue.get(timeout=60)
    proc.join(60)
    assert not forked and same_process and not pool


@pytest.mark.parametrize("stop, loaded", [(True, "False"), (False, "True")])
def test_warming_stops_after_importing_numba_when_the_file_is_read_already(stop, loaded):
    """A fresh process: warm_kernels imports numba, then loads and dispatches the kernels only while stop() is False
    (a small part read meanwhile never pays the rest of numba's start-up; its measures stay in numpy)."""
    import subprocess
    import sys

    code = (f"import sys; from amprep.geometry.measure import chordal; chordal.warm_kernels(stop=lambda: {stop}); "
            "print(chordal.kernels_loaded(), 'numba' in sys.modules, chordal.kernels_warm())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == [loaded, "True", loaded]


@needs_fork
def test_kernels_are_warmed_at_once_for_a_large_file_later_for_a_small_one(monkeypatch):
    """A large STEP (CTC-02, 3.4 MB) reads for longer than numba takes to load: the warm starts as the child starts.
    A small file's child is given WARM_AFTER first (numba's import, which cannot be stopped, would outlast it)."""
    import time

    assert read_ahead.warm_delay(corpus("nist_ctc02_ap242.stp")) == 0.0
    assert read_ahead.warm_delay(corpus("voron_vhb_din_mount.step")) == read_ahead.WARM_AFTER >= 0.5
    monkeypatch.setattr(read_ahead, "kernels_warm", lambda: False)
    calls = []
    start = time.monotonic()
    monkeypatch.setattr(read_ahead, "warm_kernels", lambda stop: calls.append((time.monotonic() - start, stop())))
    read_ahead.read_and_prepare_ahead(corpus("nist_ctc02_ap242.stp"), "step", MeshParams(tolerance=0.1))
    assert len(calls) == 1 and calls[0][0] < 0.2 and calls[0][1] is False  # at once, the child still reading
    calls.clear()
    read_ahead.read_and_prepare_ahead(corpus("cq_cube_cylinder_colors.step"), "step", MeshParams(tolerance=0.1))
    assert calls == []  # read and meshed well within WARM_AFTER
