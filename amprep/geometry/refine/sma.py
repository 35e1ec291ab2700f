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

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.cad.surfaces import Surface, nearest_copy, project_points, tangents
from amprep.geometry.core.edges import face_edge_table
from amprep.geometry.core.mesh import IN_FACE, Mesh
from amprep.geometry.core.progress import checkpoint
from amprep.geometry.core.vectors import cross, norms, triangle_normals

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


def sma_output_size(mesh: Mesh, faces: list[int] | np.ndarray) -> int:
    """Triangles SMA will output: the untouched ones plus 27 + 2k for each chosen triangle with k contour edges."""
    sel = np.isin(mesh.face_ids, np.asarray(faces, dtype=np.int64))
    if not sel.any():
        return mesh.n_triangles
    edge_id, inner = face_edge_table(mesh)
    k = (~inner[edge_id[sel]]).sum(axis=1)
    return int((~sel).sum() + (27 + 2 * k).sum())


def sma_refine(mesh: Mesh, faces: list[int] | np.ndarray, surfaces: dict[int, Surface],
               ratios: Ratios = Ratios()) -> Refinement:
    """Refine every triangle of `faces` by the SMA pattern; new points are S(u,v) of their face. Needs mesh.uv."""
    ratios.validate()
    if mesh.uv is None:
        raise AmprepError(ErrorCode.INVALID_PARAMETER, "SMA needs the (u,v) of every triangle corner")
    faces = np.unique(np.asarray(faces, dtype=np.int64))
    sel = np.flatnonzero(np.isin(mesh.face_ids, faces))
    edge_id, inner = face_edge_table(mesh)
    if len(sel) == 0:
        return Refinement(mesh, {}, np.arange(mesh.n_triangles))
    s = _Sections(mesh.triangles[sel], mesh.uv[sel], mesh.face_ids[sel], edge_id[sel], ~inner[edge_id[sel]], ratios)
    ids = _Numbering.of(s, mesh.n_vertices)
    new_uv, new_face, new_xyz, out_tris, out_uv, out_rows = _build(s, ids, surfaces)
    folded = _turned_over(np.concatenate([mesh.vertices, new_xyz]), out_tris, out_rows, mesh.vertices[s.tri])
    folded &= ~_at_a_pole(s, surfaces)  # an apex's corner has a (u,v) of its triangle's choosing: space decides none
    if folded.any():  # where (u,v) shears across a triangle: its face's new points placed in space, then projected
        _place_in_space(s, np.isin(s.fid, s.fid[folded]), mesh.vertices, surfaces)
        new_uv, new_face, new_xyz, out_tris, out_uv, out_rows = _build(s, ids, surfaces)
    out_parent = [sel[rows] for rows in out_rows]

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
    for f in np.unique(s.fid):
        counts = np.bincount(s.contour[s.fid == f].sum(axis=1), minlength=4)
        categories[int(f)] = [int(x) for x in counts]
    return Refinement(refined, categories, parent)


def _build(s: _Sections, ids: _Numbering, surfaces: dict[int, Surface]) -> tuple[
        np.ndarray, np.ndarray, np.ndarray, list[np.ndarray], list[np.ndarray], list[np.ndarray]]:
    """The new points' (u,v) (n, 2), face (n,) and S(u,v) (n, 3), and the children: per pattern (Type I, Type II)
    their triangles (c, 3), their corners' (u,v) (c, 3, 2) and the section row each comes from (c,)."""
    new_uv, new_face = ids.new_points(s)
    new_xyz = np.empty((len(new_uv), 3))
    for f in np.unique(new_face):
        idx = np.flatnonzero(new_face == f)
        new_xyz[idx] = surfaces[int(f)].evaluate(new_uv[idx])
    lab, lab_uv = _labels(s, ids, new_uv, surfaces)
    out_tris, out_uv, out_rows = [], [], []
    for pattern, which in ((TYPE_I, ~s.contour), (TYPE_II, s.contour)):
        rows, cols = np.nonzero(which)
        out_tris.append(lab[rows, cols][:, pattern].reshape(-1, 3))  # (s, p, 3)
        out_uv.append(lab_uv[rows, cols][:, pattern].reshape(-1, 3, 2))  # (s, p, 3, 2)
        out_rows.append(np.repeat(rows, len(pattern)))
    return new_uv, new_face, new_xyz, out_tris, out_uv, out_rows


