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
