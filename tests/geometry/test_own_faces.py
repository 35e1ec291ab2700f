"""Large doubly curved faces meshed by us from the start, not by BRepMesh (prepare.py)."""

import numpy as np
import pytest

from amprep.geometry.cad.read import model_from_shape, read_cad
from amprep.geometry.core.checks import check_mesh, manifold3d_accepts
from amprep.geometry.meshing import prepare
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.pipeline import mesh_model
from amprep.geometry.meshing.prepare import expected_triangles
from tests.conftest import corpus


def _cut_torus():
    """A torus R12 r4 with a box cut out of it: one trimmed torus face and three planes."""
    import cadquery as cq

    return cq.Solid.makeTorus(12, 4).cut(cq.Solid.makeBox(30, 30, 30, cq.Vector(-5, -5, -2))).wrapped


def _closed_within(r, tol):
    c = check_mesh(r.mesh)
    assert c.closed and c.degenerate_triangles == 0 and c.volume > 0, c
    assert manifold3d_accepts(r.mesh)
    assert r.max_error <= tol


@pytest.mark.parametrize("tol", [0.1, 0.01])
def test_expected_triangles_is_near_what_occt_makes_on_a_whole_torus(reference_solids, tol):
    """The estimate that picks the faces is within 25 % of BRepMesh's own count on an untrimmed torus (a trimmed
    face gets its whole (u,v) box's: more), and 0 on other surfaces."""
    model = model_from_shape(reference_solids["torus"])
    occt = mesh_model(model, MeshParams(tolerance=tol, own_large_faces=False, enforce_tolerance=False))
    estimate = expected_triangles(model.faces[0], tol)
    assert 0.75 * occt.mesh.n_triangles <= estimate <= 1.25 * occt.mesh.n_triangles, (estimate, occt.mesh.n_triangles)
    other = model_from_shape(reference_solids["filleted_block"])
    assert all(expected_triangles(f, tol) == 0 for f in other.faces)


def test_a_large_torus_is_meshed_by_us_closed_within_tolerance_with_fewer_triangles(reference_solids):
    """Torus R20 r5 at 0.01 mm (≈ 23k triangles expected): left out of BRepMesh and meshed from curvature-sized
    points; closed, every sample of it within the tolerance of the exact torus, and fewer triangles than OCCT's."""
    model = model_from_shape(reference_solids["torus"])
    ours = mesh_model(model, MeshParams(tolerance=0.01))
    assert ours.fallback_faces == {0: "large_curved"}
    _closed_within(ours, 0.01)
    w = np.array([(i, j, 8 - i - j) for i in range(9) for j in range(9 - i)], float) / 8
    p = np.einsum("pk,mkd->mpd", w, ours.mesh.corners).reshape(-1, 3)
    assert np.abs(np.hypot(np.linalg.norm(p[:, :2], axis=1) - 20, p[:, 2]) - 5).max() <= 0.01
    occt = mesh_model(model, MeshParams(tolerance=0.01, own_large_faces=False))
    assert not occt.fallback_faces
    assert ours.mesh.n_triangles < 0.9 * occt.mesh.n_triangles


@pytest.mark.parametrize("name", ["nist_ctc02_ap242.stp", "occt_top_invalid.brep", "cut_torus"])
def test_forced_own_faces_next_to_occt_faces_close_by_topology(name, monkeypatch):
    """Every torus face taken from BRepMesh whatever its size (the threshold forced to 0): BRepMesh meshes the rest
    of the part, our faces meet its faces through their shared edge discretisation, and the part is closed and
    within tolerance."""
    monkeypatch.setattr(prepare, "OWN_MESH_MIN", 0)
    model = read_cad(corpus(name)) if "." in name else model_from_shape(_cut_torus())
    r = mesh_model(model, MeshParams(tolerance=0.1))
    own = sorted(i for i, why in r.fallback_faces.items() if why == "large_curved")
    assert own == [i for i, f in enumerate(r.mesh.faces) if f.surface_type == "torus"]
    assert len(own) < len(model.faces)
    _closed_within(r, 0.1)


def test_a_trimmed_torus_at_a_micron_is_ours_with_half_the_triangles():
    """The cut torus at 0.001 mm: OCCT's mesh of its torus face is over the tolerance and mended to ~178k
    triangles; ours, from curvature-sized points, keeps the tolerance with ~95k."""
    model = model_from_shape(_cut_torus())
    ours = mesh_model(model, MeshParams(tolerance=0.001))
    assert ours.fallback_faces == {0: "large_curved"}
    _closed_within(ours, 0.001)
    occt = mesh_model(model, MeshParams(tolerance=0.001, own_large_faces=False))
    assert ours.mesh.n_triangles < 0.7 * occt.mesh.n_triangles


def test_own_faces_are_never_left_a_stale_triangulation(reference_solids):
    """The torus meshed by OCCT at 0.1 mm, then by us at 0.01 mm, then by OCCT again: each is the fresh mesh."""
    model = model_from_shape(reference_solids["torus"])
    coarse = mesh_model(model, MeshParams(tolerance=0.1))
    fine = mesh_model(model, MeshParams(tolerance=0.01))
    assert not coarse.fallback_faces and fine.fallback_faces == {0: "large_curved"}
    assert fine.mesh.n_triangles > 5 * coarse.mesh.n_triangles and fine.max_error <= 0.01
    assert mesh_model(model, MeshParams(tolerance=0.1)).mesh.n_triangles == coarse.mesh.n_triangles


def test_switching_it_off_leaves_every_face_to_brepmesh(reference_solids):
    model = model_from_shape(reference_solids["torus"])
    assert prepare.own_faces(model, MeshParams(tolerance=0.01), 0.01) == [0]
    assert prepare.own_faces(model, MeshParams(tolerance=0.01, own_large_faces=False), 0.01) == []
