"""The Butterfly limit surface as a function (refine/limit_surface.py) and the re-mesh to an edge length on it,
checked against the refinement's own nodes and against exact CAD the refinement never sees (OCCT's BRepExtrema)."""

from __future__ import annotations

import numpy as np
import pytest

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.core.checks import check_mesh
from amprep.geometry.core.edges import edge_incidence
from amprep.geometry.measure.defects import self_intersections
from amprep.geometry.refine.butterfly import ButterflyParams, butterfly_refine
from amprep.geometry.refine.limit_surface import LimitSurface, remesh_to_edge
from tests.geometry.test_butterfly import _mean_distance, _plane_of_triangles, _planes, _stl, parts  # noqa: F401


@pytest.fixture(scope="module")
def sphere(parts, tmp_path_factory):  # noqa: F811
    return _stl(parts["sphere"], tmp_path_factory.mktemp("sphere"))


def test_nodes_of_every_level_are_exact(sphere):
    """At the input's nodes, level 1's and level 2's new nodes, evaluate() gives the refinement's own vertices."""
    surface = LimitSurface.of(sphere, depth=2)
    m = sphere.n_triangles
    t = np.arange(m)
    for k in range(3):
        b = np.zeros((m, 3))
        b[:, k] = 1
        assert np.array_equal(surface.evaluate(t, b), sphere.vertices[sphere.triangles[:, k]])
    one = butterfly_refine(sphere, ButterflyParams(1)).mesh
    for k, bary in ((1, [0.5, 0.5, 0]), (2, [0.5, 0, 0.5])):  # child 0 = (corner 0, m01, m20)
        got = surface.evaluate(t, np.tile(bary, (m, 1)))
        np.testing.assert_allclose(got, one.vertices[one.triangles[:m, k]], atol=1e-12)
    # level 2: child 0 of child 3 (the middle) has its corner at the middle child's corner 0 = m01; its m01 lies at
    # the midpoint of (m01, m12) in the parent: barycentric (1/4, 1/2, 1/4)
    two = surface.fine
    got = surface.evaluate(t, np.tile([0.25, 0.5, 0.25], (m, 1)))
    np.testing.assert_allclose(got, two.vertices[two.triangles[3 * m:4 * m, 1]], atol=1e-12)


def test_locate_inverts_evaluate_and_measures_distance(sphere):
    surface = LimitSurface.of(sphere, depth=2)
    rng = np.random.default_rng(7)
    tri = rng.integers(0, sphere.n_triangles, 400)
    bary = rng.dirichlet([1, 1, 1], 400)
    pts = surface.evaluate(tri, bary)
    t2, b2, d = surface.locate(pts)
    assert d.max() < 1e-9
    np.testing.assert_allclose(surface.evaluate(t2, b2), pts, atol=1e-9)
    # pushed off along the sphere's normal by 0.05 mm: found 0.05 mm away (the sphere is smooth at that scale)
    off = pts * (1 + 0.05 / np.linalg.norm(pts, axis=1))[:, None]
    _, _, d = surface.locate(off)
    assert np.abs(d - 0.05).max() < 0.01, np.abs(d - 0.05).max()


