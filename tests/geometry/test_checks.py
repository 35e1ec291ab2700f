"""The edge table and duplicate count against plain reference implementations, on both of their sort paths."""

import subprocess
import sys

import numpy as np
import pytest

from amprep.geometry.core.checks import duplicate_count
from amprep.geometry.core.edges import edge_incidence


def _reference_incidence(t):
    sides = [(t[i, k], t[i, (k + 1) % 3]) for i in range(len(t)) for k in range(3)]
    keys = sorted({(min(a, b), max(a, b)) for a, b in sides})
    index = {e: j for j, e in enumerate(keys)}
    count = np.zeros(len(keys), np.int64)
    forward = np.zeros(len(keys), np.int64)
    edge_of = np.zeros((len(t), 3), np.int64)
    for n, (a, b) in enumerate(sides):
        j = index[(min(a, b), max(a, b))]
        count[j] += 1
        forward[j] += a < b
        edge_of[n // 3, n % 3] = j
    return np.array(keys, np.int64).reshape(-1, 2), count, forward, edge_of


@pytest.mark.parametrize("offset", [0, 10**9], ids=["packed_sort", "argsort"])
def test_edge_incidence_matches_a_plain_count(offset):
    """Random triangles (repeated edges, both directions, isolated ones); vertex ids near 1e9 take the argsort path
    (key × position would overflow int64)."""
    rng = np.random.default_rng(7)
    t = rng.integers(0, 12, size=(40, 3)) + offset
    inc = edge_incidence(t)
    edges, count, forward, edge_of = _reference_incidence(t)
    assert np.array_equal(inc.edges, edges) and np.array_equal(inc.count, count)
    assert np.array_equal(inc.forward, forward) and np.array_equal(inc.edge_of, edge_of)


@pytest.mark.parametrize("offset", [0, 2 * 10**6], ids=["packed_sort", "lexsort"])
def test_duplicate_count_counts_repeated_vertex_sets_in_any_order(offset):
    t = np.array([[0, 1, 2], [2, 0, 1], [1, 0, 2], [0, 1, 3], [3, 1, 0], [4, 5, 6]]) + offset
    assert duplicate_count(t) == 3
    assert duplicate_count(t[[0, 3, 5]]) == 0


def _box(lo, hi, outward=True):
    """(8, 3) corners and (12, 3) triangles of an axis-aligned box, wound outward (or inward)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    v = np.array([[(hi if (i >> k) & 1 else lo)[k] for k in range(3)] for i in range(8)])
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    t = np.array([tri for a, b, c, d in quads for tri in ((a, b, c), (a, c, d))])
    return v, (t if outward else t[:, [0, 2, 1]])


def _mesh(*boxes):
    from amprep.geometry.core.mesh import Mesh

    verts, tris, n = [], [], 0
    for v, t in boxes:
        verts.append(v)
        tris.append(t + n)
        n += len(v)
    return Mesh.from_arrays(np.concatenate(verts), np.concatenate(tris))


@pytest.mark.parametrize("boxes, expected", [
    ([((0, 0, 0), (1, 1, 1), True)], 0),
    ([((0, 0, 0), (1, 1, 1), False)], 1),
    ([((0, 0, 0), (4, 4, 4), True), ((1, 1, 1), (2, 2, 2), False)], 0),  # a cavity
    ([((0, 0, 0), (4, 4, 4), True), ((5, 1, 1), (6, 2, 2), False)], 1),  # beside, not inside
    ([((0, 0, 0), (4, 4, 4), False), ((1, 1, 1), (2, 2, 2), False)], 2),  # an inverted solid holding an inverted one
], ids=["box", "inverted", "cavity", "inverted_beside", "nested_inverted"])
def test_inside_out_shells_tells_a_cavity_from_an_inverted_solid(boxes, expected):
    from amprep.geometry.core.checks import check_mesh

    checks = check_mesh(_mesh(*(_box(lo, hi, out) for lo, hi, out in boxes)))
    assert checks.closed and checks.inside_out_shells == expected


def test_winding_number_of_a_box_is_one_inside_and_zero_outside():
    from amprep.geometry.core.checks import winding_numbers

    v, t = _box((0, 0, 0), (2, 3, 4))
    w = winding_numbers(np.array([[1, 1, 1], [1.9, 2.9, 3.9], [3, 1, 1], [-1, -1, -1]], float), v[t])
    assert np.allclose(w, [1, 1, 0, 0], atol=1e-9)


def _nonmanifold_by_position(path):
    """Sides of a binary STL's facets used more than twice, its corners joined by their float32 position: counted in
    plain Python, not by our checks."""
    corners = np.frombuffer(path.read_bytes()[84:], np.dtype([("n", "<f4", 3), ("c", "<f4", (3, 3)), ("a", "<u2")]))["c"]
    sides: dict = {}
    for tri in corners:
        keys = [tuple(p) for p in tri.tolist()]
        for k in range(3):
            side = frozenset((keys[k], keys[(k + 1) % 3]))
            sides[side] = sides.get(side, 0) + 1
    return sum(n > 2 for n in sides.values())


def test_solids_that_touch_are_apart_by_index_and_joined_in_the_file():
    """Two unit cubes face to face, the second moved 2e-8 mm along x (its corners on the shared face distinct from the
    first's in float64, one float32 position each): by index two closed shells; a reader that joins the file's
    vertices by position sees the shared face's four sides and its diagonal used by four triangles each."""
    from amprep.geometry.core.checks import check_mesh, float32_joined

    a, b = _box((0, 0, 0), (1, 1, 1)), _box((1, 0, 0), (2, 1, 1))
    touching = _mesh(a, (b[0] + [2e-8, 0, 0], b[1]))
    assert check_mesh(touching).closed and check_mesh(touching).nonmanifold_edges == 0
    assert float32_joined(touching) == (4, 5)
    apart = _mesh(a, (b[0] + 1e-3, b[1]))
    assert float32_joined(apart) == (0, 0)


def test_a_corner_written_as_minus_zero_is_joined_to_zero_as_the_file_read_back_joins_it(tmp_path):
    """Two unit cubes face to face at x = 0, the second's corners there written −0.0: by index two closed shells; in
    the file −0.0 and 0.0 are one position to a reader (read_stl, and the plain-Python count, where −0.0 == 0.0), so
    the shared face's four sides and its diagonal are used by four triangles each."""
    from amprep.geometry.core.checks import check_mesh, float32_joined
    from amprep.geometry.io.stl import read_stl, write_stl

    a, b = _box((-1, 0, 0), (0, 1, 1)), _box((0, 0, 0), (1, 1, 1))
    bv = b[0].copy()
    bv[bv[:, 0] == 0, 0] = -0.0
    mesh = _mesh(a, (bv, b[1]))
    assert np.signbit(mesh.vertices[:, 0]).sum() == 4 + 4  # a's four at −1 and b's four at −0.0
    checks = check_mesh(mesh)
    assert checks.closed and checks.nonmanifold_edges == 0
    write_stl(mesh, tmp_path / "z.stl")
    assert float32_joined(mesh, 0) == (4, 5) == (4, _nonmanifold_by_position(tmp_path / "z.stl"))
    assert check_mesh(read_stl(tmp_path / "z.stl")).nonmanifold_edges == 5


def test_slivers_the_float32_rounding_collapses_are_counted_as_the_file_read_back_has_them(tmp_path):
    """A box at 100 mm whose bottom edge is split 1e-7 mm from a corner (under float32's step there): closed by index;
    in the file the split point is the corner, and each of the two slivers beside it runs along one side twice. The
    count by position is what the written STL holds, counted in plain Python, and what check_mesh reads back."""
    from amprep.geometry.core.checks import check_mesh, closed_by_position, float32_joined
    from amprep.geometry.core.mesh import Mesh
    from amprep.geometry.io.stl import read_stl, write_stl

    v, t = _box((100, 100, 100), (101, 101, 101))
    split = np.vstack([v, v[0] + [1e-7, 0, 0]])  # on the edge v0–v1, a vertex of its own
    rows = []
    for tri in t.tolist():
        k = next((k for k in range(3) if {tri[k], tri[(k + 1) % 3]} == {0, 1}), None)
        if k is None:
            rows.append(tri)
            continue
        x, y, c = tri[k], tri[(k + 1) % 3], tri[(k + 2) % 3]  # side x → y on edge 0–1: cut at vertex 8
        rows += [[x, 8, c], [8, y, c]]
    mesh = Mesh.from_arrays(split, np.array(rows))
    checks = check_mesh(mesh)
    assert checks.closed and checks.degenerate_triangles == 0
    joined, by_position = float32_joined(mesh, checks.nonmanifold_edges)
    write_stl(mesh, tmp_path / "s.stl")
    assert joined == 1 and by_position == _nonmanifold_by_position(tmp_path / "s.stl") == 2
    assert check_mesh(read_stl(tmp_path / "s.stl")).nonmanifold_edges == by_position
    assert not closed_by_position(checks, by_position)



def test_convert_notes_what_a_reader_joining_by_position_sees(tmp_path, touching_step):
    """Two boxes of one STEP face to face: meshed apart (closed by index, each its own B-rep edges), their shared
    face's nodes at one position; convert says what a reader that joins by position sees."""
    import cadquery as cq

    from amprep.jobs.convert import convert, write_result

    path = touching_step
    r = convert(path)
    assert r.checks.closed and r.checks.shells == 2
    assert any("float32 position" in n and "non-manifold" in n for n in r.notes), r.notes
    mesh = r.summary()["mesh"]
    assert mesh["closed_by_edges"] and not mesh["closed_by_position"]
    assert mesh["float32_joined_vertices"] > 0 and mesh["nonmanifold_edges_by_position"] > 0
    # the file read back and joined by position in plain Python (not our checks): edges used by more than two
    out = tmp_path / "touching.stl"
    write_result(r, out)
    assert _nonmanifold_by_position(out) == mesh["nonmanifold_edges_by_position"]
    said = subprocess.run([sys.executable, "-m", "amprep", "convert", str(path), "-o", str(tmp_path / "cli.stl")],
                          capture_output=True, encoding="utf-8", errors="replace", timeout=300)
    assert said.returncode == 0 and "closed by index" in said.stdout, said.stdout + said.stderr
    one = tmp_path / "one.step"
    cq.exporters.export(cq.Workplane().box(10, 10, 10), str(one))
    alone = convert(one).summary()["mesh"]
    assert alone["closed_by_position"] and alone["float32_joined_vertices"] == 0
