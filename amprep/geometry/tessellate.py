"""Read the face meshes BRepMesh made (brepmesh.py) and tie them to the B-rep topology, to weld them through it.

Each face's triangulation is read in bulk; the nodes on a B-rep edge are identified through the edge's
polygon on that face's triangulation (edge index, edge parameter), the nodes on a B-rep vertex through the
vertex, so adjacent faces share vertices by topology, never by distance. Faces OCCT leaves unmeshed, or
meshed inconsistently with their edges, are meshed again from the shared edge discretisation (fallback.py).
"""

from __future__ import annotations

import io
from dataclasses import dataclass, field

import numpy as np
from OCP.BinTools import BinTools, BinTools_FormatVersion
from OCP.BRep import BRep_Builder, BRep_Tool
from OCP.TopAbs import TopAbs_EDGE, TopAbs_FORWARD, TopAbs_REVERSED, TopAbs_VERTEX
from OCP.TopExp import TopExp, TopExp_Explorer
from OCP.TopLoc import TopLoc_Location
from OCP.TopoDS import TopoDS, TopoDS_Compound, TopoDS_Edge, TopoDS_Face, TopoDS_Shape
from OCP.TopTools import TopTools_IndexedMapOfShape

from .errors import AmprepError, ErrorCode


@dataclass(frozen=True)
class MeshParams:
    """Meshing parameters: `tolerance` mm (absolute chord deviation) or `relative` (fraction of the bounding-box
    diagonal, overrides tolerance), `angular` rad (the largest turn of one edge segment), `min_size` mm, `algorithm`
    delabella | watson."""

    tolerance: float = 0.1
    relative: float | None = None
    angular: float = 0.5
    min_size: float = 0.0
    algorithm: str = "delabella"
    parallel: bool = True
    enforce_tolerance: bool = True
    force_fallback: bool = False
    sample_order: int = 6
    occt_edges: bool = False  # every edge at half the tolerance and angle, as BRepMesh does (brepmesh.py)
    own_large_faces: bool = True  # mesh large torus faces ourselves, not with BRepMesh (own_faces.py)
    occt_surface_control: bool = False  # OCCT's own deflection check of face interiors (ours replaces it)

    def validate(self) -> None:
        """Raise invalid_parameter for values no mesher can honour."""
        bad = None
        if not (self.tolerance > 0 and np.isfinite(self.tolerance)):
            bad = f"tolerance must be a positive number of mm, got {self.tolerance}"
        elif self.relative is not None and not (0 < self.relative < 1):
            bad = f"relative tolerance must be a fraction in (0, 1), got {self.relative}"
        elif not (0 < self.angular <= np.pi / 2):
            bad = f"angular deflection must be in (0, π/2] rad, got {self.angular}"
        elif self.min_size < 0:
            bad = f"min size must be ≥ 0, got {self.min_size}"
        elif self.algorithm not in ("delabella", "watson"):
            bad = f"algorithm must be delabella or watson, got {self.algorithm}"
        elif not (1 <= self.sample_order <= 20):
            bad = f"sample order must be 1..20, got {self.sample_order}"
        if bad:
            raise AmprepError(ErrorCode.INVALID_PARAMETER, bad)


def trsf_matrix(loc: TopLoc_Location) -> np.ndarray | None:
    """(3, 4) affine matrix of a location, or None for the identity."""
    if loc.IsIdentity():
        return None
    t = loc.Transformation()
    return np.array([[t.Value(r, c) for c in range(1, 5)] for r in range(1, 4)])


def apply_trsf(m: np.ndarray | None, pts: np.ndarray) -> np.ndarray:
    """(N, 3) points moved by a (3, 4) affine matrix (None: unchanged)."""
    return pts if m is None else pts @ m[:, :3].T + m[:, 3]


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
class Topology:
    """Indexed B-rep edges and vertices of a shape, and each edge's discretisation (sorted parameters)."""

    edges: TopTools_IndexedMapOfShape
    vertices: TopTools_IndexedMapOfShape
    edge_params: dict[int, np.ndarray] = field(default_factory=dict)
    parent: dict[int, int] = field(default_factory=dict)  # union-find over B-rep vertices of collapsed edges
    _facts: dict[int, tuple[int, int, float, int, float, bool]] = field(default_factory=dict, repr=False)

    def merge_vertices(self, a: int, b: int) -> None:
        """Record that the mesher collapsed an edge: its two end vertices become one mesh vertex."""
        ra, rb = self.root(a), self.root(b)
        if ra != rb:
            self.parent[max(ra, rb)] = min(ra, rb)

    def root(self, v: int) -> int:
        while v in self.parent:
            v = self.parent[v]
        return v

    def vertex_roots(self) -> np.ndarray:
        """(n_vertices,) the representative of each B-rep vertex after edge collapses."""
        roots = np.arange(self.vertices.Extent())
        for v in list(self.parent):
            roots[v] = self.root(v)
        return roots

    @classmethod
    def of(cls, shape: TopoDS_Shape) -> Topology:
        e, v = TopTools_IndexedMapOfShape(), TopTools_IndexedMapOfShape()
        TopExp.MapShapes_s(shape, TopAbs_EDGE, e)
        TopExp.MapShapes_s(shape, TopAbs_VERTEX, v)
        return cls(e, v)

    def edge_index(self, edge: TopoDS_Edge) -> int:
        return self.edges.FindIndex(edge) - 1

    def vertex_index(self, vertex) -> int:  # type: ignore[no-untyped-def]
        return self.vertices.FindIndex(vertex) - 1

    def edge_ends(self, edge: TopoDS_Edge) -> tuple[int, float, int, float]:
        """(first vertex, its parameter, last vertex, its parameter) of an edge, orientation ignored."""
        return self.edge_facts(edge)[1:5]  # type: ignore[return-value]

    def edge_facts(self, edge: TopoDS_Edge) -> tuple[int, int, float, int, float, bool]:
        """(edge index, edge_ends..., degenerated) of an edge, asked of OCCT once per edge (a cache on the topology)."""
        ei = self.edge_index(edge)
        known = self._facts.get(ei)
        if known is None:
            e = TopoDS.Edge_s(edge.Oriented(TopAbs_FORWARD))
            v1, v2 = TopExp.FirstVertex_s(e), TopExp.LastVertex_s(e)
            known = self._facts[ei] = (ei, self.vertex_index(v1), BRep_Tool.Parameter_s(v1, e), self.vertex_index(v2),
                                       BRep_Tool.Parameter_s(v2, e), bool(BRep_Tool.Degenerated_s(e)))
        return known