@pytest.mark.parametrize("name", ["sphere", "cylinder", "filleted_block"])
def test_remesh_to_edge(parts, tmp_path, name):  # noqa: F811
    """Every edge at most max_edge, closed and consistently wound, no self-intersection, planar faces exactly on their
    planes, and the new nodes on the curved faces far closer to the exact surface than the facets were."""
    shape = parts[name]
    stl = _stl(shape, tmp_path)
    max_edge = 1.0
    surface = LimitSurface.of(stl)
    remeshed = remesh_to_edge(surface, max_edge, 2_000_000)
    out = remeshed.mesh
    assert len(remeshed.moved) == len(out.vertices) - len(stl.vertices) and remeshed.moved.max() > 0
    inc = edge_incidence(out.triangles)
    lengths = np.linalg.norm(out.vertices[inc.edges[:, 0]] - out.vertices[inc.edges[:, 1]], axis=1)
    assert lengths.max() <= max_edge
    checks = check_mesh(out)
    assert checks.closed and checks.duplicate_triangles == 0 and (inc.count == 2).all() and (inc.forward == 1).all()
    assert self_intersections(out)[0] == 0
    planes = _planes(shape)
    diag = float(np.linalg.norm(np.ptp(stl.vertices, axis=0)))
    on_in = _plane_of_triangles(stl, planes, 1e-6 * diag)
    for i, (o, n) in enumerate(planes):  # every node of a triangle that lay on plane i still lies on it
        nodes_in = np.unique(stl.triangles[on_in == i])
        if len(nodes_in):
            near = np.abs((out.vertices - o) @ n) <= 1e-6 * diag
            assert near.sum() >= len(nodes_in)
    new = out.vertices[len(stl.vertices):]  # the input's nodes come first, unmoved
    off_planes = np.ones(len(new), bool)
    for o, n in planes:
        off_planes &= np.abs((new - o) @ n) > 1e-6 * diag
    pick = np.random.default_rng(3).choice(np.flatnonzero(off_planes), min(200, int(off_planes.sum())), replace=False)
    after = _mean_distance(shape, new[pick])
    curved_in = np.flatnonzero(on_in < 0)
    before = _mean_distance(shape, stl.corners[np.random.default_rng(3).choice(curved_in, 200)].mean(axis=1))
    assert after <= 0.25 * before, (before, after)


def test_planes_stay_exactly_planar(parts, tmp_path):  # noqa: F811
    """The plate with holes re-meshed to 2 mm: every node near one of its planes lies on the plane the STL's own
    (float32) corners define, to 1e-9 of the part's size; the bounding box is unchanged."""
    shape = parts["plate_with_holes"]
    stl = _stl(shape, tmp_path)
    out = remesh_to_edge(LimitSurface.of(stl), 2.0, 2_000_000).mesh
    assert out.n_triangles > 2 * stl.n_triangles
    diag = float(np.linalg.norm(np.ptp(stl.vertices, axis=0)))
    on_in = _plane_of_triangles(stl, _planes(shape), 1e-6 * diag)
    for i, (o, n) in enumerate(_planes(shape)):
        if not (on_in == i).any():
            continue
        ref = stl.vertices[stl.triangles[on_in == i][0, 0]]
        mine = np.abs((out.vertices - o) @ n) <= 1e-5 * diag
        assert np.abs((out.vertices[mine] - ref) @ n).max() <= 1e-9 * diag
    np.testing.assert_allclose(out.bbox(), stl.bbox(), atol=1e-9 * diag)


def test_refused_before_it_runs(sphere):
    with pytest.raises(AmprepError) as e:
        remesh_to_edge(LimitSurface.of(sphere, depth=1), 0.01, 100_000)
    assert e.value.code == ErrorCode.OUTPUT_TOO_LARGE


def test_nearest_point_among_slivers():
    """On an STL of long fans (the corpus's Voron mount), the nearest point found equals a brute-force search over
    every triangle: candidates by triangle centroid alone missed by up to 4 mm here."""
    from amprep.geometry.io.stl import read_stl
    from amprep.geometry.refine.limit_surface import _closest_on_triangles, nearest_on_mesh
    from tests.conftest import corpus

    stl = read_stl(corpus("voron_vhb_din_mount.stl"))
    rng = np.random.default_rng(11)
    tri = rng.integers(0, stl.n_triangles, 200)
    pts = np.einsum("qk,qkd->qd", rng.dirichlet([1, 1, 1], 200), stl.corners[tri]) + rng.normal(0, 0.05, (200, 3))
    d, t, b = nearest_on_mesh(pts, stl)
    for i in range(len(pts)):
        q, _ = _closest_on_triangles(np.repeat(pts[i][None], stl.n_triangles, 0), stl.corners)
        assert d[i] == pytest.approx(np.linalg.norm(q - pts[i], axis=1).min(), abs=1e-12)
    np.testing.assert_allclose(np.einsum("qk,qkd->qd", b, stl.corners[t]), pts, atol=d.max() + 1e-9)
