"""The first look at OCCT's mesh of every face: the same in one process and shared with forked workers, checks made
on a chunk's triangles at once that name the right face, and chunks that survive the trip between processes."""

import pickle
import subprocess
import sys

import numpy as np
import pytest

from amprep.geometry.cad.read import read_cad
from amprep.geometry.cad.surfaces import surface_of
from amprep.geometry.cad.topology import Topology
from amprep.geometry.measure.chordal import load_kernels
from amprep.geometry.meshing.brepmesh import run_brepmesh
from amprep.geometry.meshing.local_refine import flat_triangles
from amprep.geometry.meshing.occt_check import _Chunk, first_look, patch_error, rejected
from amprep.geometry.meshing.occt_read import bulk_triangulation_arrays, check_patch_boundary, extract_patch
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.pipeline import mesh_model
from amprep.geometry.parallel import face_pool
from tests.conftest import corpus


@pytest.fixture(scope="module")
def ctc02():
    model = read_cad(corpus("nist_ctc02_ap242.stp"))
    run_brepmesh(model.shape, 0.1, MeshParams(tolerance=0.1))
    return model


def _look_all(model, monkeypatch, parallel: bool):
    monkeypatch.setattr(face_pool, "PARALLEL_MIN_COST", 0 if parallel else float("inf"))
    topo = Topology.of(model.shape)
    bulk = bulk_triangulation_arrays(model.faces)
    surfaces = [surface_of(f) for f in model.faces]
    return topo, bulk, first_look(model.faces, topo, bulk, surfaces, {3: "large_curved"}, 6, 1e-9)


def test_first_look_is_the_same_in_parallel_and_in_one_process(ctc02, monkeypatch):
    """Every face of CTC-02 (487, every surface type): the same keys, edges, reasons and errors whether forked
    workers took chunks or not, and the same patch as extract_patch gives; a skipped face keeps its reason."""
    if not face_pool.can_fork():
        pytest.skip("no fork here")
    load_kernels()
    _, bulk, one = _look_all(ctc02, monkeypatch, parallel=False)
    topo, _, many = _look_all(ctc02, monkeypatch, parallel=True)
    assert len(one) == len(many) == len(ctc02.faces)
    assert one[3].reason == many[3].reason == "large_curved"
    for i, (a, b) in enumerate(zip(one, many, strict=True)):
        assert a.reason == b.reason and a.found.face_id == b.found.face_id == i
        assert (a.error is None) == (b.error is None)
        if a.error is not None:
            assert np.array_equal(a.error, b.error)
        assert (a.found.keys is None) == (b.found.keys is None)
        if a.found.keys is not None:
            for x, y in zip(a.found.keys, b.found.keys, strict=True):
                assert np.array_equal(x, y, equal_nan=True)
        assert np.array_equal(a.found.params, b.found.params) and a.found.merges == b.found.merges
    kept = [i for i, look in enumerate(many) if look.reason is None]
    assert len(kept) > 400
    for i in kept[::20]:
        patch = many[i].found.assemble(ctc02.faces[i], bulk[i])
        ref = extract_patch(i, ctc02.faces[i], Topology.of(ctc02.shape))
        for name in ("nodes", "tris", "node_vertex", "node_edge"):
            assert np.array_equal(getattr(patch, name), getattr(ref, name)), (i, name)
        assert np.array_equal(patch.node_param, ref.node_param, equal_nan=True)
        assert np.array_equal(many[i].error, patch_error(ref, surface_of(ctc02.faces[i]), 6))
    for look in many:  # recorded edges are those extract_patch records
        look.found.record(topo)
    ref_topo = Topology.of(ctc02.shape)
    for i in range(len(ctc02.faces)):
        if i != 3:
            extract_patch(i, ctc02.faces[i], ref_topo)
    assert topo.edge_params.keys() == ref_topo.edge_params.keys()
    assert all(np.array_equal(topo.edge_params[e], ref_topo.edge_params[e]) for e in topo.edge_params)