def _turned_over(xyz: np.ndarray, out_tris: list[np.ndarray], out_rows: list[np.ndarray],
                 parents: np.ndarray) -> np.ndarray:
    """(k,) bool: the chosen triangles (corners (k, 3, 3)) with a child turned over against them in space."""
    n = triangle_normals(parents)
    folded = np.zeros(len(parents), bool)
    for tris, rows in zip(out_tris, out_rows, strict=True):
        c = xyz[tris]
        d = np.einsum("ij,ij->i", triangle_normals(c), n[rows])
        folded[rows[d < 0]] = True
    return folded


def _at_a_pole(s: _Sections, surfaces: dict[int, Surface]) -> np.ndarray:
    """(k,) bool: the chosen triangles with a corner where S_u × S_v vanishes (a pole or apex)."""
    out = np.zeros(len(s.tri), bool)
    for f in np.unique(s.fid):
        k = np.flatnonzero(s.fid == f)
        su, sv = tangents(surfaces[int(f)], s.uv[k].reshape(-1, 2))
        size = norms(cross(su, sv))
        scale = norms(su) * norms(sv)
        out[k] = (size <= 1e-6 * scale + 1e-300).reshape(-1, 3).any(axis=1)
    return out


def _place_in_space(s: _Sections, rows: np.ndarray, vertices: np.ndarray, surfaces: dict[int, Surface]) -> None:
    """Place the new points of the sections' rows (k,) bool, whole faces, in space and project them onto the surface
    (surfaces.project_points, from their (u,v)): a triangle's own points (centroid, spoke, middle and band points) at
    the barycentric coordinates they have in (u,v), on the corners; the two points of an inner edge at the edge
    fractions of its chord, once per edge (canon_a, canon_b), so both its triangles take the same."""
    edges = np.isin(s.canon_face, s.fid[rows])
    r = np.flatnonzero(rows)
    a, b, c = s.uv[r, 0], s.uv[r, 1], s.uv[r, 2]
    m = np.stack([b - a, c - a], axis=2)  # (k, 2, 2): columns b − a, c − a
    det = m[:, 0, 0] * m[:, 1, 1] - m[:, 0, 1] * m[:, 1, 0]
    flat = np.abs(det) <= 1e-12 * np.abs(m).max(axis=(1, 2)) ** 2  # no area in (u,v), at a pole: points stay put
    r, a, m = r[~flat], a[~flat], m[~flat]
    corners = vertices[s.tri[r]]
    for name in ("uc", "spoke1", "spoke2", "mid", "band1", "band2"):
        arr = getattr(s, name)
        q = arr[r].reshape(len(r), -1, 2)  # (k, p, 2): p = 1 for the centroid, 3 for the others
        lam = np.linalg.solve(m[:, None], (q - a[:, None])[..., None])[..., 0]  # (k, p, 2)
        bary = np.concatenate([1 - lam.sum(axis=2, keepdims=True), lam], axis=2)  # (k, p, 3)
        arr[r] = _projected(np.einsum("kpj,kjd->kpd", bary, corners), q, s.fid[r], surfaces).reshape(arr[r].shape)
    lo, hi = vertices[s.canon_lo[edges]], vertices[s.canon_hi[edges]]
    for name, frac in zip(("canon_a", "canon_b"), s.edge_fractions, strict=True):
        arr = getattr(s, name)
        arr[edges] = _projected((lo + frac * (hi - lo))[:, None], arr[edges][:, None], s.canon_face[edges],
                                surfaces)[:, 0]


def _projected(target: np.ndarray, uv0: np.ndarray, fid: np.ndarray, surfaces: dict[int, Surface]) -> np.ndarray:
    """(k, p, 2) (u,v) of the surface points nearest target (k, p, 3), row i on face fid[i], from uv0 (k, p, 2)."""
    out = uv0.copy()
    for f in np.unique(fid):
        checkpoint()
        k = fid == f
        out[k] = project_points(surfaces[int(f)], target[k].reshape(-1, 3), uv0[k].reshape(-1, 2))[0].reshape(
            uv0[k].shape)
    return out


