"""The B-rep topology the meshers weld through: indexed edges and vertices, each edge's discretisation, explorers."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from OCP.BRep import BRep_Builder, BRep_Tool
from OCP.BRepGProp import BRepGProp
from OCP.GProp import GProp_GProps
from OCP.TopAbs import TopAbs_EDGE, TopAbs_FORWARD, TopAbs_REVERSED, TopAbs_VERTEX
from OCP.TopExp import TopExp, TopExp_Explorer
from OCP.TopLoc import TopLoc_Location
from OCP.TopoDS import TopoDS, TopoDS_Compound, TopoDS_Edge, TopoDS_Face, TopoDS_Shape
from OCP.TopTools import TopTools_IndexedMapOfShape

from amprep.geometry.core.progress import checkpoint
from amprep.geometry.parallel.face_pool import map_faces

#: measure_areas forks where its faces cost this much (one free-form face's integral ≈ 1: about a millisecond)
AREAS_PARALLEL_MIN = 100.0


def trsf_matrix(loc: TopLoc_Location) -> np.ndarray | None:
    """(3, 4) affine matrix of a location, or None for the identity."""
    if loc.IsIdentity():
        return None
    t = loc.Transformation()
    return np.array([[t.Value(r, c) for c in range(1, 5)] for r in range(1, 4)])


def mirrors(face: TopoDS_Face) -> bool:
    """True when the face is placed by a mirroring location: the determinant of its matrix < 0 (gp_Trsf.IsNegative
    reads the sign of the stored scale, which an IGES transformation can leave +1 on a mirror: a BREP round trip of
    the same location then reads -1)."""
    m = trsf_matrix(face.Location())
    return m is not None and float(np.linalg.det(m[:, :3])) < 0


def winds_inward(face: TopoDS_Face) -> bool:
    """True when triangles wound counter-clockwise in the face's (u,v) (normal S_u × S_v of its placed surface) face
    into the material: the face is REVERSED, or placed by a mirroring location, but not both. A mirror turns the
    surface's normal but not the face's orientation flag, so a mirrored instance would come out inside out without
    the second test; a face mirrored inside its own shell (oriented by its mirrored surface) is set right by its
    neighbours after the weld (weld.agree_face_orientations)."""
    return (face.Orientation() == TopAbs_REVERSED) != mirrors(face)


def apply_trsf(m: np.ndarray | None, pts: np.ndarray) -> np.ndarray:
    """(N, 3) points moved by a (3, 4) affine matrix (None: unchanged)."""
    return pts if m is None else pts @ m[:, :3].T + m[:, 3]


@dataclass
class Topology:
    """Indexed B-rep edges and vertices of a shape, and each edge's discretisation (sorted parameters)."""

    edges: TopTools_IndexedMapOfShape
    vertices: TopTools_IndexedMapOfShape
    edge_params: dict[int, np.ndarray] = field(default_factory=dict)
    parent: dict[int, int] = field(default_factory=dict)  # union-find over B-rep vertices of collapsed edges
    _facts: dict[int, tuple[int, int, float, int, float, bool]] = field(default_factory=dict, repr=False)
    _areas: dict[TopoDS_Face, float] = field(default_factory=dict, repr=False)
    _lengths: dict[int, tuple[np.ndarray, float]] = field(default_factory=dict, repr=False)  # shared_edges.edge_length
    #: face_mesher.boundary_loops of each face, with what they were made from (its edges' params, which collapsed)
    loops: dict[TopoDS_Face, tuple[tuple, list]] = field(default_factory=dict, repr=False)  # type: ignore[type-arg]

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

    def face_area(self, face: TopoDS_Face) -> float:
        """|∫∫ dA| of a face (OCCT's surface integral), asked of OCCT once per face (a cache on the topology)."""
        known = self._areas.get(face)
        if known is None:
            known = self._areas[face] = _area(face)
        return known

    def measure_areas(self, faces: list[TopoDS_Face], cost: list[float]) -> None:
        """face_area of each of `faces` not yet known, computed side by side (face_pool.map_faces, costliest first by
        `cost`, one per face: the same integral in any process) where they cost AREAS_PARALLEL_MIN or more."""
        todo = list(dict.fromkeys(f for f in faces if f not in self._areas))  # a face met twice is one
        price = {f: c for f, c in zip(faces, cost, strict=True)}
        order = sorted(range(len(todo)), key=lambda k: (-price[todo[k]], k))

        def area(k: int) -> float:
            checkpoint()
            return _area(todo[k])

        areas = map_faces(area, order, cost=[price[todo[k]] for k in order],
                          parallel_min=AREAS_PARALLEL_MIN)
        self._areas.update((todo[k], areas[k]) for k in range(len(todo)))


def _area(face: TopoDS_Face) -> float:
    """|∫∫ dA| of a face by OCCT's surface integral (BRepGProp)."""
    props = GProp_GProps()
    BRepGProp.SurfaceProperties_s(face, props)
    return abs(props.Mass())


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


def faces_of_edge(faces: list[TopoDS_Face], topo: Topology, edge_index: int) -> set[int]:
    """Ids of the faces (indices into `faces`, the model's) bounded by a B-rep edge (an edge → faces map kept on the
    topology)."""
    cache = getattr(topo, "_edge_faces", None)
    if cache is None:
        cache = {}
        for i, face in enumerate(faces):
            for e in face_edges(face):
                cache.setdefault(topo.edge_index(e), set()).add(i)
        topo._edge_faces = cache  # type: ignore[attr-defined]
    return cache.get(edge_index, set())  # type: ignore[no-any-return]
