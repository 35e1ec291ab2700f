"""Faces meshed in forked worker processes give the very mesh the serial loop gives; a dying worker is an error."""

import os
import time

import numpy as np
import pytest

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.cad.read import read_cad
from amprep.geometry.measure.chordal import load_kernels
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.pipeline import mesh_model
from amprep.geometry.parallel import face_pool
from tests.conftest import corpus


@pytest.mark.skipif(not face_pool.can_fork(), reason="no fork here")
def test_faces_meshed_in_worker_processes_equal_the_serial_mesh(monkeypatch):
    """OCCT's sample part at 0.1 mm (faces re-meshed by the fallback), once with every face in the pool from the
    first and once serially: the same vertices and triangles, bit for bit."""
    load_kernels()  # the pool is used only once every measure is compiled
    model = read_cad(corpus("occt_top_invalid.brep"))
    calls = []
    real = face_pool.Forked

    def counting(*args, **kwargs):
        calls.append(args)
        return real(*args, **kwargs)

    monkeypatch.setattr(face_pool, "PARALLEL_MIN_COST", 0.0)
    monkeypatch.setattr(face_pool, "Forked", counting)
    pooled = mesh_model(model, MeshParams(tolerance=0.1))
    assert calls, "no worker was forked"
    monkeypatch.setattr(face_pool, "can_fork", lambda: False)
    serial = mesh_model(model, MeshParams(tolerance=0.1))
    assert pooled.fallback_faces == serial.fallback_faces
    assert np.array_equal(pooled.mesh.vertices, serial.mesh.vertices)
    assert np.array_equal(pooled.mesh.triangles, serial.mesh.triangles)
    assert np.array_equal(pooled.face_error, serial.face_error, equal_nan=True)


@pytest.mark.skipif(not face_pool.can_fork(), reason="no fork here")
def test_the_quality_meshers_plan_made_side_by_side_equals_the_serial_plan(monkeypatch):
    """The quality mesher's planning forks for the faces' areas (Topology.measure_areas) and the edges' standing
    sizes (shared_edges.bend_sizes_many, one surface per task) and the lattices' fields (plan_lattices): forced to
    fork for all three, OCCT's sample part at 0.03 mm (13 lattices) comes out bit for bit as with no fork at all."""
    from amprep.geometry.cad import topology
    from amprep.geometry.meshing import lattice, shared_edges, uv_seed

    load_kernels()
    model = read_cad(corpus("occt_top_invalid.brep"))
    forked: list[str] = []
    real = face_pool.Forked

    def counting(*args, **kwargs):
        forked.append(args[1].__qualname__)  # Forked(_work, fn, ...): the task each child runs
        return real(*args, **kwargs)

    monkeypatch.setattr(face_pool, "Forked", counting)
    monkeypatch.setattr(topology, "AREAS_PARALLEL_MIN", 0.0)
    monkeypatch.setattr(shared_edges, "BEND_PARALLEL_MIN", 0.0)
    monkeypatch.setattr(lattice, "FIELDS_PARALLEL_MIN", 0.0)
    pooled = mesh_model(model, MeshParams(tolerance=0.03, mesher="quality"))
    assert {"measure_areas", "bend_sizes_many", "plan_lattices"} <= {q.split(".")[-3] for q in forked}, forked
    assert any(p.meshed_by == "lattice" for p in pooled.mesh.faces)
    monkeypatch.setattr(face_pool, "can_fork", lambda: False)
    uv_seed.BOUNDED_MEDIANS.clear()
    serial = mesh_model(read_cad(corpus("occt_top_invalid.brep")), MeshParams(tolerance=0.03, mesher="quality"))
    assert np.array_equal(pooled.mesh.vertices, serial.mesh.vertices)
    assert np.array_equal(pooled.mesh.triangles, serial.mesh.triangles)
    assert np.array_equal(pooled.face_error, serial.face_error, equal_nan=True)


@pytest.mark.skipif(not face_pool.can_fork(), reason="no fork here")
def test_a_worker_that_dies_is_a_meshing_error_not_a_hang():
    parent = os.getpid()

    def die(i):
        time.sleep(0.01)
        if os.getpid() != parent:
            os._exit(1)
        return i

    with pytest.raises(AmprepError) as exc:
        face_pool.map_faces(die, range(40), parallel_min=0)
    assert exc.value.code == ErrorCode.MESHING_FAILED
    assert face_pool.map_faces(lambda i: i * i, range(5), parallel_min=0) == {i: i * i for i in range(5)}


@pytest.mark.skipif(not face_pool.can_fork(), reason="no fork here")
def test_every_process_takes_work_and_errors_come_back():
    """Ids are shared out one at a time (the parent and a child both compute some); a child's AmprepError is raised
    with its own code; the serial path below parallel_min never forks."""
    def who(i):
        time.sleep(0.01)
        return os.getpid()

    out = face_pool.map_faces(who, range(30), parallel_min=0, workers=2)
    assert sorted(out) == list(range(30))
    assert os.getpid() in out.values() and len(set(out.values())) == 2
    serial = face_pool.map_faces(who, range(5), cost=[1.0] * 5, parallel_min=10)
    assert set(serial.values()) == {os.getpid()}
    parent = os.getpid()

    def fail(i):
        time.sleep(0.01)
        if os.getpid() != parent:
            raise AmprepError(ErrorCode.EMPTY_MODEL, "from a child")
        return i

    with pytest.raises(AmprepError) as exc:
        face_pool.map_faces(fail, range(30), parallel_min=0, workers=2)
    assert exc.value.code == ErrorCode.EMPTY_MODEL


@pytest.mark.skipif(not face_pool.can_fork(), reason="no fork here")
def test_a_shared_count_adds_up_across_the_forked_processes():
    """Every process's adds land in one total (the triangle limit is kept by it while faces are meshed in parallel):
    the largest total any process saw is the sum of all, and each total seen is distinct."""
    from amprep.geometry.parallel.face_pool import SharedCount

    count = SharedCount(5)

    def add(i: int) -> tuple[int, int]:
        time.sleep(0.05)  # long enough for the forked child to take its share
        return os.getpid(), count.add(i + 1)

    seen = face_pool.map_faces(add, list(range(40)), parallel_min=0, workers=2)
    totals = sorted(t for _, t in seen.values())
    assert len({pid for pid, _ in seen.values()}) == 2
    assert totals[-1] == 5 + sum(range(1, 41)) and len(set(totals)) == 40
    assert count.value == totals[-1]  # what the children added is read here too


@pytest.mark.skipif(not face_pool.can_fork(), reason="no fork here")
def test_a_dominant_face_runs_here_first_on_every_numba_thread():
    """An id costing DOMINANT × all after it is computed in this process before any fork, with numba's threads as
    they were (a forked pool gives each process one); the rest are shared out."""
    import numba

    load_kernels()
    threads = numba.get_num_threads()

    def who(i):
        time.sleep(0.02)
        return os.getpid(), numba.get_num_threads()

    out = face_pool.map_faces(who, range(30), cost=[100.0] + [1.0] * 29, parallel_min=0, workers=2)
    assert out[0] == (os.getpid(), threads)
    assert len({pid for pid, _ in out.values()}) == 2 and {n for _, n in list(out.values())[1:]} == {1}
