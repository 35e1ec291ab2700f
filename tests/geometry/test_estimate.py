"""The triangle count estimated from the B-rep before meshing (cad/estimate.py) against the count the mesher
then gives, on the corpus; a model estimated over max_triangles is refused before BRepMesh runs."""

from __future__ import annotations

import re

import numpy as np
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
    """Within 1/2–2× of the default mesher's count on every corpus part (0.68–1.64 when written; the estimate before
    it, which took a free-form face's largest curvature over its whole area and a cone or sphere for a strip or an
    equilateral fill, was 0.26–2.5)."""
    model = read_cad(corpus(name))
    for tol in (0.1, 0.02):
        real = mesh_model(model, MeshParams(tolerance=tol)).mesh.n_triangles
        est = estimate_triangles(model, tol, MeshParams().angular)
        assert real / 2 <= est <= real * 2, (tol, est, real)


def test_cones_spheres_and_tori_are_estimated_as_brepmesh_meshes_them():
    """BRepMesh puts a grid of interior nodes on a cone, sphere or torus (its range splitters); the estimate counts
    them by the same steps: each face within 0.75–1.33 of the triangles BRepMesh makes on it, as the default mesher
    runs it, whatever the tolerance (a sphere made 2.6 × the estimate before, an apex cone 10 ×)."""
    from OCP.BRepAdaptor import BRepAdaptor_Surface
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeCone, BRepPrimAPI_MakeSphere, BRepPrimAPI_MakeTorus
    from OCP.GeomAbs import GeomAbs_Plane
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopoDS import TopoDS

    from amprep.geometry.cad.estimate import face_triangles
    from amprep.geometry.cad.topology import explore
    from amprep.geometry.meshing.brepmesh import run_brepmesh

    shapes = {"sphere": BRepPrimAPI_MakeSphere(12.0).Shape(), "hemisphere": BRepPrimAPI_MakeSphere(25.0, 0.0, 1.5).Shape(),
              "torus": BRepPrimAPI_MakeTorus(20.0, 5.0).Shape(), "apex cone": BRepPrimAPI_MakeCone(6.0, 0.0, 7.0).Shape(),
              "cone": BRepPrimAPI_MakeCone(10.0, 4.0, 30.0).Shape()}
    for tol in (0.1, 0.01):
        for name, shape in shapes.items():
            run_brepmesh(shape, tol, MeshParams(tolerance=tol))
            for face in explore(shape, TopAbs_FACE, TopoDS.Face_s):
                if BRepAdaptor_Surface(face).GetType() == GeomAbs_Plane:
                    continue
                made = BRep_Tool.Triangulation_s(face, TopLoc_Location()).NbTriangles()
                est = face_triangles(face, tol, MeshParams().angular)
                assert 0.75 <= made / est <= 1.33, (name, tol, made, est)


def test_a_part_the_enforcement_would_take_over_the_limit_is_refused_before_brepmesh():
    """CTC-02 at 0.0001 mm: BRepMesh alone makes about 7 M triangles in ~40 s and the tolerance's enforcement takes
    the mesh past the default limit of 10 M (it was refused after ~90 s, part way). Its spheres and cones, which
    BRepMesh fills with grids, and its B-spline fillets are counted as they are meshed: refused at once, before
    BRepMesh runs."""
    model = read_cad(corpus("nist_ctc02_ap242.stp"))
    BRepTools.Clean_s(model.shape)
    with pytest.raises(AmprepError) as e:
        mesh_model(model, MeshParams(tolerance=1e-4))
    assert e.value.code == ErrorCode.OUTPUT_TOO_LARGE and "before meshing" in e.value.message
    assert all(BRep_Tool.Triangulation_s(f, TopLoc_Location()) is None for f in model.faces)


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


