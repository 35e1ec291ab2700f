"""Every long loop honours cancel and the time limit, and a soup cannot make the self-intersection test quadratic:
the broad phase stops after a budget of candidate pairs and says so."""

from __future__ import annotations

import numpy as np
import pytest

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.core.mesh import Mesh
from amprep.geometry.measure.analysis import AnalysisParams, analyze_mesh
from amprep.geometry.measure.defects import self_intersections


def _soup(n: int, seed: int = 3) -> Mesh:
    """n random triangles spanning a unit cube: nearly every pair of boxes overlaps (a soup's worst case)."""
    corners = np.random.default_rng(seed).uniform(0, 1, size=(n, 3, 3))
    return Mesh.from_arrays(corners.reshape(-1, 3), np.arange(3 * n).reshape(-1, 3))


def test_a_soup_stops_at_the_pair_budget_and_says_so():
    mesh = _soup(3000)  # ~4.5 M overlapping pairs
    full = self_intersections(mesh)
    capped = self_intersections(mesh, max_pairs=100_000)
    assert full[2] and not capped[2]
    assert 0 < capped[0] < full[0]


def test_progress_runs_between_blocks_and_a_cancel_stops_the_test(monkeypatch):
    from amprep.geometry.measure import defects

    monkeypatch.setattr(defects, "PAIRS_PER_CALL", 50_000)
    calls: list[float] = []
    self_intersections(_soup(1500), progress=lambda stage, f: calls.append(f))
    assert len(calls) > 5  # ~1.1 M pairs in blocks of 50k

    def cancel(stage: str, fraction: float) -> None:
        raise AmprepError(ErrorCode.CANCELLED, "the job was cancelled")

    with pytest.raises(AmprepError) as e:
        self_intersections(_soup(1500), progress=cancel)
    assert e.value.code == ErrorCode.CANCELLED


def test_the_report_says_when_the_test_stopped(monkeypatch):
    from amprep.geometry.measure import analysis

    monkeypatch.setattr(analysis, "self_intersections",
                        lambda mesh, examples, progress: self_intersections(mesh, examples, progress, max_pairs=1000))
    a = analyze_mesh(_soup(400), AnalysisParams(bounding_box=False))
    assert a.report["mesh"]["self_intersections"]["complete"] is False
    assert "self_intersections_incomplete" in [i["code"] for i in a.report["issues"]]


def test_the_box_cusp_method_runs_in_blocks_with_the_same_answer(monkeypatch):
    """Blocks of SEGMENTS_PER_CALL segments, progress and the cancel check between them (the refine report's
    comparison calls it with no progress: it went 10 s without a check on CTC-02)."""
    from amprep.geometry.core.progress import checking
    from amprep.geometry.measure import cusp

    mesh = _soup(800)
    z = np.array([0.0, 0.0, 1.0])
    whole = cusp.bounding_box(mesh.corners, 0.05, z, density=400.0)
    monkeypatch.setattr(cusp, "SEGMENTS_PER_CALL", 97)
    calls: list[float] = []
    checks: list[int] = []
    with checking(lambda: checks.append(1)):
        blocks = cusp.bounding_box(mesh.corners, 0.05, z, density=400.0, progress=lambda s, f: calls.append(f))
    assert len(calls) > 10 and calls[-1] == 1.0 and len(checks) == len(calls)
    np.testing.assert_array_equal(whole.height, blocks.height)
    assert np.isfinite(whole.height).sum() > 100


def test_the_chordal_kernel_runs_in_bounded_calls_that_see_a_cancel(reference_solids, monkeypatch):
    """A face's chordal error by the compiled kernel in calls of CALL_TRIANGLES, checkpoint() between them: the
    same numbers as one call, and a cancel raised at a checkpoint stops it."""
    from amprep.geometry.cad.read import model_from_shape
    from amprep.geometry.cad.surfaces import surface_of
    from amprep.geometry.core.compiled import compiled
    from amprep.geometry.core.progress import checking
    from amprep.geometry.measure import chordal
    from amprep.geometry.meshing.params import MeshParams
    from amprep.geometry.meshing.pipeline import mesh_model

    model = model_from_shape(reference_solids["torus"])
    mesh = mesh_model(model, MeshParams(tolerance=0.005)).mesh
    face = int(np.bincount(mesh.face_ids).argmax())
    sel = mesh.face_ids == face
    corners, uv, surface = mesh.corners[sel], mesh.uv[sel], surface_of(model.faces[face])
    assert len(corners) > 5000
    with compiled(True):
        whole = chordal.triangle_chordal_error(corners, uv, surface)
        monkeypatch.setattr(chordal, "CALL_TRIANGLES", 500)
        calls: list[int] = []
        with checking(lambda: calls.append(1)):
            blocks = chordal.triangle_chordal_error(corners, uv, surface)
        np.testing.assert_array_equal(whole, blocks)
        assert len(calls) == (len(corners) - 1) // 500

        def cancel() -> None:
            raise AmprepError(ErrorCode.CANCELLED, "the job was cancelled")

        with checking(cancel), pytest.raises(AmprepError) as e:
            chordal.triangle_chordal_error(corners, uv, surface)
    assert e.value.code == ErrorCode.CANCELLED