def explore(shape: TopoDS_Shape, kind, cast, avoid=None) -> list:  # type: ignore[no-untyped-def,type-arg]
    """The sub-shapes of one kind in TopExp order, oriented as they sit in `shape`, cast by `cast` (`avoid`: a
    kind whose sub-shapes are not entered, e.g. the shells outside solids)."""
    out = []
    exp = TopExp_Explorer(shape, kind) if avoid is None else TopExp_Explorer(shape, kind, avoid)
    while exp.More():
        out.append(cast(exp.Current()))
        exp.Next()
    return out


def compound(shapes: list) -> TopoDS_Compound:  # type: ignore[type-arg]
    """A compound holding the given shapes (sharing their sub-shapes, not copies)."""
    builder, comp = BRep_Builder(), TopoDS_Compound()
    builder.MakeCompound(comp)
    for s in shapes:
        builder.Add(comp, s)
    return comp


def face_edges(face: TopoDS_Face) -> list[TopoDS_Edge]:
    """The oriented edges of a face (a seam edge comes twice, once per orientation)."""
    return explore(face, TopAbs_EDGE, TopoDS.Edge_s)


@dataclass
class PatchRead:
    """What read_patch found on one face, compact enough to send between processes: the keys of its boundary nodes
    (`keys`: node ids, B-rep vertex, B-rep edge, parameter on it, (b,) each; None when the face has no or a broken
    triangulation), each B-rep edge's discretisation (`edges` (e,) indices, `sizes` (e,), `params` (Σ sizes,) in
    the polygons' order), the B-rep vertex pairs BRepMesh collapsed into one node (an edge shorter than its min
    size), and `stored` for a tessellated-only face. `patch`, the assembled FacePatch, stays in its process."""

    face_id: int
    keys: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
    edges: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    sizes: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    params: np.ndarray = field(default_factory=lambda: np.zeros(0))
    merges: list[tuple[int, int]] = field(default_factory=list)
    stored: bool = False
    patch: FacePatch | None = None

    def __getstate__(self) -> dict:  # type: ignore[type-arg]
        return {**self.__dict__, "patch": None}

    def record(self, topo: Topology) -> None:
        """Add the edges' discretisations (sorted, where topo has none yet) and the collapses to the topology."""
        ends = np.cumsum(self.sizes)
        for ei, end, size in zip(self.edges.tolist(), ends.tolist(), self.sizes.tolist(), strict=True):
            if ei not in topo.edge_params:
                topo.edge_params[ei] = np.sort(self.params[end - size:end])
        for a, b in self.merges:
            topo.merge_vertices(a, b)

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
        if face.Orientation() == TopAbs_REVERSED:
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
    facts, sizes, pole_nodes, pole_vertex = [], [], [], []
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
            continue
        ids.extend([poly.Node(i) for i in range(1, n + 1)])
        par.extend([poly.Parameter(i) for i in range(1, n + 1)])
        facts.append(fact)
        sizes.append(n)
    node_ids = np.array(ids, dtype=np.int64) - 1
    poles = np.array(pole_nodes, dtype=np.int64) - 1
    if min(node_ids.min(initial=0), poles.min(initial=0)) < 0 or max(node_ids.max(initial=-1), poles.max(initial=-1)) >= k:
        return none
    node_vertex = np.full(k, -1, np.int64)
    node_edge = np.full(k, -1, np.int64)
    node_param = np.full(k, np.nan)
    params = np.array(par)
    found = PatchRead(face_id, stored=not has_surface)
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


def extract_patch(face_id: int, face: TopoDS_Face, topo: Topology,
                  arrays: tuple[np.ndarray, np.ndarray | None, np.ndarray] | None = None) -> FacePatch | None:
    """read_patch, with what it found recorded in `topo`: the face's patch, or None when it has no or a broken
    triangulation."""
    found = read_patch(face_id, face, topo, arrays)
    found.record(topo)
    return found.patch


def off_boundary_edges(patch: FacePatch) -> np.ndarray:
    """(e, 2) node pairs of the edges used by one triangle only that do not lie on the B-rep boundary (an end on
    neither an edge nor a vertex): none in a sound patch."""
    t = patch.tris
    a, b = t.reshape(-1), t[:, [1, 2, 0]].reshape(-1)  # the directed edges (a → b) of every triangle
    key = np.stack([np.minimum(a, b), np.maximum(a, b)], axis=1)
    _, inv, cnt = np.unique(key[:, 0] * (len(patch.nodes) + 1) + key[:, 1], return_inverse=True, return_counts=True)
    once = key[cnt[inv.reshape(-1)] == 1]
    on_boundary = (patch.node_edge >= 0) | (patch.node_vertex >= 0)
    return once[~on_boundary[once].all(axis=1)]


def check_patch_boundary(patch: FacePatch) -> bool:
    """True when every edge used once within the face lies on its B-rep boundary (both ends on edges/vertices)."""
    return len(off_boundary_edges(patch)) == 0