def test_checks_on_a_chunk_name_the_face_that_fails(ctc02):
    """A patch with a triangle taken out (an inner edge then used once) and one with a flat triangle among sound
    ones: the chunk's check rejects exactly those two, as the one-face checks do."""
    topo = Topology.of(ctc02.shape)
    patches = [p for p in (extract_patch(i, f, topo) for i, f in enumerate(ctc02.faces)) if p is not None]
    big = [k for k, p in enumerate(patches) if len(p.tris) > 20]
    inner_node = [k for k in big if ((patches[k].node_edge < 0) & (patches[k].node_vertex < 0)).any()]
    holed, flat = inner_node[0], inner_node[2]
    p = patches[holed]
    inner = np.flatnonzero(((p.node_edge[p.tris] < 0) & (p.node_vertex[p.tris] < 0)).any(axis=1))
    patches[holed] = type(p)(**{**p.__dict__, "tris": np.delete(p.tris, inner[0], axis=0)})
    p = patches[flat]  # an inner node moved onto the opposite side of one of its triangles: a flat triangle
    t = next(t for t in p.tris if p.node_edge[t[2]] < 0 and p.node_vertex[t[2]] < 0)
    nodes = p.nodes.copy()
    nodes[t[2]] = 0.5 * (nodes[t[0]] + nodes[t[1]])
    patches[flat] = type(p)(**{**p.__dict__, "nodes": nodes})
    reasons = rejected(patches, 0.0)
    expect = ["broken_triangulation" if not check_patch_boundary(q) else
              "degenerate_triangles" if flat_triangles(q, 0.0).any() else None for q in patches]
    assert reasons == expect
    assert reasons[holed] == "broken_triangulation" and reasons[flat] == "degenerate_triangles"
    assert sum(r is not None for r in reasons) == 2


def test_a_chunk_survives_pickling(ctc02, monkeypatch):
    """The eleven flat arrays a chunk travels as give back every Look (assembled patches stay behind)."""
    _, bulk, looks = _look_all(ctc02, monkeypatch, parallel=False)
    back = pickle.loads(pickle.dumps(_Chunk(looks[:64]))).looks
    assert len(back) == 64
    for a, b in zip(looks[:64], back, strict=True):
        assert (a.found.face_id, a.reason, a.found.stored, a.found.merges) == (b.found.face_id, b.reason,
                                                                               b.found.stored, b.found.merges)
        assert b.found.patch is None
        assert np.array_equal(a.found.edges, b.found.edges) and np.array_equal(a.found.params, b.found.params)
        assert (a.error is None and b.error is None) or np.array_equal(a.error, b.error)
        if a.found.keys is not None:
            assert all(np.array_equal(x, y, equal_nan=True) for x, y in zip(a.found.keys, b.found.keys, strict=True))
            i = a.found.face_id
            assert np.array_equal(b.found.assemble(ctc02.faces[i], bulk[i]).node_edge, a.found.patch.node_edge)


def test_mesh_model_is_the_same_with_and_without_workers(ctc02, monkeypatch):
    """The whole conversion of CTC-02 at 0.1 mm: identical triangles whether faces were looked at and re-meshed in
    forked workers or not."""
    if not face_pool.can_fork():
        pytest.skip("no fork here")
    load_kernels()
    monkeypatch.setattr(face_pool, "PARALLEL_MIN_COST", float("inf"))
    one = mesh_model(ctc02, MeshParams(tolerance=0.1))
    monkeypatch.setattr(face_pool, "PARALLEL_MIN_COST", 0)
    many = mesh_model(ctc02, MeshParams(tolerance=0.1))
    assert np.array_equal(one.mesh.triangles, many.mesh.triangles)
    assert np.array_equal(one.mesh.vertices, many.mesh.vertices)
    assert one.fallback_faces == many.fallback_faces


def test_importing_amprep_turns_openblas_threads_off_unless_set():
    """numpy's OpenBLAS threads spin while OCCT reads: amprep sets OPENBLAS_NUM_THREADS=1 before numpy loads, and
    a value the user gave is kept."""
    code = "import os, amprep, numpy; print(os.environ['OPENBLAS_NUM_THREADS'])"
    env = {k: v for k, v in __import__("os").environ.items() if k != "OPENBLAS_NUM_THREADS"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "1"
    out = subprocess.run([sys.executable, "-c", code], env={**env, "OPENBLAS_NUM_THREADS": "2"}, capture_output=True,
                         text=True, check=True)
    assert out.stdout.strip() == "2"
