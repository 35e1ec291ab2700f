"""The triangle count estimated from the B-rep before meshing (cad/estimate.py) against the count the mesher
then gives, on the corpus; a model estimated over max_triangles is refused before BRepMesh runs."""

from __future__ import annotations

import pytest
from OCP.BRep import BRep_Tool
from OCP.BRepTools import BRepTools
from OCP.TopLoc import TopLoc_Location

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.cad.estimate import estimate_triangles
from amprep.geometry.cad.read import model_from_shape, read_cad
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.pipeline import mesh_model
from tests.conftest import CAD_FILES, corpus


@pytest.mark.parametrize("name", CAD_FILES)
def test_estimate_is_within_a_small_factor_of_the_mesh(name):
    model = read_cad(corpus(name))
    for tol in (0.1, 0.02):
        real = mesh_model(model, MeshParams(tolerance=tol)).mesh.n_triangles
        est = estimate_triangles(model, tol, MeshParams().angular)
        assert real / 3 <= est <= real * 4, (tol, est, real)


@pytest.mark.parametrize("name", ["torus", "sphere", "bspline_loft"])
def test_estimate_follows_the_tolerance(reference_solids, name):
    """Curved faces need ~1/t triangles: a tenth of the tolerance, about ten times the estimate."""
    model = model_from_shape(reference_solids[name])
    coarse, fine = (estimate_triangles(model, t, 0.5) for t in (0.01, 0.001))
    assert 5 <= fine / coarse <= 12


def test_a_model_over_the_limit_is_refused_before_meshing(reference_solids):
    model = model_from_shape(reference_solids["torus"])
    BRepTools.Clean_s(model.shape)  # the session's solids may have been meshed by an earlier test
    with pytest.raises(AmprepError) as e:
        mesh_model(model, MeshParams(tolerance=1e-4, max_triangles=100_000))
    assert e.value.code == ErrorCode.OUTPUT_TOO_LARGE and "100,000" in e.value.message
    assert all(BRep_Tool.Triangulation_s(f, TopLoc_Location()) is None for f in model.faces)
    assert mesh_model(model, MeshParams(tolerance=0.1, max_triangles=100_000)).mesh.n_triangles > 0


@pytest.mark.parametrize("name", CAD_FILES)
def test_the_quality_meshers_estimate_is_within_a_small_factor_of_its_mesh(name):
    """Made from the edges, the planned rows and the faces' curvature before any face is meshed
    (prepare.quality_estimate): on the corpus a part's quality mesh is 0.43–1.7 × it from 0.34 to 0.01 mm."""
    model = read_cad(corpus(name))
    for tol in (0.1, 0.03):
        r = mesh_model(model, MeshParams(tolerance=tol, mesher="quality"))
        assert r.mesh.n_triangles / 3 <= r.estimated_triangles <= r.mesh.n_triangles * 3, (tol, r.estimated_triangles,
                                                                                             r.mesh.n_triangles)


def test_the_quality_mesher_is_not_refused_for_what_the_b_rep_estimate_overstates():
    """The hull's B-rep estimate takes its largest curvature over the whole face: 108k at 0.05 mm, where the quality
    mesher makes about 50k. Six times it (the quality mesher's estimate before its own) refused the hull under a
    limit of 200k; it is meshed, within that limit."""
    model = read_cad(corpus("dtmb5415_bow_hull.iges"))
    assert estimate_triangles(model, 0.05, MeshParams().angular) * 6 > 200_000
    r = mesh_model(model, MeshParams(tolerance=0.05, mesher="quality", max_triangles=200_000))
    assert 0 < r.mesh.n_triangles <= 200_000 and r.max_error <= 0.05


def test_the_quality_meshers_estimate_refuses_before_any_face_is_meshed(meshed_faces):
    """featuretype at 0.01 mm makes over 50k quality triangles, fewer than 45k of them in lattice rows; under a limit
    of 45k its estimate refuses it once the edges are discretised, before any face is meshed (six times its B-rep
    estimate, 27k, let it through to be stopped part way)."""
    model = read_cad(corpus("featuretype_inch_ap214.step"))
    started, _ = meshed_faces
    with pytest.raises(AmprepError) as e:
        mesh_model(model, MeshParams(tolerance=0.01, mesher="quality", max_triangles=45_000, parallel=False))
    assert e.value.code == ErrorCode.OUTPUT_TOO_LARGE and "before any face is meshed" in e.value.message
    assert not started


