"""Read the face meshes BRepMesh made (brepmesh.py) and tie them to the B-rep topology, to weld them through it.

Each face's triangulation is read in bulk; the nodes on a B-rep edge are identified through the edge's
polygon on that face's triangulation (edge index, edge parameter), the nodes on a B-rep vertex through the
vertex, so adjacent faces share vertices by topology, never by distance. Faces OCCT leaves unmeshed, or
meshed inconsistently with their edges, are meshed again from the shared edge discretisation (face_mesher.py).
"""

from __future__ import annotations

import io
from dataclasses import dataclass, field

import numpy as np
from OCP.BinTools import BinTools, BinTools_FormatVersion
from OCP.BRep import BRep_Builder, BRep_Tool
from OCP.TopLoc import TopLoc_Location
from OCP.TopoDS import TopoDS_Compound, TopoDS_Face

from amprep.geometry.cad.topology import Topology, apply_trsf, face_edges, trsf_matrix, winds_inward
from amprep.geometry.core.edges import edge_codes


def triangulation_arrays(tri) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:  # type: ignore[no-untyped-def]
    """nodes (k, 3), uv (k, 2) or None, triangles (t, 3) 0-based, of one Poly_Triangulation (local frame)."""
    k, t = tri.NbNodes(), tri.NbTriangles()
    nodes = np.array([tri.Node(i).Coord() for i in range(1, k + 1)], dtype=float).reshape(k, 3)
    uv = (np.array([tri.UVNode(i).Coord() for i in range(1, k + 1)], dtype=float).reshape(k, 2)
          if tri.HasUVNodes() else None)
    tris = np.array([tri.Triangle(i).Get() for i in range(1, t + 1)], dtype=np.int64).reshape(t, 3) - 1
    return nodes, uv, tris


def bulk_triangulation_arrays(faces: list[TopoDS_Face]) -> list[tuple[np.ndarray, np.ndarray | None, np.ndarray] | None]:
    """triangulation_arrays of every face (None: no triangulation) in one pass through OCCT's binary BREP writer:
    copies of the triangulations on bare faces are written to memory (VERSION_3: int32 node and triangle counts,
    a UV flag byte, the deflection, nodes, (u,v), 1-based triangles; native byte order) and read by np.frombuffer.
    A face whose counts in the stream disagree with its triangulation's is read node by node."""
    tris = [BRep_Tool.Triangulation_s(f, TopLoc_Location()) for f in faces]
    builder, comp = BRep_Builder(), TopoDS_Compound()
    builder.MakeCompound(comp)
    present = [i for i, t in enumerate(tris) if t is not None and t.NbTriangles() > 0]
    for i in present:  # a copy each: the writer keeps one entry per distinct triangulation (instanced solids share)
        f = TopoDS_Face()
        builder.MakeFace(f, tris[i].Copy())
        builder.Add(comp, f)
    buf = io.BytesIO()
    BinTools.Write_s(comp, buf, True, False, BinTools_FormatVersion.BinTools_FormatVersion_VERSION_3)
    data = buf.getbuffer()
    out: list[tuple[np.ndarray, np.ndarray | None, np.ndarray] | None] = [None] * len(faces)
    head = bytes(data[:4096])
    at = head.find(b"\nTriangulations ")
    count = int(head[at + 16:head.index(b"\n", at + 1)]) if at >= 0 else -1
    pos = head.index(b"\n", at + 1) + 1 if at >= 0 else 0
    ok = count == len(present)
    for i in present:
        t = tris[i]
        k, m = t.NbNodes(), t.NbTriangles()
        if ok:
            nn, nt = np.frombuffer(data, "=i4", 2, pos)
            ok = (int(nn), int(nt)) == (k, m) and bool(data[pos + 8]) == t.HasUVNodes()
        if not ok:  # not the layout expected: the slow, exact reader
            out[i] = triangulation_arrays(t)
            continue
        pos += 17
        nodes = np.frombuffer(data, "=f8", 3 * k, pos).reshape(k, 3).copy()
        pos += 24 * k
        uv = None
        if t.HasUVNodes():
            uv = np.frombuffer(data, "=f8", 2 * k, pos).reshape(k, 2).copy()
            pos += 16 * k
        out[i] = nodes, uv, np.frombuffer(data, "=i4", 3 * m, pos).reshape(m, 3).astype(np.int64) - 1
        pos += 12 * m
    del data
    return out


