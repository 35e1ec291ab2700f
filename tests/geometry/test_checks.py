"""The edge table and duplicate count against plain reference implementations, on both of their sort paths."""

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
