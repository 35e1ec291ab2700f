"""STL-only refinement by the modified Butterfly scheme (refine/butterfly.py), checked on exact CAD the refinement
never sees: parts tessellated coarsely (0.5 mm) and written to STL, refined from the STL alone, measured against
the exact surfaces by OCCT's BRepExtrema."""

from __future__ import annotations

import numpy as np
import pytest
from OCP.BRepAdaptor import BRepAdaptor_Surface
from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeVertex
from OCP.BRepExtrema import BRepExtrema_DistShapeShape
from OCP.GeomAbs import GeomAbs_Plane
from OCP.gp import gp_Pnt
from OCP.TopAbs import TopAbs_FACE, TopAbs_SHELL
from OCP.TopoDS import TopoDS

from amprep.geometry.cad.read import model_from_shape
from amprep.geometry.cad.topology import explore
from amprep.geometry.core.checks import check_mesh
from amprep.geometry.core.mesh import Mesh
from amprep.geometry.io.stl import read_stl, write_stl
from amprep.geometry.measure.defects import self_intersections
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.pipeline import mesh_model
from amprep.geometry.refine.butterfly import ButterflyParams, butterfly_refine


@pytest.fixture(scope="module")
def parts():
    import cadquery as cq

    return {
        "sphere": cq.Solid.makeSphere(12, angleDegrees1=-90, angleDegrees2=90).wrapped,
        "cylinder": cq.Solid.makeCylinder(10, 30).wrapped,
        "torus": cq.Solid.makeTorus(20, 5).wrapped,
        "filleted_block": cq.Workplane().box(30, 20, 10).edges().fillet(3).faces(">Z").workplane()
        .rarray(12, 6, 2, 2).hole(3).val().wrapped,
        "plate_with_holes": cq.Workplane().box(40, 30, 5).faces(">Z").workplane().rarray(20, 10, 2, 2).hole(4)
        .val().wrapped,
    }


def _stl(shape, tmp_path) -> Mesh:
    """The part tessellated at 0.5 mm and written as a binary STL, read back (float32 coordinates, no topology)."""
    mesh = mesh_model(model_from_shape(shape), MeshParams(tolerance=0.5)).mesh
    path = tmp_path / "part.stl"
    write_stl(mesh, path)
    return read_stl(path)


def _planes(shape) -> list[tuple[np.ndarray, np.ndarray]]:
    out = []
    for f in explore(shape, TopAbs_FACE, TopoDS.Face_s):
        ad = BRepAdaptor_Surface(f)
        if ad.GetType() == GeomAbs_Plane:
            pl = ad.Plane()
            out.append((np.array(pl.Location().Coord()), np.array(pl.Axis().Direction().Coord())))
    return out


def _plane_of_triangles(mesh: Mesh, planes, eps: float) -> np.ndarray:
    """(m,) index of the CAD plane every corner of a triangle lies on (−1: none)."""
    out = np.full(mesh.n_triangles, -1)
    for i, (o, n) in enumerate(planes):
        on = np.abs((mesh.vertices - o) @ n) <= eps
        out[on[mesh.triangles].all(axis=1) & (out < 0)] = i
    return out


def _mean_distance(shape, points: np.ndarray) -> float:
    shell = explore(shape, TopAbs_SHELL, TopoDS.Shell_s)[0]
    d = []
    for p in points:
        ext = BRepExtrema_DistShapeShape(BRepBuilderAPI_MakeVertex(gp_Pnt(*map(float, p))).Vertex(), shell)
        d.append(ext.Value())
    return float(np.mean(d))


def _curved_samples(mesh: Mesh, parent_plane: np.ndarray, m0: int, n: int = 250) -> np.ndarray:
    """Centroids of n triangles whose original triangle (index mod m0) lay on no plane."""
    curved = np.flatnonzero(parent_plane[np.arange(mesh.n_triangles) % m0] < 0)
    pick = np.random.default_rng(1).choice(curved, min(n, len(curved)), replace=False)
    return mesh.corners[pick].mean(axis=1)


@pytest.mark.parametrize("name", ["sphere", "cylinder", "torus", "filleted_block"])
def test_curved_faces_come_at_least_twice_as_close(parts, tmp_path, name):
    shape = parts[name]
    stl = _stl(shape, tmp_path)
    planes = _planes(shape)
    diag = float(np.linalg.norm(np.ptp(stl.vertices, axis=0)))
    on_plane = _plane_of_triangles(stl, planes, 1e-6 * diag)
    result = butterfly_refine(stl, ButterflyParams(levels=1))
    before = _mean_distance(shape, _curved_samples(stl, on_plane, stl.n_triangles))
    after = _mean_distance(shape, _curved_samples(result.mesh, on_plane, stl.n_triangles))
    assert after <= 0.5 * before, (before, after)


@pytest.mark.parametrize("name", ["filleted_block", "plate_with_holes", "cylinder"])
@pytest.mark.parametrize("levels", [1, 2])
def test_planar_faces_stay_on_their_planes_and_the_part_stays_closed(parts, tmp_path, name, levels):
    shape = parts[name]
    stl = _stl(shape, tmp_path)
    planes = _planes(shape)
    diag = float(np.linalg.norm(np.ptp(stl.vertices, axis=0)))
    on_plane = _plane_of_triangles(stl, planes, 1e-6 * diag)  # float32 STL: its vertices are within ~1e-7
    assert (on_plane >= 0).any()
    out = butterfly_refine(stl, ButterflyParams(levels=levels)).mesh
    m0 = stl.n_triangles
    parent = on_plane[np.arange(out.n_triangles) % m0]  # a child's original triangle is its index mod m0
    for i, (_o, n) in enumerate(planes):
        mine = out.triangles[parent == i]
        if len(mine):
            # on the plane the STL's own corners define (float32), to 1e-9 of the part's size
            ref = stl.vertices[stl.triangles[on_plane == i][0, 0]]
            assert np.abs((out.vertices[mine] - ref) @ n).max() <= 1e-9 * diag
    checks = check_mesh(out)
    assert checks.closed and checks.duplicate_triangles == 0 and checks.inside_out_shells == 0
    assert self_intersections(out)[0] == 0
    if name != "cylinder":  # prismatic: the bounding box is the planes'
        lo, hi = stl.bbox()
        lo2, hi2 = out.bbox()
        np.testing.assert_allclose(np.concatenate([lo2, hi2]), np.concatenate([lo, hi]), atol=1e-9 * diag)


