"""The B-rep edges behind a mesh: which B-rep edge a mesh edge discretises, and points on it (3D curve and each
face's pcurve), so a refinement can split a contour edge on both sides with the vertex on the exact edge."""

from __future__ import annotations

import numpy as np
from OCP.BRep import BRep_Tool
from OCP.BRepAdaptor import BRepAdaptor_Curve
from OCP.TopoDS import TopoDS

from amprep.geometry.cad.read import CadModel
from amprep.geometry.cad.topology import Topology
from amprep.geometry.core.mesh import ON_BREP_EDGE, ON_BREP_VERTEX, Mesh


class EdgeCurves:
    """Edge curves of a model indexed as the mesher indexed them (Topology.of(model.shape))."""

    def __init__(self, model: CadModel) -> None:
        self.model = model
        self.topo = Topology.of(model.shape)
        self._ends: dict[int, tuple[int, float, int, float]] = {}
        self._curve: dict[int, BRepAdaptor_Curve] = {}
        self._pcurve: dict[tuple[int, int], list] = {}  # type: ignore[type-arg]

    def _edge(self, e: int):  # type: ignore[no-untyped-def]
        return TopoDS.Edge_s(self.topo.edges.FindKey(e + 1))

    def ends(self, e: int) -> tuple[int, float, int, float]:
        if e not in self._ends:
            self._ends[e] = self.topo.edge_ends(self._edge(e))
        return self._ends[e]

    def resolve(self, mesh: Mesh, a: int, b: int) -> tuple[int, float] | None:
        """(B-rep edge, mid parameter) of the mesh edge between vertices a and b, or None when it is not a piece
        of one B-rep edge with known parameters (e.g. both ends on B-rep vertices, or no topology)."""
        if mesh.vertex_dim is None or mesh.vertex_entity is None or mesh.vertex_param is None:
            return None
        dim, ent, par = mesh.vertex_dim, mesh.vertex_entity, mesh.vertex_param
        length = float(np.linalg.norm(mesh.vertices[a] - mesh.vertices[b]))
        if dim[a] == ON_BREP_EDGE and dim[b] == ON_BREP_EDGE:
            if ent[a] != ent[b]:
                return None
            e, t = int(ent[a]), 0.5 * (float(par[a]) + float(par[b]))
            mid = 0.5 * (mesh.vertices[a] + mesh.vertices[b])
            return (e, t) if np.linalg.norm(self.point(e, t) - mid) <= length else None  # not two neighbours on it
        if ON_BREP_EDGE not in (dim[a], dim[b]) or ON_BREP_VERTEX not in (dim[a], dim[b]):
            return None
        on_edge, at_vertex = (a, b) if dim[a] == ON_BREP_EDGE else (b, a)
        e, t = int(ent[on_edge]), float(par[on_edge])
        v1, t1, v2, t2 = self.ends(e)
        # the end the mesh edge runs to: by position (an edge whose two B-rep vertices almost coincide, or a closed
        # edge, has both ends there; then the end nearer in parameter), not by vertex identity, which a weld may
        # have merged
        x = mesh.vertices[at_vertex]
        d = [float(np.linalg.norm(self.point(e, tv) - x)) for tv in (t1, t2)]
        if min(d) > 0.5 * length:
            return None
        ends = [tv for tv, dv in zip((t1, t2), d, strict=True) if dv <= min(d) + 0.1 * length]
        tv = min(ends, key=lambda x: abs(x - t))
        return e, 0.5 * (t + tv)

    def point(self, e: int, t: float) -> np.ndarray:
        if e not in self._curve:
            self._curve[e] = BRepAdaptor_Curve(self._edge(e))
        return np.array(self._curve[e].Value(t).Coord())

    def uv(self, e: int, face: int, t: float, near: np.ndarray,
           periods: tuple[float | None, float | None] = (None, None)) -> np.ndarray:
        """(u, v) of the edge's point at t on the face, from its pcurve(s) (a seam has two: the one nearer `near`),
        shifted by whole periods of a periodic surface to the copy nearest `near`."""
        key = (e, face)
        if key not in self._pcurve:
            f = self.model.faces[face]
            edge = self._edge(e)
            curves = []
            for oriented in (edge, edge.Reversed()):
                c = BRep_Tool.CurveOnSurface_s(TopoDS.Edge_s(oriented), f, 0.0, 0.0)
                if c is not None:
                    curves.append(c)
            self._pcurve[key] = curves
        near = np.asarray(near, float)
        pts = [np.array(c.Value(t).Coord()) for c in self._pcurve[key]]
        if not pts:
            return near
        for p in pts:
            for d, per in enumerate(periods):
                if per:
                    p[d] += np.round((near[d] - p[d]) / per) * per
        return min(pts, key=lambda p: float(np.linalg.norm(p - near)))
