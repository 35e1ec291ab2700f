"""The quality mesher on faces with a pole or apex (a side of their (u,v) that is one point): spheres, domes, cones,
the corner patches of a filleted box. They take the quality mesh (their interior cut by the surface's own lengths,
small analytic ones as rows), not the boundary-and-refinement path that gave a full sphere a mean angle regularity of
0.47 against OCCT's 0.67; a quality mesh that folds at the pole is found and the face meshed the old way."""

from __future__ import annotations

import numpy as np
import pytest
from OCP.BRepBuilderAPI import BRepBuilderAPI_NurbsConvert

from amprep.geometry.cad.read import model_from_shape, read_cad
from amprep.geometry.core.checks import check_mesh
from amprep.geometry.measure.regularity import regularity
from amprep.geometry.meshing.occt_read import FacePatch
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.pipeline import mesh_model
from amprep.geometry.meshing.weld import fins, folded_pairs, pole_folds
from tests.conftest import corpus
from tests.geometry.test_independent_distance import _worst_distance


def _shapes():  # type: ignore[no-untyped-def]
    import cadquery as cq

    shapes = {
        "sphere": cq.Solid.makeSphere(7, angleDegrees1=-90, angleDegrees2=90),
        "dome": cq.Workplane().sphere(20).intersect(cq.Workplane().box(60, 60, 20).translate((0, 0, 10))).val(),
        "cone": cq.Solid.makeCone(8, 0, 12),
        "filleted box": cq.Workplane().box(30, 20, 10).edges().fillet(2).val(),
        "sphere cut by a box": cq.Workplane().sphere(10).cut(cq.Workplane().box(10, 10, 10).translate((5, 5, 5))).val(),
    }
    # the same as B-splines: no closed form, no rows; their poles on the Delaunay path
    shapes.update({f"{k} as B-splines": cq.Shape.cast(BRepBuilderAPI_NurbsConvert(shapes[k].wrapped, True).Shape())
                   for k in ("sphere", "dome", "cone", "filleted box")})
    return shapes


@pytest.mark.parametrize("tol", [0.34, 0.1])
@pytest.mark.parametrize("name", ["sphere", "dome", "cone", "filleted box", "sphere cut by a box", "sphere as B-splines",
                                  "dome as B-splines", "cone as B-splines", "filleted box as B-splines"])
def test_faces_with_a_pole_take_the_quality_mesh(name, tol):
    model = model_from_shape(_shapes()[name].wrapped)
    r = mesh_model(model, MeshParams(tolerance=tol, mesher="quality"))
    default = mesh_model(model, MeshParams(tolerance=tol))
    c = check_mesh(r.mesh)
    assert c.closed and c.degenerate_triangles == 0, c
    assert {f.meshed_by for f in r.mesh.faces} <= {"quality", "lattice"}
    q, q_default = (regularity(m.mesh.corners)["angle"].mean() for m in (r, default))
    assert q >= max(0.6, q_default + 0.05), (q, q_default)
    assert r.max_error <= tol
    assert _worst_distance(model, r.mesh, samples=200) <= tol * 1.001


@pytest.mark.parametrize("tol", [0.34, 0.1])
def test_b_spline_poles_of_a_real_part(tol):
    """CTC-02's B-spline version: 60 faces closed at one end, whose interior points near the pole's line joined its
    nodes on either side of others (106 faces fell back to the old path, then 54 with the points judged by the surface's
    lengths); a row of points along each pole's line leaves fewer than 1 % of its 597 faces to fall back."""
    r = mesh_model(read_cad(corpus("nist_ctc02_bspline_ap203.stp")), MeshParams(tolerance=tol, mesher="quality"))
    c = check_mesh(r.mesh)
    assert c.closed and c.degenerate_triangles == 0, c
    assert sum(f.meshed_by == "fallback" for f in r.mesh.faces) < 0.01 * len(r.mesh.faces)
    assert r.max_error <= tol


def _patch(tris: list[list[int]]) -> FacePatch:
    """Nodes 0..4 of one face: 2 and 3 on the pole (B-rep vertex 7), 0 on vertex 5, 1 and 4 inside."""
    vertex = np.array([5, -1, 7, 7, -1])
    uv = np.array([[0, 0], [0.5, 0.2], [1, 0], [1, 1], [0.6, 0.5]], float)
    return FacePatch(0, np.c_[uv, np.zeros(5)], uv, np.array(tris), vertex, np.full(5, -1), np.full(5, np.nan))


def test_a_fold_at_a_pole_is_found():
    """Two triangles either side of 1–4 reaching two pole nodes are one triangle, wound both ways, once welded."""
    assert pole_folds(_patch([[1, 2, 4], [4, 3, 1], [0, 2, 1]]))
    assert not pole_folds(_patch([[1, 2, 4], [2, 3, 4], [0, 2, 1]]))  # 2-3-4 collapses: a fan, no fold


def test_the_weld_drops_folded_pairs_only():
    tris = np.array([[0, 1, 2], [2, 1, 0], [0, 1, 3], [3, 1, 0], [4, 5, 6], [5, 6, 4]])
    faces = np.array([0, 0, 0, 1, 2, 2])
    # a pair wound opposite ways in one face goes; across faces, or wound the same way (a defect to report), stays
    assert folded_pairs(tris, faces).tolist() == [True, True, False, False, False, False]


def test_folded_pairs_on_a_large_list_match_grouping_every_row():
    """The weld groups only rows whose hash repeats: on 200,000 random triangles with folds, triples and same-way
    copies planted, it finds what grouping every sorted (corners, face) row finds."""
    rng = np.random.default_rng(7)
    tris = rng.integers(0, 3000, (200_000, 3))
    tris = tris[(tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2]) & (tris[:, 0] != tris[:, 2])]
    faces = rng.integers(0, 3, len(tris))
    pick = rng.choice(len(tris), 300, replace=False)
    tris = np.concatenate([tris, tris[pick[:200]][:, [0, 2, 1]], tris[pick[100:]][:, [1, 2, 0]]])
    faces = np.concatenate([faces, faces[pick[:200]], faces[pick[100:]]])
    rows = np.concatenate([np.sort(tris, axis=1), faces[:, None]], axis=1)
    _, inv, count = np.unique(rows, axis=0, return_inverse=True, return_counts=True)
    inv = inv.reshape(-1)
    odd = ((tris[:, 0] > tris[:, 1]).astype(int) + (tris[:, 0] > tris[:, 2]) + (tris[:, 1] > tris[:, 2])) % 2
    expected = (count[inv] == 2) & (np.bincount(inv, weights=odd)[inv] == 1)
    assert expected.sum() >= 200
    assert np.array_equal(folded_pairs(tris, faces), expected)


def test_two_faces_closing_a_narrow_corner_with_one_triangle_drop_it():
    """Two faces meeting along two edges at a narrow corner (FreeCAD's SOT23 IDF part) each close it with the same
    triangle of boundary nodes: a fin across faces, dropped when all its corners are on B-rep edges or vertices; a pair
    with a corner inside a face stays (the weld's checks report it)."""
    tris = np.array([[0, 1, 2], [1, 0, 2], [3, 4, 5], [4, 3, 5]])
    faces = np.array([0, 1, 0, 1])
    on_boundary = np.array([True, True, False, False])
    assert fins(tris, faces, on_boundary).tolist() == [True, True, False, False]
