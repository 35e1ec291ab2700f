"""The tolerance checked by something other than our own chordal measure: OCCT's BRepExtrema_DistShapeShape from
points on the output's triangles to their CAD face (trimmed, with its location), on the analytic and free-form test
solids and on real parts of the corpus, for both meshers (the quality mesher's also at points on the triangles' sides,
where a sliver beside a boundary arc would show)."""

from __future__ import annotations

import numpy as np
import pytest
from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeVertex
from OCP.BRepExtrema import BRepExtrema_DistShapeShape
from OCP.gp import gp_Pnt

from amprep.geometry.cad.read import model_from_shape, read_cad
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.pipeline import mesh_model
from tests.conftest import corpus

#: barycentric points of each sampled triangle: its centroid and the midpoints between centroid and corners
WEIGHTS = np.array([[1 / 3, 1 / 3, 1 / 3], [2 / 3, 1 / 6, 1 / 6], [1 / 6, 2 / 3, 1 / 6], [1 / 6, 1 / 6, 2 / 3]])
#: and points on its sides: their midpoints and quarter points
SIDES = np.array([[1 / 2, 1 / 2, 0], [0, 1 / 2, 1 / 2], [1 / 2, 0, 1 / 2], [1 / 4, 3 / 4, 0], [0, 1 / 4, 3 / 4],
                  [3 / 4, 0, 1 / 4]])


def _worst_distance(model, mesh, samples: int = 600, seed: int = 5, weights: np.ndarray = WEIGHTS) -> float:
    """Largest distance from points (barycentric `weights` (k, 3)) on `samples` random triangles (with a face) to
    their own CAD face, by OCCT."""
    rng = np.random.default_rng(seed)
    tris = np.flatnonzero(mesh.face_ids >= 0)
    tris = rng.choice(tris, min(samples, len(tris)), replace=False)
    worst = 0.0
    for t in tris:
        face = model.faces[int(mesh.face_ids[t])]
        for p in weights @ mesh.corners[t]:
            v = BRepBuilderAPI_MakeVertex(gp_Pnt(*map(float, p))).Vertex()
            ext = BRepExtrema_DistShapeShape(v, face)
            assert ext.IsDone()
            worst = max(worst, ext.Value())
    return worst


@pytest.mark.parametrize("tol", [0.1, 0.01])
@pytest.mark.parametrize("name", ["cone", "filleted_block", "bspline_loft"])
def test_test_solids_within_tolerance_by_occt(reference_solids, name, tol):
    model = model_from_shape(reference_solids[name])
    r = mesh_model(model, MeshParams(tolerance=tol))
    assert _worst_distance(model, r.mesh) <= tol * 1.001


@pytest.mark.parametrize("name, tol", [("voron_hotend_mount_dragon.step", 0.02), ("featuretype_inch_ap214.step", 0.05),
                                       ("as1_assembly_ap214.stp", 0.1), ("as1_assembly_ap214.stp", 0.01),
                                       ("cq_cube_cylinder_colors.step", 0.01)])
def test_corpus_parts_within_tolerance_by_occt(name, tol):
    """Real parts, among them an assembly of 18 placed solids (as1: nested placements, bolts and nuts used several
    times) and a file in metres: measured in the output's coordinates, after every location and unit scale."""
    model = read_cad(corpus(name))
    r = mesh_model(model, MeshParams(tolerance=tol))
    assert _worst_distance(model, r.mesh) <= tol * 1.001


@pytest.mark.parametrize("name, tol", [("cone", 0.01), ("filleted_block", 0.1), ("bspline_loft", 0.01),
                                       ("plate_with_holes", 0.01)])
def test_quality_mesher_on_test_solids_within_tolerance_by_occt(reference_solids, name, tol):
    """`--mesher quality`: its lattice rows, Delaunay planes and smoothed curved faces, inside and on the sides."""
    model = model_from_shape(reference_solids[name])
    r = mesh_model(model, MeshParams(tolerance=tol, mesher="quality"))
    assert _worst_distance(model, r.mesh, samples=300, weights=np.concatenate([WEIGHTS, SIDES])) <= tol * 1.001


@pytest.mark.parametrize("name, tol", [("voron_hotend_mount_dragon.step", 0.02), ("featuretype_inch_ap214.step", 0.05),
                                       ("as1_assembly_ap214.stp", 0.1), ("cq_cube_cylinder_colors.step", 0.01),
                                       ("bspline_45_faces.iges", 0.01), ("sunglasses_lens_inch.igs", 0.01)])
def test_quality_mesher_on_corpus_parts_within_tolerance_by_occt(name, tol):
    """Real parts by `--mesher quality`: an assembly, a file in inches, trimmed B-spline sheets."""
    model = read_cad(corpus(name))
    r = mesh_model(model, MeshParams(tolerance=tol, mesher="quality"))
    assert _worst_distance(model, r.mesh, samples=300, weights=np.concatenate([WEIGHTS, SIDES])) <= tol * 1.001