@dataclass
class FacePatch:
    """One face's triangles before welding: local nodes and their topological keys.

    nodes (k, 3) world mm · uv (k, 2) · tris (t, 3) local indices, oriented outward ·
    node_vertex (k,) B-rep vertex index or −1 · node_edge (k,) B-rep edge index or −1 ·
    node_param (k,) parameter on that edge · error (t,) chordal error per triangle, when already measured.
    """

    face_id: int
    nodes: np.ndarray
    uv: np.ndarray | None
    tris: np.ndarray
    node_vertex: np.ndarray
    node_edge: np.ndarray
    node_param: np.ndarray
    meshed_by: str = "occt"
    error: np.ndarray | None = None  # (t,) chordal error per triangle when the mesher already measured it


@dataclass
class PatchRead:
    """What read_patch found on one face, compact enough to send between processes: the keys of its boundary nodes
    (`keys`: node ids, B-rep vertex, B-rep edge, parameter on it, (b,) each; None when the face has no or a broken
    triangulation), each B-rep edge's discretisation (`edges` (e,) indices, `sizes` (e,), `params` (Σ sizes,) in
    the polygons' order), the B-rep vertex pairs BRepMesh collapsed into one node (an edge shorter than its min
    size), and `stored` for a tessellated-only face. `patch`, the assembled FacePatch, and `segments` (s, 2), the
    node pairs along each edge polygon (poles too), stay in its process."""

    face_id: int
    keys: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
    edges: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    sizes: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    params: np.ndarray = field(default_factory=lambda: np.zeros(0))
    merges: list[tuple[int, int]] = field(default_factory=list)
    stored: bool = False
    patch: FacePatch | None = None
    segments: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int64))

    def __getstate__(self) -> dict:  # type: ignore[type-arg]
        return {**self.__dict__, "patch": None, "segments": np.zeros((0, 2), np.int64)}

    def record(self, topo: Topology) -> bool:
        """Add the edges' discretisations (sorted, where topo has none yet) and the collapses to the topology; False
        when an edge already there has other parameters than this face's polygon on it (BRepMesh gave two faces of
        one edge two polygons: the weld, which knows a node by its edge and parameter, could not join them)."""
        ends = np.cumsum(self.sizes)
        agrees = True
        for ei, end, size in zip(self.edges.tolist(), ends.tolist(), self.sizes.tolist(), strict=True):
            params = np.sort(self.params[end - size:end])
            if ei not in topo.edge_params:
                topo.edge_params[ei] = params
            elif not np.array_equal(topo.edge_params[ei], params):
                agrees = False
        for a, b in self.merges:
            topo.merge_vertices(a, b)
        return agrees

    def assemble(self, face: TopoDS_Face, arrays: tuple[np.ndarray, np.ndarray | None, np.ndarray] | None = None
                 ) -> FacePatch | None:
        """The face's FacePatch (kept in `patch`) from its triangulation (`arrays`: its triangulation_arrays when
        read in bulk) and the keys; None when there are no keys."""
        if self.patch is not None or self.keys is None:
            return self.patch
        loc = TopLoc_Location()
        tri = BRep_Tool.Triangulation_s(face, loc)
        arrays = arrays if arrays is not None else triangulation_arrays(tri)
        k = len(arrays[0])
        ids, vertex, edge, param = self.keys
        node_vertex = np.full(k, -1, np.int64)
        node_edge = np.full(k, -1, np.int64)
        node_param = np.full(k, np.nan)
        node_vertex[ids], node_edge[ids], node_param[ids] = vertex, edge, param
        self._set_patch(face, loc, arrays, node_vertex, node_edge, node_param)
        return self.patch

    def _set_patch(self, face: TopoDS_Face, loc: TopLoc_Location,
                   arrays: tuple[np.ndarray, np.ndarray | None, np.ndarray], node_vertex: np.ndarray,
                   node_edge: np.ndarray, node_param: np.ndarray) -> None:
        """`patch` from the face's triangulation arrays (local frame) moved by `loc`, oriented as the face, and the
        node keys (k,) each."""
        nodes, uv, tris = arrays
        if winds_inward(face):
            tris = tris[:, [0, 2, 1]]
        self.patch = FacePatch(self.face_id, apply_trsf(trsf_matrix(loc), nodes), uv, tris, node_vertex, node_edge,
                               node_param, meshed_by="stored" if self.stored else "occt")