def _twelve_gon(h: float = 0.3):
    """002's Fig. 9 control grid: 24 triangles over a regular 12-gon (radius 2: 12 boundary nodes, a hexagon of
    radius 1 and the centre), two opposite hexagon nodes lifted by +h and −h out of the plane."""
    ring = [(2 * np.cos(a), 2 * np.sin(a), 0.0) for a in np.arange(12) * np.pi / 6]
    hexa = [(np.cos(a), np.sin(a), 0.0) for a in np.arange(6) * np.pi / 3]
    v = np.array([(0.0, 0.0, 0.0), *hexa, *ring])
    v[1, 2], v[4, 2] = h, -h
    tris = [(0, 1 + i, 1 + (i + 1) % 6) for i in range(6)]
    for i in range(6):  # hexagon node i faces ring nodes 2i-1, 2i, 2i+1
        r = [7 + (2 * i + k) % 12 for k in (-1, 0, 1)]
        tris += [(1 + i, r[0], r[1]), (1 + i, r[1], r[2]), (1 + i, r[2], 1 + (i + 1) % 6)]
    t = np.array(tris)
    # orient counter-clockwise seen from +z
    n = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])[:, 2]
    t[n < 0] = t[n < 0][:, [0, 2, 1]]
    return Mesh.from_arrays(v, t), h


def test_the_twelve_gon_of_fig_9():
    """Hand-computed values of the masks on 002's example: the boundary is a feature curve refined by the 4-point
    mask (a new node at radius 2·(9 cos 15° − cos 45°)/8 on the polygon's plane), the new node between the centre and
    a lifted node (both regular: the 10-point stencil, whose other eight nodes lie in the plane) at height h/2, and
    the grid's point symmetry kept."""
    mesh, h = _twelve_gon()
    assert len(mesh.triangles) == 24
    r = butterfly_refine(mesh, ButterflyParams(levels=1, feature_angle=60, flat_faces=False))
    out = r.mesh
    assert r.nodes == {"surface": 7, "curve": 12, "vertex": 0}
    assert r.triangles_in["on_feature_curves"] == 12 and r.feature_edges == 12  # the rim's triangles and edges
    new = out.vertices[len(mesh.vertices):]
    radius = np.hypot(new[:, 0], new[:, 1])
    boundary = np.isclose(radius, 2 * (9 * np.cos(np.pi / 12) - np.cos(np.pi / 4)) / 8, atol=1e-12)
    assert boundary.sum() == 12 and np.abs(new[boundary, 2]).max() < 1e-15
    # centre–lifted node: ½(C + H1) + ⅛(H2 + H6) − 1/16(H3 + H5 + R1 + R11), every node but H1 at z = 0
    x = 0.5 + 0.125 * (0.5 + 0.5) - 0.0625 * (-0.5 - 0.5 + 2 * np.sqrt(3))
    hit = np.isclose(new, [x, 0.0, h / 2], atol=1e-12).all(axis=1)
    assert hit.sum() == 1
    # point symmetry: every new node has its mirror −x, −y, −z
    key = lambda p: np.round(p, 9)[np.lexsort(np.round(p, 9).T)]  # noqa: E731
    np.testing.assert_allclose(key(-new), key(new), atol=1e-9)
    assert check_mesh(out).boundary_edges == 24  # the 12-gon's 12 boundary edges split in two


@pytest.mark.parametrize("name", ["voron_hotend_mount_dragon.stl", "voron_vhb_din_mount.stl", "featuretype_inch.stl",
                                  "adis16480_metres.stl"])
def test_corpus_stls_refine_without_new_defects(name):
    """STLs written by others: closed in, closed out; no self-intersection where there was none; 4× the triangles."""
    from tests.conftest import corpus

    stl = read_stl(corpus(name))
    before = check_mesh(stl)
    out = butterfly_refine(stl, ButterflyParams(levels=1)).mesh
    after = check_mesh(out)
    assert out.n_triangles == 4 * stl.n_triangles
    assert after.closed == before.closed and after.boundary_edges == 2 * before.boundary_edges
    assert after.nonmanifold_edges == 2 * before.nonmanifold_edges
    assert self_intersections(stl)[0] == 0 and self_intersections(out)[0] == 0


def test_a_fold_is_undone(monkeypatch):
    """With the height clamp off, the masks fold the slivers of a real STL; the unfolding pass alone undoes it."""
    from amprep.geometry.refine import butterfly
    from tests.conftest import corpus

    stl = read_stl(corpus("adis16480_metres.stl"))
    monkeypatch.setattr(butterfly, "CLAMP", 1e9)
    monkeypatch.setattr(butterfly, "UNFOLD_ROUNDS", -1)  # no unfolding at all: the folds show
    folded = butterfly_refine(stl, ButterflyParams(levels=1)).mesh
    monkeypatch.setattr(butterfly, "UNFOLD_ROUNDS", 6)
    unfolded = butterfly_refine(stl, ButterflyParams(levels=1)).mesh
    assert self_intersections(folded)[0] > 0 and self_intersections(unfolded)[0] == 0