def test_a_refusal_names_a_tolerance_that_fits(reference_solids):
    """The torus at 0.0001 mm under a limit of 100k: the refusal names the finest tolerance whose estimate fits
    (to the rounding up of its two digits); meshed at it, the torus is within the limit and the tolerance."""
    model = model_from_shape(reference_solids["torus"])
    with pytest.raises(AmprepError) as e:
        mesh_model(model, MeshParams(tolerance=1e-4, max_triangles=100_000))
    fit = float(re.search(r"about ([0-9.e-]+) mm would fit", e.value.message).group(1))
    angular = MeshParams().angular
    assert estimate_triangles(model, fit, angular) <= 100_000 < estimate_triangles(model, fit / 1.15, angular)
    r = mesh_model(model, MeshParams(tolerance=fit, max_triangles=100_000))
    assert 0 < r.mesh.n_triangles <= 100_000 and r.max_error <= fit


def test_the_fitting_tolerance_is_the_finest_that_fits_or_none():
    """fitting_tolerance on counts known in closed form: the first tolerance whose count is under the limit, rounded up
    to two digits; None when no tolerance up to the coarsest allowed fits; its calls bounded by the search."""
    from amprep.geometry.core.limits import MAX_TOLERANCE
    from amprep.geometry.meshing.prepare import FIT_GROWTH, FIT_HALVINGS, fitting_tolerance

    calls: list[float] = []

    def count(t: float) -> float:
        calls.append(t)
        return 1000 / t

    for tol, limit in ((1e-4, 100), (0.003, 70), (0.01, 2e4)):
        calls.clear()
        fit = fitting_tolerance(count, tol, int(limit))
        assert fit > tol and count(fit) <= limit < count(fit / 1.15), (tol, limit, fit)
        assert fit == float(f"{fit:.2g}")
        assert len(calls) <= np.log(MAX_TOLERANCE / tol) / np.log(FIT_GROWTH) + FIT_HALVINGS + 3
    assert fitting_tolerance(lambda t: 1e9, 1e-4, 100) is None
    assert fitting_tolerance(count, 0.003, 7) is None  # 1000 / t ≤ 7 from t = 143 mm, past the coarsest


@pytest.mark.parametrize("name", CAD_FILES)
def test_the_quality_meshers_estimate_is_within_a_small_factor_of_its_mesh(name):
    """Made from the edges, the planned rows and the faces' curvature before any face is meshed
    (prepare.quality_estimate): on the corpus a part's quality mesh is 0.43–1.7 × it from 0.34 to 0.01 mm."""
    model = read_cad(corpus(name))
    for tol in (0.1, 0.03):
        r = mesh_model(model, MeshParams(tolerance=tol, mesher="quality"))
        assert r.mesh.n_triangles / 3 <= r.estimated_triangles <= r.mesh.n_triangles * 3, (tol, r.estimated_triangles,
                                                                                             r.mesh.n_triangles)


def test_the_quality_mesher_is_not_refused_by_a_multiple_of_the_b_rep_estimate():
    """The quality mesher makes 0.8–15 × the B-rep estimate on the corpus (typically 6), 2.7 × on the hull at 0.05 mm
    (23k estimated, ~61k made). Six times it (the quality mesher's first estimate) would refuse the hull under a
    limit of 100k; only a quarter of it refuses before the edges exist, and the quality mesher's own estimate, made
    from them, lets the hull be meshed, within that limit."""
    model = read_cad(corpus("dtmb5415_bow_hull.iges"))
    assert estimate_triangles(model, 0.05, MeshParams().angular) * 6 > 100_000
    r = mesh_model(model, MeshParams(tolerance=0.05, mesher="quality", max_triangles=100_000))
    assert 0 < r.mesh.n_triangles <= 100_000 and r.max_error <= 0.05


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
    # the refusal names a tolerance (its estimate scaled by the B-rep estimate's) at which the part is meshed within
    # the limit and the tolerance
    fit = float(re.search(r"about ([0-9.e-]+) mm would fit", e.value.message).group(1))
    assert fit > 0.01
    r = mesh_model(model, MeshParams(tolerance=fit, mesher="quality", max_triangles=45_000))
    assert 0 < r.mesh.n_triangles <= 45_000 and r.max_error <= fit


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
    """bspline_45 at 0.01 mm: the B-rep estimate (7k) would measure in numpy; the quality mesher makes ~87k triangles
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