def read_patch(face_id: int, face: TopoDS_Face, topo: Topology,
               arrays: tuple[np.ndarray, np.ndarray | None, np.ndarray] | None = None) -> PatchRead:
    """The keys of a face's OCCT triangulation, its patch assembled, leaving `topo`'s discretisations unchanged (so
    faces can be read in any process; PatchRead.record adds what was found). `arrays`: its triangulation_arrays
    when read in bulk. A face with an edge polygon missing, without parameters or out of range gives no keys."""
    loc = TopLoc_Location()
    tri = BRep_Tool.Triangulation_s(face, loc)
    none = PatchRead(face_id)
    if tri is None or tri.NbTriangles() == 0:
        return none
    arrays = arrays if arrays is not None else triangulation_arrays(tri)
    k, tris = len(arrays[0]), arrays[2]
    if tris.min(initial=0) < 0 or tris.max(initial=0) >= k:
        return none
    has_surface = BRep_Tool.Surface_s(face) is not None
    ids: list[int] = []  # 1-based polygon nodes of every edge, one after the other
    par: list[float] = []
    facts, sizes, pole_nodes, pole_vertex, polygon_sizes = [], [], [], [], []
    for edge in face_edges(face):
        poly = BRep_Tool.PolygonOnTriangulation_s(edge, tri, loc)
        if poly is None:
            if not has_surface:  # tessellated-only face: topology is the file's shared coordinates
                continue
            return none
        if not poly.HasParameters():
            return none
        n = poly.NbNodes()
        fact = topo.edge_facts(edge)
        if fact[5]:  # degenerated: a pole, all its nodes on the vertex
            pole_nodes.extend(poly.Node(i) for i in range(1, n + 1))
            pole_vertex.extend([fact[1]] * n)
            polygon_sizes.append(-n)
            continue
        ids.extend([poly.Node(i) for i in range(1, n + 1)])
        par.extend([poly.Parameter(i) for i in range(1, n + 1)])
        facts.append(fact)
        sizes.append(n)
        polygon_sizes.append(n)
    node_ids = np.array(ids, dtype=np.int64) - 1
    poles = np.array(pole_nodes, dtype=np.int64) - 1
    if min(node_ids.min(initial=0), poles.min(initial=0)) < 0 or max(node_ids.max(initial=-1), poles.max(initial=-1)) >= k:
        return none
    node_vertex = np.full(k, -1, np.int64)
    node_edge = np.full(k, -1, np.int64)
    node_param = np.full(k, np.nan)
    params = np.array(par)
    found = PatchRead(face_id, stored=not has_surface)
    found.segments = _polygon_segments(node_ids, poles, np.array(polygon_sizes, dtype=np.int64))
    if facts:
        fa = np.array(facts, dtype=float)
        sizes_a = np.array(sizes, dtype=np.int64)
        node_edge[node_ids] = np.repeat(fa[:, 0].astype(np.int64), sizes_a)
        node_param[node_ids] = params
        last = np.cumsum(sizes_a) - 1
        first = last - sizes_a + 1
        both = np.concatenate([first, last])
        ends = node_ids[both].reshape(2, -1).T  # (edges, 2) end nodes and their parameters
        end_par = params[both].reshape(2, -1).T
        v1, p1, v2, p2 = (fa[:, j:j + 1] for j in range(1, 5))
        end_vertex = np.where(np.abs(end_par - p1) <= np.abs(end_par - p2), v1, v2).astype(np.int64)
        node_vertex[ends.reshape(-1)] = end_vertex.reshape(-1)
        found.edges, found.sizes, found.params = fa[:, 0].astype(np.int64), sizes_a, params
        collapsed = np.flatnonzero((ends[:, 0] == ends[:, 1]) & (fa[:, 1] != fa[:, 3]))  # BRepMesh collapsed an
        found.merges = [(facts[j][1], facts[j][3]) for j in collapsed]  # edge shorter than its min size
    if len(poles):
        node_vertex[poles] = pole_vertex
    keyed = np.flatnonzero((node_vertex >= 0) | (node_edge >= 0))
    found.keys = (keyed, node_vertex[keyed], node_edge[keyed], node_param[keyed])
    found._set_patch(face, loc, arrays, node_vertex, node_edge, node_param)
    return found