class _Sections:
    """The (u,v) of a chosen triangle's new points, per section s = edge (corner s, corner s+1), arrays (k, 3, 2):
    centroid uc (k, 2), spoke1/spoke2 on the spokes, mid, band1/band2 (contour sections), own1/own2 on its edge at
    the edge fractions from corner s; and, per unique inner edge, its two shared points placed from its first
    triangle, lo → hi vertex (canon_a, canon_b, canon_face, edge_slot: each section's edge in that order)."""

    def __init__(self, tri: np.ndarray, uv: np.ndarray, fid: np.ndarray, ei: np.ndarray, contour: np.ndarray,
                 ratios: Ratios) -> None:
        self.tri, self.uv, self.fid, self.contour = tri, uv, fid, contour
        k = len(tri)
        f1, f2 = ratios.spoke_fractions
        e1, e2 = ratios.edge_fractions
        self.uc = uc = uv.mean(axis=1)
        self.spoke1 = uc[:, None] + f1 * (uv - uc[:, None])
        self.spoke2 = uc[:, None] + f2 * (uv - uc[:, None])
        self.mid = 0.5 * (self.spoke2 + np.roll(self.spoke2, -1, axis=1))  # between spoke2 of corners s and s+1
        temp = uc[:, None] + TEMPORARY_FRACTION * (uv - uc[:, None])
        tn = np.roll(temp, -1, axis=1)
        self.band1, self.band2 = temp + e1 * (tn - temp), temp + e2 * (tn - temp)
        uv_next = np.roll(uv, -1, axis=1)
        self.own1, self.own2 = uv + e1 * (uv_next - uv), uv + e2 * (uv_next - uv)  # from corner s towards s+1
        self.forward = tri < np.roll(tri, -1, axis=1)  # corner s is the lower vertex of edge s
        lo_first = np.where(self.forward[..., None], self.own1, self.own2)  # the point at e1 from the lower vertex
        lo_second = np.where(self.forward[..., None], self.own2, self.own1)
        mask = ~contour
        self.uniq_edges, first = np.unique(ei[mask], return_index=True)
        self.canon_a, self.canon_b = lo_first[mask][first], lo_second[mask][first]
        tri_next = np.roll(tri, -1, axis=1)
        self.canon_lo = np.minimum(tri, tri_next)[mask][first]
        self.canon_hi = np.maximum(tri, tri_next)[mask][first]
        self.edge_fractions = (e1, e2)
        self.canon_face = np.broadcast_to(fid[:, None], (k, 3))[mask][first]
        self.edge_slot = np.searchsorted(self.uniq_edges, ei.clip(min=0))  # valid where mask


