"""Mesh validity from edge incidence: boundary, non-manifold and misoriented edges, degenerates, shells."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from amprep.geometry.core.edges import EdgeIncidence, edge_incidence
from amprep.geometry.core.mesh import Mesh
from amprep.geometry.core.vectors import cross, group_rows, norms, triangle_normals


def triangle_areas(corners: np.ndarray) -> np.ndarray:
    """(m,) area = |(b − a) × (c − a)| / 2 of (m, 3, 3) corners."""
    return 0.5 * norms(triangle_normals(corners))


def signed_volume(corners: np.ndarray) -> float:
    """V = Σ a · (b × c) / 6 over (m, 3, 3) corners (positive for a closed, outward-oriented mesh)."""
    return float(np.einsum("ij,ij->i", corners[:, 0], cross(corners[:, 1], corners[:, 2])).sum() / 6.0)


@dataclass(frozen=True)
class MeshChecks:
    """Counts from our own edge checks; `closed` = no boundary, non-manifold or misoriented edge."""

    triangles: int
    vertices: int
    boundary_edges: int
    nonmanifold_edges: int
    misoriented_edges: int
    degenerate_triangles: int
    duplicate_triangles: int
    shells: int
    volume: float
    area: float
    inside_out_shells: int = 0  # closed shells of negative volume that no other shell encloses (not cavities)

    @property
    def closed(self) -> bool:
        return self.boundary_edges == 0 and self.nonmanifold_edges == 0 and self.misoriented_edges == 0


#: a triangle of area ≤ this × (bounding-box diagonal)² is degenerate (its height is near float32 resolution)
DEGENERATE_REL_AREA = 1e-12


def degenerate_mask(mesh: Mesh, rel_eps: float = DEGENERATE_REL_AREA, areas: np.ndarray | None = None) -> np.ndarray:
    """(m,) bool: a repeated corner index, or area ≤ rel_eps · (bbox diagonal)² (`areas` (m,): the mesh's
    triangle_areas when already computed)."""
    t = mesh.triangles
    repeated = (t[:, 0] == t[:, 1]) | (t[:, 1] == t[:, 2]) | (t[:, 0] == t[:, 2])
    lo, hi = mesh.bbox()
    scale = float(np.linalg.norm(hi - lo)) or 1.0
    areas = triangle_areas(mesh.corners) if areas is None else areas
    return repeated | (areas <= rel_eps * scale * scale)


def float32_degenerate_count(mesh: Mesh, degenerate: np.ndarray | None = None) -> int:
    """Triangles that are not degenerate but become so once their corners are rounded to float32 (what STL and
    3MF store): the triangle count a reader of the file will call degenerate beyond the in-memory check
    (`degenerate` (m,): the mesh's degenerate_mask when already computed)."""
    if mesh.n_triangles == 0:
        return 0
    rounded = mesh.with_arrays(vertices=mesh.vertices.astype(np.float32).astype(np.float64))
    degenerate = degenerate_mask(mesh) if degenerate is None else degenerate
    return int((degenerate_mask(rounded) & ~degenerate).sum())


def float32_joined(mesh: Mesh, nonmanifold: int = 0) -> tuple[int, int]:
    """(joined, nonmanifold by position): the vertices that share their float32 position (what STL and 3MF store;
    −0.0 is 0.0) with another vertex, less the positions they take, and the edges used by more than two triangles once
    vertices are joined by that position, as a reader that welds a file by position sees them ((0, `nonmanifold`, the
    mesh's own count) when no two vertices share one). The mesh's own checks go by index: two solids that touch stay
    apart there, not in the file. A triangle whose corners the rounding joins stays in the count, as check_mesh counts
    the file read back: one with two corners at one position runs along its third side twice, both ways (a sliver
    whose short side is under float32's step; a reader that drops degenerate facets finds its neighbours closed)."""
    if mesh.n_triangles == 0:
        return 0, nonmanifold
    at, first = group_rows(mesh.vertices.astype(np.float32))
    joined = mesh.n_vertices - len(first)
    if joined == 0:
        return 0, nonmanifold
    return joined, int((edge_incidence(at[mesh.triangles]).count > 2).sum())


def closed_by_position(checks: MeshChecks, nonmanifold_by_position: int) -> bool:
    """Closed by index and still closed once vertices are joined by their float32 position (float32_joined), as a
    reader of an STL (which has no indices) joins them."""
    return checks.closed and nonmanifold_by_position == 0


def shell_labels(mesh: Mesh, inc: EdgeIncidence | None = None) -> tuple[int, np.ndarray]:
    """(number of shells, (m,) label per triangle): triangles joined through shared edges (`inc`: the mesh's edge
    table when already made)."""
    m = mesh.n_triangles
    if m == 0:
        return 0, np.zeros(0, np.int64)
    inc = inc if inc is not None else edge_incidence(mesh.triangles)
    tri = np.repeat(np.arange(m), 3)
    edge = inc.edge_of.reshape(-1)
    graph = coo_matrix((np.ones(len(tri)), (tri, edge + m)), shape=(m + len(inc.edges),) * 2)
    n, labels = connected_components(graph, directed=False)
    labels = labels[:m]
    present = np.zeros(n, bool)
    present[labels] = True
    labels = (np.cumsum(present) - 1)[labels]  # components renumbered 0.. in order, as np.unique would
    return int(labels.max()) + 1, labels


def duplicate_count(triangles: np.ndarray) -> int:
    """Triangles whose vertex set repeats an earlier triangle's: (m, 3) sorted per row, rows sorted (as one int64
    key when the indices allow), equal neighbours counted."""
    if len(triangles) < 2:
        return 0
    srt = np.sort(triangles, axis=1).astype(np.int64)
    n = int(srt.max()) + 1
    if n**3 < 2**62:
        key = np.sort((srt[:, 0] * n + srt[:, 1]) * n + srt[:, 2])
        return int((key[1:] == key[:-1]).sum())
    srt = srt[np.lexsort((srt[:, 2], srt[:, 1], srt[:, 0]))]
    return int((srt[1:] == srt[:-1]).all(axis=1).sum())


def check_mesh(mesh: Mesh, degenerate: np.ndarray | None = None) -> MeshChecks:
    """Edge-incidence checks of a mesh (an edge is identified by its two vertex indices, never by distance);
    `degenerate` (m,) bool, when given, receives the degenerate_mask."""
    if mesh.n_triangles == 0:
        return MeshChecks(0, mesh.n_vertices, 0, 0, 0, 0, 0, 0, 0.0, 0.0)
    inc = edge_incidence(mesh.triangles)
    boundary = int((inc.count == 1).sum())
    nonmanifold = int((inc.count > 2).sum())
    misoriented = int(((inc.count == 2) & (inc.forward != 1)).sum())
    corners = mesh.corners
    areas = triangle_areas(corners)
    mask = degenerate_mask(mesh, areas=areas)
    if degenerate is not None:
        degenerate[:] = mask
    shells, labels = shell_labels(mesh, inc)
    used = np.zeros(max(mesh.n_vertices, int(mesh.triangles.max()) + 1), bool)
    used[mesh.triangles] = True
    return MeshChecks(
        triangles=mesh.n_triangles,
        vertices=int(used.sum()),
        boundary_edges=boundary,
        nonmanifold_edges=nonmanifold,
        misoriented_edges=misoriented,
        degenerate_triangles=int(mask.sum()),
        duplicate_triangles=duplicate_count(mesh.triangles),
        shells=shells,
        volume=signed_volume(corners),
        area=float(areas.sum()),
        inside_out_shells=inside_out_shells(mesh, labels, shells, inc),
    )


#: triangle–point pairs inside_out_shells evaluates at most (past it, an enclosing test left undone counts the shell
#: as inside out: the count is then an upper bound)
WINDING_PAIRS = 20_000_000


def winding_numbers(points: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """(P,) generalised winding number w(p) = Σ Ω_t(p) / 4π of (P, 3) points over (T, 3, 3) triangles, with the
    solid angle tan(Ω/2) = a·(b×c) / (|a||b||c| + (a·b)|c| + (b·c)|a| + (c·a)|b|) (Van Oosterom and Strackee)."""
    out = np.zeros(len(points))
    block = max(1, 2_000_000 // max(len(corners), 1))
    for i in range(0, len(points), block):
        d = corners[None, :, :, :] - points[i:i + block, None, None, :]  # (p, T, 3, 3)
        a, b, c = d[:, :, 0], d[:, :, 1], d[:, :, 2]
        la, lb, lc = (norms(x) for x in (a, b, c))
        num = np.einsum("ptk,ptk->pt", a, cross(b, c))
        den = (la * lb * lc + np.einsum("ptk,ptk->pt", a, b) * lc + np.einsum("ptk,ptk->pt", b, c) * la
               + np.einsum("ptk,ptk->pt", c, a) * lb)
        out[i:i + block] = 2 * np.arctan2(num, den).sum(axis=1) / (4 * np.pi)
    return out


def inside_out_shells(mesh: Mesh, labels: np.ndarray, shells: int, inc: EdgeIncidence) -> int:
    """Closed shells (every edge used twice within the shell) of negative signed volume not enclosed by the rest of
    the mesh (winding number < 1/2 at one of their vertices): a cavity's inner shell is negative by right, a solid
    turned inside out is not."""
    if shells == 0:
        return 0
    corners = mesh.corners
    vol = np.zeros(shells)
    np.add.at(vol, labels, np.einsum("ij,ij->i", corners[:, 0], cross(corners[:, 1], corners[:, 2])) / 6.0)
    open_tri = (inc.count[inc.edge_of] != 2).any(axis=1)
    has_open = np.zeros(shells, bool)
    has_open[labels[open_tri]] = True
    negative = np.flatnonzero((vol < 0) & ~has_open)
    if len(negative) == 0:
        return 0
    lo, hi = np.full((shells, 3), np.inf), np.full((shells, 3), -np.inf)
    flat = corners.reshape(-1, 3)
    np.minimum.at(lo, np.repeat(labels, 3), flat)
    np.maximum.at(hi, np.repeat(labels, 3), flat)
    count, budget = 0, WINDING_PAIRS
    for s in negative.tolist():
        boxed = np.flatnonzero((lo <= lo[s]).all(axis=1) & (hi >= hi[s]).all(axis=1))
        others = np.isin(labels, boxed[boxed != s])
        point = corners[np.flatnonzero(labels == s)[0], 0][None]
        n = int(others.sum())
        if n == 0:
            count += 1
        elif n > budget:
            count += 1  # not tested: counted, so a clean report is never claimed for it
        else:
            budget -= n
            count += int(winding_numbers(point, corners[others])[0] < 0.5)
    return count


def manifold3d_accepts(mesh: Mesh) -> bool:
    """True when manifold3d builds a valid Manifold from the mesh (its own 2-manifold, oriented check)."""
    import manifold3d

    if mesh.n_triangles == 0:
        return False
    m = manifold3d.Mesh(
        vert_properties=np.ascontiguousarray(mesh.vertices, dtype=np.float32),
        tri_verts=np.ascontiguousarray(mesh.triangles, dtype=np.uint32),
    )
    man = manifold3d.Manifold(m)
    return man.status() == manifold3d.Error.NoError