def test_the_quality_meshers_estimate_counts_each_placement():
    """as1's instanced parts are meshed once and placed: the estimate counts each face once per placement, as meshing
    every instance would."""
    model = read_cad(corpus("as1_assembly_ap214.stp"))
    once, each = (mesh_model(model, MeshParams(tolerance=0.1, mesher="quality", mesh_instances_once=o))
                  for o in (True, False))
    assert abs(once.mesh.n_triangles - each.mesh.n_triangles) <= 0.01 * each.mesh.n_triangles
    assert abs(once.estimated_triangles - each.estimated_triangles) <= 0.01 * each.estimated_triangles
    assert once.estimated_triangles > 2 * len(model.faces)


def test_the_quality_mesher_chooses_its_evaluator_by_its_own_estimate(monkeypatch):
    """bspline_45 at 0.01 mm: the B-rep estimate (5k) would measure in numpy; the quality mesher makes ~87k triangles
    on B-splines, so its own estimate, made before any face is meshed, runs its faces on the compiled kernels (2 ×
    faster) and in parallel by each face's estimate. The mesh does not depend on the kernels being loaded before."""
    from amprep.geometry.measure.chordal import worth_compiling
    from amprep.geometry.meshing import enforce

    chosen: list[bool] = []
    real = enforce.compiled
    monkeypatch.setattr(enforce, "compiled", lambda on: chosen.append(on) or real(on))
    model = read_cad(corpus("bspline_45_faces.iges"))
    params = MeshParams(tolerance=0.01, mesher="quality")
    result = mesh_model(model, params)
    assert not worth_compiling(estimate_triangles(model, 0.01, params.angular), params.check_order)
    n = result.estimated_triangles  # every face a B-spline
    assert worth_compiling(n, params.check_order, n) and chosen == [True]
    assert result.mesh.n_triangles > 50_000 and result.max_error <= 0.01


def test_the_default_mesher_weighs_free_form_faces_by_their_degree(monkeypatch):
    """OCCT's top.brep at 0.1 mm: its B-spline faces, of degree up to 11 in v, carry under 2,000 triangles in OCCT's
    first mesh, too few to pay numba's start-up were they bicubic; weighted by what numpy pays per point of their
    degrees (numpy_cost) they are over it, and the part is measured on the compiled kernels (3× faster here)."""
    from amprep.geometry.cad.bspline import numpy_cost
    from amprep.geometry.cad.surfaces import surface_of
    from amprep.geometry.measure.chordal import free_form_work, worth_compiling
    from amprep.geometry.meshing import pipeline
    from amprep.geometry.meshing.occt_read import bulk_triangulation_arrays

    assert numpy_cost(3, 3) == numpy_cost(1, 1) == 1.0 and numpy_cost(2, 11) == 36 / 16 and numpy_cost(8, 8) == 81 / 16
    chosen: list[bool] = []
    real = pipeline.compiled
    monkeypatch.setattr(pipeline, "compiled", lambda on: chosen.append(on) or real(on))
    model = read_cad(corpus("occt_top_invalid.brep"))
    params = MeshParams(tolerance=0.1)
    result = mesh_model(model, params)
    assert chosen == [True] and result.max_error <= 0.1
    surfaces = [surface_of(f) for f in model.faces]
    counts = [len(b[2]) for b in bulk_triangulation_arrays(model.faces)]  # OCCT's first mesh, left on the faces
    bicubic = sum(n for n, s in zip(counts, surfaces, strict=True) if s.surface_type == "bspline")
    assert 0 < bicubic < 2_000 and not worth_compiling(bicubic, params.check_order, bicubic)
    assert worth_compiling(0, params.check_order, free_form_work(counts, surfaces))