@dataclass(frozen=True)
class _Numbering:
    """New vertex ids: per triangle 1 + 6 + 3 + 2·(contour sections) interior points from n0 on (vc (k,), vs1, vs2,
    vmid, vq1, vq2 (k, 3)), then 2 per inner edge (ve1, ve2 (k, 3): the edge point at e1 / e2 from corner s)."""

    n0: int
    per_tri: np.ndarray
    vc: np.ndarray
    vs1: np.ndarray
    vs2: np.ndarray
    vmid: np.ndarray
    vq1: np.ndarray
    vq2: np.ndarray
    ve1: np.ndarray
    ve2: np.ndarray

    @classmethod
    def of(cls, s: _Sections, n0: int) -> _Numbering:
        per_tri = 10 + 2 * s.contour.sum(axis=1)
        start = n0 + np.concatenate([[0], np.cumsum(per_tri)[:-1]])
        band_rank = np.cumsum(s.contour, axis=1) - s.contour  # 0.. among the triangle's contour sections
        vq1 = start[:, None] + 10 + 2 * band_rank
        ve_lo = n0 + int(per_tri.sum()) + 2 * s.edge_slot
        ve_hi = ve_lo + 1
        return cls(n0, per_tri, start, start[:, None] + 1 + np.arange(3), start[:, None] + 4 + np.arange(3),
                   start[:, None] + 7 + np.arange(3), vq1, vq1 + 1,
                   np.where(s.forward, ve_lo, ve_hi), np.where(s.forward, ve_hi, ve_lo))

    def new_points(self, s: _Sections) -> tuple[np.ndarray, np.ndarray]:
        """((n_new, 2) (u,v), (n_new,) face) of every new vertex, by id − n0."""
        n_tri_points = int(self.per_tri.sum())
        new_uv = np.empty((n_tri_points + 2 * len(s.uniq_edges), 2))
        new_face = np.empty(len(new_uv), np.int64)
        n0 = self.n0
        new_uv[self.vc - n0] = s.uc
        new_uv[self.vs1 - n0] = s.spoke1
        new_uv[self.vs2 - n0] = s.spoke2
        new_uv[self.vmid - n0] = s.mid
        new_uv[self.vq1[s.contour] - n0] = s.band1[s.contour]
        new_uv[self.vq2[s.contour] - n0] = s.band2[s.contour]
        new_face[:n_tri_points] = np.repeat(s.fid, self.per_tri)
        new_uv[n_tri_points::2] = s.canon_a
        new_uv[n_tri_points + 1::2] = s.canon_b
        new_face[n_tri_points:] = np.repeat(s.canon_face, 2)
        return new_uv, new_face


def _labels(s: _Sections, ids: _Numbering, new_uv: np.ndarray,
            surfaces: dict[int, Surface]) -> tuple[np.ndarray, np.ndarray]:
    """Each section's 12 labelled points as vertex ids (k, 3, 12) (−1: absent) and the triangle's own (u,v) of them
    (k, 3, 12, 2); a shared edge point's (u,v) is the canonical one moved by whole periods next to the triangle's own."""
    mask = ~s.contour
    own_e1, own_e2 = s.own1.copy(), s.own2.copy()
    for f in np.unique(s.fid):
        checkpoint()
        rows, cols = np.nonzero(mask & (s.fid[:, None] == f))
        per = surfaces[int(f)].periods
        own_e1[rows, cols] = nearest_copy(new_uv[ids.ve1[rows, cols] - ids.n0], s.own1[rows, cols], per)
        own_e2[rows, cols] = nearest_copy(new_uv[ids.ve2[rows, cols] - ids.n0], s.own2[rows, cols], per)
    k = len(s.tri)
    nxt = np.roll(np.arange(3), -1)
    lab = np.zeros((k, 3, 12), np.int64)
    lab_uv = np.zeros((k, 3, 12, 2))
    lab[:, :, C], lab_uv[:, :, C] = ids.vc[:, None], s.uc[:, None]
    lab[:, :, CI1], lab_uv[:, :, CI1] = ids.vs1, s.spoke1
    lab[:, :, CJ1], lab_uv[:, :, CJ1] = ids.vs1[:, nxt], s.spoke1[:, nxt]
    lab[:, :, CI2], lab_uv[:, :, CI2] = ids.vs2, s.spoke2
    lab[:, :, CJ2], lab_uv[:, :, CJ2] = ids.vs2[:, nxt], s.spoke2[:, nxt]
    lab[:, :, MID], lab_uv[:, :, MID] = ids.vmid, s.mid
    lab[:, :, PI], lab_uv[:, :, PI] = s.tri, s.uv
    lab[:, :, PJ], lab_uv[:, :, PJ] = s.tri[:, nxt], s.uv[:, nxt]
    lab[:, :, E1], lab_uv[:, :, E1] = np.where(mask, ids.ve1, -1), own_e1
    lab[:, :, E2], lab_uv[:, :, E2] = np.where(mask, ids.ve2, -1), own_e2
    lab[:, :, Q1], lab_uv[:, :, Q1] = np.where(s.contour, ids.vq1, -1), s.band1
    lab[:, :, Q2], lab_uv[:, :, Q2] = np.where(s.contour, ids.vq2, -1), s.band2
    return lab, lab_uv