def test_a_sliver_face_costs_the_quality_mesher_little_memory():
    """A cylinder face 2 mm long and 1.5 µm wide (as IDF parts of FreeCAD's library have): its cells were cut square
    at 1.5 µm, 1.3 M of them, and its boundary sampled at a quarter of that (1.9 GB, 75 s); no cell is now cut under
    the tolerance, and the boundary is sampled in a bounded number of points."""
    import tracemalloc

    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.gp import gp_Ax3, gp_Cylinder

    from amprep.geometry.cad.read import model_from_shape
    from amprep.geometry.meshing.params import MeshParams
    from amprep.geometry.meshing.pipeline import mesh_model

    model = model_from_shape(BRepBuilderAPI_MakeFace(gp_Cylinder(gp_Ax3(), 1.0), 0.0, 1.5e-6, 0.0, 2.0).Face())
    tracemalloc.start()
    try:
        r = mesh_model(model, MeshParams(tolerance=0.1, mesher="quality", parallel=False))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 50e6, f"{peak / 1e6:.0f} MB"
    assert r.mesh.n_triangles > 0 and r.max_error <= 0.1


@pytest.mark.parametrize("mesher", ["occt", "quality"])
def test_a_cancel_seen_while_a_face_is_meshed_stops_the_meshing(reference_solids, monkeypatch, mesher):
    """A cancel raised at a checkpoint inside our face mesher ends mesh_model with `cancelled`; it is not taken for
    a face that failed (which would leave it unmeshed and carry on)."""
    from amprep.geometry.cad.read import model_from_shape
    from amprep.geometry.core.progress import checking, checkpoint
    from amprep.geometry.meshing import enforce
    from amprep.geometry.meshing.params import MeshParams
    from amprep.geometry.meshing.pipeline import mesh_model

    started = []
    real = enforce.mesh_face

    def meshing(*args, **kwargs):  # type: ignore[no-untyped-def]
        started.append(1)
        checkpoint()
        return real(*args, **kwargs)

    def cancel() -> None:
        if started:
            raise AmprepError(ErrorCode.CANCELLED, "the job was cancelled")

    monkeypatch.setattr(enforce, "mesh_face", meshing)
    model = model_from_shape(reference_solids["filleted_block"])
    with checking(cancel), pytest.raises(AmprepError) as e:
        mesh_model(model, MeshParams(tolerance=0.01, mesher=mesher, force_fallback=True, parallel=False))
    assert e.value.code == ErrorCode.CANCELLED and started


def test_the_quality_mesher_looks_for_a_cancel_before_every_face(monkeypatch):
    """In a service worker (a daemonic process: no forks) the quality mesher consults the job's cancel check before
    each face it meshes, so a cancel is seen within one face's work: on the Voron DIN mount (152 faces) no two faces
    are meshed without a check between them. The check is counted, not mocked: mesh_model runs as a worker runs it."""
    from amprep.geometry.cad.read import read_cad
    from amprep.geometry.core.progress import checking
    from amprep.geometry.meshing import enforce
    from amprep.geometry.meshing.params import MeshParams
    from amprep.geometry.meshing.pipeline import mesh_model
    from amprep.geometry.parallel import face_pool
    from tests.conftest import corpus

    events: list[str] = []
    for name in ("mesh_face", "mesh_lattice"):
        real = getattr(enforce, name)

        def meshing(*args, _real=real, **kwargs):  # type: ignore[no-untyped-def]
            events.append("F")
            return _real(*args, **kwargs)

        monkeypatch.setattr(enforce, name, meshing)
    monkeypatch.setattr(face_pool, "can_fork", lambda: False)
    with checking(lambda: events.append("C")):
        r = mesh_model(read_cad(corpus("voron_vhb_din_mount.step")), MeshParams(tolerance=0.1, mesher="quality"))
    faces = "".join(events).replace("C", " ").split(" ")  # the runs of faces with no check between
    assert events.count("F") >= len(r.mesh.faces) and max(len(run) for run in faces) == 1


