"""SMA, the thesis's Surface-based Modification Algorithm (3.2.3): every triangle of a chosen face is refined in
the face's (u,v) by a fixed facet pattern; contour edges stay intact, shared inner edges get the same two points
from both sides, so a closed mesh stays closed.

Pattern (ALGORITHMS.md): centroid P_C; per triangle edge P_iP_j one section (P_C, P_i, P_j) with rows
[P_C] · [P_Ci1, P_Cj1] · [P_Ci2, mid, P_Cj2] · edge; Type I (inner edge, two shared edge points at p:q:p) 9
triangles, Type II (contour edge, intact; two interior points at p:q:p between the temporary points at 0.9 of the
spokes) 11 triangles. A triangle with k contour edges gives 27 + 2k triangles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import AmprepError, ErrorCode
from .mesh import IN_FACE, Mesh
from .surfaces import Surface

# Local labels of a section's points.
C, CI1, CJ1, CI2, MID, CJ2, PI, PJ, E1, E2, Q1, Q2 = range(12)
_COMMON = [(C, CI1, CJ1), (CI1, CI2, MID), (CI1, MID, CJ1), (CJ1, MID, CJ2)]
TYPE_I = np.array(_COMMON + [(CI2, PI, E1), (CI2, E1, MID), (MID, E1, E2), (MID, E2, CJ2), (CJ2, E2, PJ)])
TYPE_II = np.array(_COMMON + [(CI2, PI, Q1), (CI2, Q1, MID), (MID, Q1, Q2), (MID, Q2, CJ2), (CJ2, Q2, PJ),
                              (Q1, PI, PJ), (Q1, PJ, Q2)])
TEMPORARY_FRACTION = 0.9  # the thesis's 9:1 temporary points, measured from P_C (ALGORITHMS.md)


@dataclass(frozen=True)
class Ratios:
    """Spoke ratio a:b:c (points at a/(a+b+c) and (a+b)/(a+b+c) from P_C) and edge ratio p:q:p (points at
    p/(2p+q) and (p+q)/(2p+q) along an edge, symmetric so both neighbours put them at the same place)."""

    spoke: tuple[float, float, float] = (3.0, 4.0, 3.0)
    edge: tuple[float, float, float] = (3.0, 4.0, 3.0)

    @classmethod
    def parse(cls, text: str) -> Ratios:
        """'3:4:3,3:4:3' → Ratios; invalid_parameter on anything else."""
        try:
            spoke, edge = (tuple(float(x) for x in part.split(":")) for part in text.split(","))
        except ValueError:
            raise AmprepError(ErrorCode.INVALID_PARAMETER, f"ratios must look like 3:4:3,3:4:3, not {text!r}") from None
        r = cls(spoke, edge)  # type: ignore[arg-type]
        r.validate()
        return r

    def validate(self) -> None:
        if len(self.spoke) != 3 or len(self.edge) != 3 or min(*self.spoke, *self.edge) <= 0:
            raise AmprepError(ErrorCode.INVALID_PARAMETER, "ratios need three positive numbers each: a:b:c,p:q:p")
        if self.edge[0] != self.edge[2]:
            raise AmprepError(ErrorCode.INVALID_PARAMETER, "the edge ratio must be symmetric (p:q:p) so that "
                              "both triangles of an edge put the same points on it")
        if self.spoke_fractions[1] >= TEMPORARY_FRACTION:
            raise AmprepError(ErrorCode.INVALID_PARAMETER, "the spoke ratio must leave an outer band: "
                              f"(a+b)/(a+b+c) < {TEMPORARY_FRACTION}")

    @property
    def spoke_fractions(self) -> tuple[float, float]:
        a, b, c = self.spoke
        return a / (a + b + c), (a + b) / (a + b + c)

    @property
    def edge_fractions(self) -> tuple[float, float]:
        p, q, _ = self.edge
        return p / (2 * p + q), (p + q) / (2 * p + q)


@dataclass(frozen=True, eq=False)
class Refinement:
    """The refined mesh; `categories[f]` triangles of face f by number of contour edges (4,); `parent` (m',) the
    input triangle each output triangle comes from."""

    mesh: Mesh
    categories: dict[int, list[int]]
    parent: np.ndarray


def edge_table(mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """((m, 3) unique-edge id of each triangle edge (corner k → k+1), (E,) bool inner: shared by exactly two
    triangles of the same CAD face, traversed in opposite directions)."""
    t = mesh.triangles
    a, b = t, np.roll(t, -1, axis=1)
    lo, hi = np.minimum(a, b).ravel(), np.maximum(a, b).ravel()
    key = lo * np.int64(mesh.n_vertices) + hi
    uniq, inverse, count = np.unique(key, return_inverse=True, return_counts=True)
    face = np.repeat(mesh.face_ids, 3)
    fmin = np.full(len(uniq), np.iinfo(np.int64).max)
    fmax = np.full(len(uniq), np.iinfo(np.int64).min)
    np.minimum.at(fmin, inverse, face)
    np.maximum.at(fmax, inverse, face)
    forward = np.zeros(len(uniq), np.int64)
    np.add.at(forward, inverse, (a.ravel() < b.ravel()).astype(np.int64))
    inner = (count == 2) & (fmin == fmax) & (fmin >= 0) & (forward == 1)
    return inverse.reshape(-1, 3), inner


def sma_output_size(mesh: Mesh, faces: list[int] | np.ndarray) -> int:
    """Triangles SMA will output: the untouched ones plus 27 + 2k for each chosen triangle with k contour edges."""
    sel = np.isin(mesh.face_ids, np.asarray(faces, dtype=np.int64))
    if not sel.any():
        return mesh.n_triangles
    edge_id, inner = edge_table(mesh)
    k = (~inner[edge_id[sel]]).sum(axis=1)
    return int((~sel).sum() + (27 + 2 * k).sum())


def _nearest_copy(uv: np.ndarray, guess: np.ndarray, periods: tuple[float | None, float | None]) -> np.ndarray:
    """uv shifted by whole periods to lie nearest `guess` (both (N, 2))."""
    out = uv.copy()
    for d, per in enumerate(periods):
        if per:
            out[:, d] += np.round((guess[:, d] - uv[:, d]) / per) * per
    return out


def sma_refine(mesh: Mesh, faces: list[int] | np.ndarray, surfaces: dict[int, Surface],
               ratios: Ratios = Ratios()) -> Refinement:
    """Refine every triangle of `faces` by the SMA pattern; new points are S(u,v) of their face. Needs mesh.uv."""
    ratios.validate()
    if mesh.uv is None:
        raise AmprepError(ErrorCode.INVALID_PARAMETER, "SMA needs the (u,v) of every triangle corner")
    faces = np.unique(np.asarray(faces, dtype=np.int64))
    sel = np.flatnonzero(np.isin(mesh.face_ids, faces))
    edge_id, inner = edge_table(mesh)
    n0 = mesh.n_vertices
    if len(sel) == 0:
        return Refinement(mesh, {}, np.arange(mesh.n_triangles))
    tri = mesh.triangles[sel]
    uv = mesh.uv[sel]
    fid = mesh.face_ids[sel]
    k = len(sel)
    f1, f2 = ratios.spoke_fractions
    e1, e2 = ratios.edge_fractions
    contour = ~inner[edge_id[sel]]  # (k, 3): section s = edge (corner s, corner s+1)

    # New points in (u,v): centroid, spokes (two per corner), mids (one per section), band points (contour sections).
    uc = uv.mean(axis=1)  # (k, 2)
    spoke1 = uc[:, None] + f1 * (uv - uc[:, None])  # (k, 3, 2)
    spoke2 = uc[:, None] + f2 * (uv - uc[:, None])
    mid = 0.5 * (spoke2 + np.roll(spoke2, -1, axis=1))  # section s: between spoke2 of corners s and s+1
    temp = uc[:, None] + TEMPORARY_FRACTION * (uv - uc[:, None])
    tn = np.roll(temp, -1, axis=1)
    band1, band2 = temp + e1 * (tn - temp), temp + e2 * (tn - temp)

    # Shared points on inner edges: one pair per unique edge, placed from its first triangle, lo → hi vertex.
    ei = edge_id[sel]
    uv_next = np.roll(uv, -1, axis=1)
    own1, own2 = uv + e1 * (uv_next - uv), uv + e2 * (uv_next - uv)  # from corner s towards s+1
    forward = tri < np.roll(tri, -1, axis=1)  # corner s is the lower vertex of edge s
    lo_first = np.where(forward[..., None], own1, own2)  # the point at e1 from the lower vertex
    lo_second = np.where(forward[..., None], own2, own1)
    mask = ~contour
    edges_here = ei[mask]
    uniq_edges, first = np.unique(edges_here, return_index=True)
    canon_a, canon_b = lo_first[mask][first], lo_second[mask][first]
    canon_face = np.broadcast_to(fid[:, None], (k, 3))[mask][first]
    edge_slot = np.searchsorted(uniq_edges, ei.clip(min=0))  # valid where mask

    # Vertex numbering: per triangle 1 + 6 + 3 + 2·(contour sections) interior points, then 2 per inner edge.
    n_band = contour.sum(axis=1)
    per_tri = 10 + 2 * n_band
    start = n0 + np.concatenate([[0], np.cumsum(per_tri)[:-1]])
    vc = start
    vs1 = start[:, None] + 1 + np.arange(3)
    vs2 = start[:, None] + 4 + np.arange(3)
    vmid = start[:, None] + 7 + np.arange(3)
    band_rank = np.cumsum(contour, axis=1) - contour  # 0.. among the triangle's contour sections
    vq1 = start[:, None] + 10 + 2 * band_rank
    vq2 = vq1 + 1
    n_tri_points = int(per_tri.sum())
    edge_base = n0 + n_tri_points
    ve_lo = edge_base + 2 * edge_slot
    ve_hi = ve_lo + 1
    ve1 = np.where(forward, ve_lo, ve_hi)  # the edge point at e1 from corner s
    ve2 = np.where(forward, ve_hi, ve_lo)

    # (u,v) of every new vertex, and its face, then S(u,v).
    new_uv = np.empty((n_tri_points + 2 * len(uniq_edges), 2))
    new_face = np.empty(len(new_uv), np.int64)
    rel = lambda v: v - n0  # noqa: E731
    new_uv[rel(vc)] = uc
    new_uv[rel(vs1)] = spoke1
    new_uv[rel(vs2)] = spoke2
    new_uv[rel(vmid)] = mid
    new_uv[rel(vq1[contour])] = band1[contour]
    new_uv[rel(vq2[contour])] = band2[contour]
    new_face[:n_tri_points] = np.repeat(fid, per_tri)
    new_uv[n_tri_points::2] = canon_a
    new_uv[n_tri_points + 1::2] = canon_b
    new_face[n_tri_points:] = np.repeat(canon_face, 2)
    new_xyz = np.empty((len(new_uv), 3))
    for f in np.unique(new_face):
        idx = np.flatnonzero(new_face == f)
        new_xyz[idx] = surfaces[int(f)].evaluate(new_uv[idx])

    # Each triangle's own (u,v) of the shared edge points: the canonical one, moved by whole periods next to its own.
    own_e1 = own1.copy()
    own_e2 = own2.copy()
    for f in np.unique(fid):
        rows, cols = np.nonzero(mask & (fid[:, None] == f))
        per = surfaces[int(f)].periods
        own_e1[rows, cols] = _nearest_copy(new_uv[rel(ve1[rows, cols])], own1[rows, cols], per)
        own_e2[rows, cols] = _nearest_copy(new_uv[rel(ve2[rows, cols])], own2[rows, cols], per)

    # Labels → vertex ids and (u,v), per section (k, 3, 12).
    corner_next = np.roll(np.arange(3), -1)
    lab = np.zeros((k, 3, 12), np.int64)
    lab_uv = np.zeros((k, 3, 12, 2))
    lab[:, :, C], lab_uv[:, :, C] = vc[:, None], uc[:, None]
    lab[:, :, CI1], lab_uv[:, :, CI1] = vs1, spoke1
    lab[:, :, CJ1], lab_uv[:, :, CJ1] = vs1[:, corner_next], spoke1[:, corner_next]
    lab[:, :, CI2], lab_uv[:, :, CI2] = vs2, spoke2
    lab[:, :, CJ2], lab_uv[:, :, CJ2] = vs2[:, corner_next], spoke2[:, corner_next]
    lab[:, :, MID], lab_uv[:, :, MID] = vmid, mid
    lab[:, :, PI], lab_uv[:, :, PI] = tri, uv
    lab[:, :, PJ], lab_uv[:, :, PJ] = tri[:, corner_next], uv[:, corner_next]
    lab[:, :, E1], lab_uv[:, :, E1] = np.where(mask, ve1, -1), own_e1
    lab[:, :, E2], lab_uv[:, :, E2] = np.where(mask, ve2, -1), own_e2
    lab[:, :, Q1], lab_uv[:, :, Q1] = np.where(contour, vq1, -1), band1
    lab[:, :, Q2], lab_uv[:, :, Q2] = np.where(contour, vq2, -1), band2

    out_tris, out_uv, out_parent = [], [], []
    for pattern, which in ((TYPE_I, mask), (TYPE_II, contour)):
        rows, cols = np.nonzero(which)
        ids = lab[rows, cols][:, pattern]  # (s, p, 3)
        uvs = lab_uv[rows, cols][:, pattern]  # (s, p, 3, 2)
        out_tris.append(ids.reshape(-1, 3))
        out_uv.append(uvs.reshape(-1, 3, 2))
        out_parent.append(np.repeat(sel[rows], len(pattern)))

    keep = np.setdiff1d(np.arange(mesh.n_triangles), sel)
    triangles = np.concatenate([mesh.triangles[keep], *out_tris])
    parent = np.concatenate([keep, *out_parent])
    uv_all = np.concatenate([mesh.uv[keep], *out_uv])
    order = np.argsort(parent, kind="stable")  # children where their parent was
    triangles, parent, uv_all = triangles[order], parent[order], uv_all[order]

    n_new = len(new_uv)
    def extend(a: np.ndarray | None, fill: np.ndarray) -> np.ndarray | None:  # noqa: E306
        return None if a is None else np.concatenate([a, fill.astype(a.dtype)])
    refined = Mesh(
        np.concatenate([mesh.vertices, new_xyz]), triangles, mesh.face_ids[parent], uv_all,
        extend(mesh.vertex_dim, np.full(n_new, IN_FACE)), extend(mesh.vertex_entity, new_face),
        extend(mesh.vertex_param, np.full(n_new, np.nan)), mesh.faces)
    categories = {}
    for f in np.unique(fid):
        counts = np.bincount(contour[fid == f].sum(axis=1), minlength=4)
        categories[int(f)] = [int(x) for x in counts]
    return Refinement(refined, categories, parent)