def _polygon_segments(node_ids: np.ndarray, poles: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    """(s, 2) the node pairs next to each other in each edge polygon: polygons of `sizes` (p,) nodes, their nodes
    taken in turn from node_ids (size > 0) or from the pole nodes `poles` (size < 0); pairs of one node left out."""
    nodes = np.empty(int(np.abs(sizes).sum()), np.int64)
    on_pole = np.repeat(sizes < 0, np.abs(sizes))
    nodes[~on_pole], nodes[on_pole] = node_ids, poles
    last = np.cumsum(np.abs(sizes)) - 1  # the last node of each polygon pairs with the next polygon's first: no pair
    pairs = np.stack([nodes[:-1], nodes[1:]], axis=1)
    keep = np.ones(len(pairs), bool)
    keep[last[:-1]] = False
    pairs = pairs[keep]
    return pairs[pairs[:, 0] != pairs[:, 1]]


def extract_patch(face_id: int, face: TopoDS_Face, topo: Topology,
                  arrays: tuple[np.ndarray, np.ndarray | None, np.ndarray] | None = None) -> FacePatch | None:
    """read_patch, with what it found recorded in `topo`: the face's patch, or None when it has no or a broken
    triangulation."""
    found = read_patch(face_id, face, topo, arrays)
    found.record(topo)
    return found.patch


def off_boundary_edges(patch: FacePatch, segments: np.ndarray | None = None) -> np.ndarray:
    """(e, 2) node pairs that break the patch's boundary: sides used by one triangle only that are not a segment of an
    edge polygon (`segments` (s, 2), PatchRead.segments; without them, those with an end on neither a B-rep edge nor
    a vertex), and segments no triangle uses. None in a sound patch: its boundary is its edges' discretisation."""
    t, base = patch.tris, len(patch.nodes) + 1
    a, b = t.reshape(-1), t[:, [1, 2, 0]].reshape(-1)  # the directed edges (a → b) of every triangle
    key = np.stack([np.minimum(a, b), np.maximum(a, b)], axis=1)
    codes, inv, cnt = np.unique(edge_codes(t, base).reshape(-1), return_inverse=True, return_counts=True)
    once = key[cnt[inv.reshape(-1)] == 1]
    if segments is None:
        on_boundary = (patch.node_edge >= 0) | (patch.node_vertex >= 0)
        return once[~on_boundary[once].all(axis=1)]
    seg = np.sort(segments, axis=1)
    seg_codes = seg[:, 0] * base + seg[:, 1]
    once_codes = once[:, 0] * base + once[:, 1]
    return np.concatenate([once[~np.isin(once_codes, seg_codes)], seg[~np.isin(seg_codes, codes)]])


def check_patch_boundary(patch: FacePatch, segments: np.ndarray | None = None) -> bool:
    """True when the patch's boundary is its B-rep edges' discretisation (off_boundary_edges finds nothing)."""
    return len(off_boundary_edges(patch, segments)) == 0