def test_the_triangle_limit_stops_meshing_as_the_faces_come_when_the_estimate_was_low(monkeypatch, meshed_faces):
    """Estimates far under the truth (forced: the B-rep estimated at one triangle, the quality mesher's faces at none)
    let a part past the checks before meshing; the limit is then kept face by face, so meshing stops with
    output_too_large once the faces made exceed it, not after every face is meshed (the quality mesher on OCCT's
    hammer ran 90 s before refusing)."""
    import cadquery as cq

    from amprep.geometry.cad.read import model_from_shape
    from amprep.geometry.meshing import enforce, prepare
    from amprep.geometry.meshing.params import MeshParams
    from amprep.geometry.meshing.pipeline import mesh_model

    plate = cq.Workplane("XY").box(40, 40, 2).faces(">Z").workplane().rarray(6, 6, 5, 5).rect(2, 2).cutThruAll()
    model = model_from_shape(plate.val().wrapped)
    params = MeshParams(tolerance=0.01, mesher="quality", parallel=False)
    whole = mesh_model(model, params).mesh.n_triangles
    calls, _ = meshed_faces
    calls.clear()
    monkeypatch.setattr(prepare, "TriangleEstimate", lambda *a, **k: lambda tol: 1)
    monkeypatch.setattr(enforce, "quality_estimate", lambda surfaces, *a, **k: np.zeros(len(surfaces)))
    with pytest.raises(AmprepError) as e:
        mesh_model(model, MeshParams(tolerance=0.01, mesher="quality", parallel=False, max_triangles=whole // 3))
    assert e.value.code == ErrorCode.OUTPUT_TOO_LARGE
    assert 0 < len(calls) < len(model.faces)


@pytest.mark.parametrize("mesher", ["occt", "quality"])
def test_one_face_stops_refining_at_the_triangle_limit(reference_solids, monkeypatch, meshed_faces, mesher):
    """A single face far over the limit, every estimate forced to nothing: the face's own meshing stops once it alone
    would exceed the limit (its curvature cells, its refinement rounds); the face is never finished. The limit used to
    be seen only once the face was done: OCCT's terrain, one face estimated at 7 M and needing ~30 M, refined for
    over 300 s."""
    from amprep.geometry.cad.read import model_from_shape
    from amprep.geometry.meshing import enforce, lattice, prepare
    from amprep.geometry.meshing.params import MeshParams
    from amprep.geometry.meshing.pipeline import mesh_model

    model = model_from_shape(reference_solids["torus"])
    params = dict(tolerance=0.005, mesher=mesher, force_fallback=mesher == "occt", parallel=False)
    monkeypatch.setattr(lattice, "LATTICE_MIN", np.inf)  # no rows (the torus has no pole): theirs is checked before
    whole = mesh_model(model, MeshParams(**params)).mesh.n_triangles
    monkeypatch.setattr(prepare, "TriangleEstimate", lambda *a, **k: lambda tol: 1)
    monkeypatch.setattr(enforce, "quality_estimate", lambda surfaces, *a, **k: np.zeros(len(surfaces)))
    _, finished = meshed_faces
    finished.clear()
    with pytest.raises(AmprepError) as e:
        mesh_model(model, MeshParams(**params, max_triangles=whole // 10))
    assert e.value.code == ErrorCode.OUTPUT_TOO_LARGE and f"{whole // 10:,}" in e.value.message
    assert len(model.faces) == 1 and not finished


@pytest.mark.parametrize("stage", ["aligning the STL on the CAD", "isolating faces"])
def test_placing_a_users_stl_looks_for_a_cancel_between_faces_and_icp_rounds(monkeypatch, stage):
    """Placing an STL on its CAD (analyze, refine with a user's STL) consults the job's cancel check between ICP
    rounds and between faces' projections: a CTC-02 STL of 193k triangles went 21 s without one, a million-triangle
    STL minutes. On the Voron DIN mount with its authors' STL no face's projections (at most 1 + RESTARTS calls)
    follow another's without a check between, and a cancel raised at the first check of either stage ends the
    placement with `cancelled` in that stage."""
    from amprep.geometry.cad.read import read_cad
    from amprep.geometry.core.progress import Progress, checking
    from amprep.geometry.io.stl import read_stl
    from amprep.geometry.meshing.params import MeshParams
    from amprep.geometry.placement import project
    from amprep.geometry.placement.place import place_user_stl
    from tests.conftest import corpus

    events: list[str] = []
    stages: list[str] = []
    real = project.project_settled

    def projecting(*args, **kwargs):  # type: ignore[no-untyped-def]
        events.append("P")
        return real(*args, **kwargs)

    monkeypatch.setattr(project, "project_settled", projecting)
    model, user = read_cad(corpus("voron_vhb_din_mount.step")), read_stl(corpus("voron_vhb_din_mount.stl"))
    with checking(lambda: events.append("C")):
        place_user_stl(model, user, MeshParams(tolerance=0.34))
    runs = "".join(events).replace("C", " ").split(" ")
    assert events.count("P") > 500 and max(len(r) for r in runs) <= 1 + project.RESTARTS

    def cancel() -> None:
        if stages and stages[-1] == stage:
            raise AmprepError(ErrorCode.CANCELLED, "the job was cancelled")

    with checking(cancel), pytest.raises(AmprepError) as e:
        place_user_stl(model, user, MeshParams(tolerance=0.34), Progress(lambda s, f: stages.append(s)))
    assert e.value.code == ErrorCode.CANCELLED and stages[-1] == stage


def test_refinement_and_its_comparison_look_for_a_cancel_between_faces(monkeypatch):
    """SMA, VTA (the comparison's other method) and the per-face report consult the job's cancel check before each
    face's work (SMA's projections, VTA's worst points per round, each face's chordal error and score): an SMA job on
    CTC-02 with its own STL went 15 s without one, VTA's 21 s. Counted on featuretype's curved faces: no two faces'
    work without a check between; and a cancel raised at the first check of the refinement ends the job there."""
    from amprep.geometry.core.progress import checking
    from amprep.geometry.meshing.params import MeshParams
    from amprep.geometry.refine import sma, vta
    from amprep.jobs.refine import RefineParams, refine_file
    from tests.conftest import corpus

    events: list[str] = []
    for module, name in ((sma, "project_points"), (vta, "_worst_points")):
        real = getattr(module, name)

        def work(*args, _real=real, **kwargs):  # type: ignore[no-untyped-def]
            events.append("W")
            return _real(*args, **kwargs)

        monkeypatch.setattr(module, name, work)
    params = RefineParams(method="sma", compare_box=False)
    with checking(lambda: events.append("C")):
        refine_file(corpus("featuretype_inch_ap214.step"), None, MeshParams(tolerance=0.1), params)
    runs = "".join(events).replace("C", " ").split(" ")
    assert events.count("W") > 80 and max(len(r) for r in runs) == 1

    stages: list[str] = []

    def cancel() -> None:
        if stages and stages[-1] == "refining":
            raise AmprepError(ErrorCode.CANCELLED, "the job was cancelled")

    with checking(cancel), pytest.raises(AmprepError) as e:
        refine_file(corpus("featuretype_inch_ap214.step"), None, MeshParams(tolerance=0.1), params,
                    progress=lambda s, f: stages.append(s))
    assert e.value.code == ErrorCode.CANCELLED and stages[-1] == "refining"


def test_the_reports_whole_mesh_checks_look_for_a_cancel_between_them():
    """check_mesh, manifold3d, the edge incidence, boundary loops, non-manifold vertices, float32 joins and defect
    locations are each one pass over the whole mesh (4.7 s together on a 772k-triangle Butterfly output, minutes on
    tens of millions): a cancel is looked for between them, and one raised there ends the report in that stage."""
    from amprep.geometry.core.progress import checking

    stages: list[str] = []
    checks: list[str] = []

    def cancel() -> None:
        checks.append(stages[-1] if stages else "")
        if checks.count("checking the mesh") == 3:
            raise AmprepError(ErrorCode.CANCELLED, "the job was cancelled")

    with checking(cancel), pytest.raises(AmprepError) as e:
        analyze_mesh(_soup(300), AnalysisParams(bounding_box=False), progress=lambda s, f: stages.append(s))
    assert e.value.code == ErrorCode.CANCELLED and stages[-1] == "checking the mesh"
