"""Mesh one face ourselves: constrained Delaunay in its (u,v) domain from the shared edge discretisation,
refined until the chord tolerance holds (the approach of seed paper 000)."""

from __future__ import annotations

import numpy as np
import triangle as tr
from OCP.BRep import BRep_Tool
from OCP.BRepAdaptor import BRepAdaptor_Curve
from OCP.BRepTools import BRepTools_WireExplorer
from OCP.GCPnts import GCPnts_TangentialDeflection
from OCP.TopAbs import TopAbs_REVERSED, TopAbs_WIRE
from OCP.TopoDS import TopoDS, TopoDS_Edge, TopoDS_Face
from scipy.spatial import ConvexHull, QhullError, cKDTree

from .chordal import triangle_chordal_error
from .errors import AmprepError, ErrorCode
from .surfaces import Surface
from .tessellate import FacePatch, Topology, explore

MAX_ROUNDS = 40
#: points are inserted no closer than this × tolerance (in metric-scaled (u,v) ≈ mm) to another
MIN_SPACING = 0.01


def discretize_edge(edge: TopoDS_Edge, tolerance: float, angular: float) -> np.ndarray:
    """(n,) sorted parameters of an edge with no mesh yet, at the chord tolerance and angle (OCCT's GCPnts)."""
    first, last = BRep_Tool.Range_s(edge)
    if BRep_Tool.Degenerated_s(edge):
        return np.linspace(first, last, 9)
    curve = BRepAdaptor_Curve(edge)
    disc = GCPnts_TangentialDeflection(curve, angular, tolerance, 3)
    params = np.array([disc.Parameter(i) for i in range(1, disc.NbPoints() + 1)])
    params = np.unique(np.clip(np.concatenate([[first, last], params]), first, last))
    return params


def edge_sagitta(edge: TopoDS_Edge, params: np.ndarray) -> np.ndarray:
    """(n−1,) max distance from the edge curve at 1/4, 1/2, 3/4 of each parameter segment to its chord."""
    curve = BRepAdaptor_Curve(edge)
    pts = np.array([curve.Value(t).Coord() for t in params])
    fr = np.array([0.25, 0.5, 0.75])
    mids = params[:-1, None] + fr[None, :] * np.diff(params)[:, None]
    mid_pts = np.array([curve.Value(t).Coord() for t in mids.ravel()]).reshape(-1, 3, 3)
    a, b = pts[:-1, None], pts[1:, None]
    ab = b - a
    len2 = np.maximum((ab * ab).sum(-1), 1e-300)
    s = np.clip(((mid_pts - a) * ab).sum(-1) / len2, 0, 1)
    return np.linalg.norm(mid_pts - (a + s[..., None] * ab), axis=-1).max(axis=1)


def split_edge_to_tolerance(edge: TopoDS_Edge, params: np.ndarray, tolerance: float, rounds: int = 12) -> np.ndarray:
    """Edge parameters with every segment whose sagitta exceeds the tolerance halved, until none does."""
    if BRep_Tool.Degenerated_s(edge):
        return params
    for _ in range(rounds):
        bad = edge_sagitta(edge, params) > tolerance
        if not bad.any():
            break
        params = np.sort(np.concatenate([params, 0.5 * (params[:-1][bad] + params[1:][bad])]))
    return params


def boundary_loops(face: TopoDS_Face, topo: Topology, tolerance: float, angular: float) -> list[dict]:  # type: ignore[type-arg]
    """Each wire of the face as a closed polygon in (u,v): uv (n, 2), vertex (n,), edge (n,), param (n,)."""
    loops = []
    for wire in explore(face, TopAbs_WIRE, TopoDS.Wire_s):
        uvs, verts, edges, pars = [], [], [], []
        wexp = BRepTools_WireExplorer(wire, face)
        while wexp.More():
            edge = TopoDS.Edge_s(wexp.Current())
            ei = topo.edge_index(edge)
            degenerate = BRep_Tool.Degenerated_s(edge)
            if ei not in topo.edge_params:
                topo.edge_params[ei] = discretize_edge(edge, tolerance, angular)
            params = topo.edge_params[ei]
            if edge.Orientation() == TopAbs_REVERSED:
                params = params[::-1]
            pcurve = BRep_Tool.CurveOnSurface_s(edge, face, 0.0, 0.0)
            if pcurve is None:
                raise AmprepError(ErrorCode.MESHING_FAILED, "an edge of face has no curve on its surface")
            v1, p1, v2, p2 = topo.edge_ends(edge)
            n = len(params) - 1  # the last point starts the next edge
            for t in params[:n]:
                uvs.append(pcurve.Value(t).Coord())
            vtx = np.full(n, -1, np.int64)
            vtx[0] = v1 if abs(params[0] - p1) <= abs(params[0] - p2) else v2
            if degenerate:
                vtx[:] = vtx[0]
            verts.append(vtx)
            edges.append(np.where(vtx >= 0, -1, ei))
            pars.append(np.where(vtx >= 0, np.nan, params[:n]))
            wexp.Next()
        if uvs:
            loops.append(dict(uv=np.array(uvs, float), vertex=np.concatenate(verts),
                              edge=np.concatenate(edges), param=np.concatenate(pars)))
    return loops


def _metric_scale(surface: Surface, uv: np.ndarray) -> np.ndarray:
    """(2,) mean |∂S/∂u|, |∂S/∂v| over the boundary points, so that CDT in scaled (u,v) sees near-true lengths."""
    h = 1e-6 * max(float(np.ptp(uv[:, 0])), float(np.ptp(uv[:, 1])), 1e-9)
    sample = uv[:: max(1, len(uv) // 64)]
    p = surface.evaluate(sample)
    du = np.linalg.norm(surface.evaluate(sample + [h, 0]) - p, axis=1) / h
    dv = np.linalg.norm(surface.evaluate(sample + [0, h]) - p, axis=1) / h
    s = np.array([du.mean(), dv.mean()])
    return np.where(s > 1e-12, s, 1.0)


def triangulate_pslg(pts: np.ndarray, segments: np.ndarray, holes: np.ndarray | None = None) -> np.ndarray:
    """(t, 3) constrained Delaunay triangles of points (n, 2) and segments (s, 2), nothing added on a segment, the
    parts holding a hole point (h, 2) and outside the segments removed. Triangle crashes the process on two equal
    points or a hole point outside the convex hull: equal or non-finite points raise meshing_failed, hole points
    outside are dropped (the outside is removed anyway); segments crossing raise meshing_failed."""
    if not np.isfinite(pts).all():
        raise AmprepError(ErrorCode.MESHING_FAILED, "a face's (u,v) boundary has non-finite points")
    z = np.ascontiguousarray(pts, dtype=np.float64).view(np.complex128).ravel()  # a point as one sortable value
    if len(np.unique(z)) != len(z):
        raise AmprepError(ErrorCode.MESHING_FAILED, "a face's boundary touches itself in (u,v)")
    data = dict(vertices=pts, segments=segments)
    if holes is not None and len(holes) and len(pts) >= 3:
        try:
            eq = ConvexHull(pts).equations
        except QhullError:  # all points on a line: nothing to triangulate, nothing to hole
            eq = None
        if eq is not None:
            size = float(np.ptp(pts, axis=0).max())
            inside = holes[(holes @ eq[:, :2].T + eq[:, 2] < -1e-9 * size).all(axis=1)]
            if len(inside):
                data["holes"] = inside
    out = tr.triangulate(data, "pYQ")
    if len(out.get("vertices", [])) != len(pts):
        raise AmprepError(ErrorCode.MESHING_FAILED, "the face's boundary in (u,v) self-intersects")
    return out.get("triangles", np.zeros((0, 3), np.int64)).astype(np.int64)


def _cdt(pts: np.ndarray, segments: np.ndarray, holes: np.ndarray | None) -> np.ndarray:
    return triangulate_pslg(pts, segments, holes)


def _inside(points: np.ndarray, loops: list[np.ndarray]) -> np.ndarray:
    """(N,) bool even-odd point-in-polygon over all loops (closed polygons (n, 2))."""
    inside = np.zeros(len(points), bool)
    x, y = points[:, 0:1], points[:, 1:2]
    for poly in loops:
        a, b = poly, np.roll(poly, -1, axis=0)
        cond = (a[None, :, 1] > y) != (b[None, :, 1] > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            xint = a[None, :, 0] + (y - a[None, :, 1]) * (b[None, :, 0] - a[None, :, 0]) / (b[None, :, 1] - a[None, :, 1])
        inside ^= (cond & (x < xint)).sum(axis=1) % 2 == 1
    return inside


def mesh_face(face_id: int, face: TopoDS_Face, topo: Topology, surface: Surface, tolerance: float,
              angular: float, order: int = 6, seeds: np.ndarray | None = None) -> FacePatch:
    """A FacePatch for one face: CDT of its boundary loops in scaled (u,v) (plus `seeds` (k, 2) interior (u,v)
    points, e.g. an earlier mesh's), points inserted (longest inner edge midpoint, else centroid) in every
    triangle whose chordal error exceeds the tolerance, until none does."""
    loops = boundary_loops(face, topo, tolerance, angular)
    if not loops:
        raise AmprepError(ErrorCode.MESHING_FAILED, f"face {face_id} has no boundary")
    b_uv = np.concatenate([lp["uv"] for lp in loops])
    nb = len(b_uv)
    scale = _metric_scale(surface, b_uv)
    seg, start = [], 0
    for lp in loops:
        n = len(lp["uv"])
        idx = np.arange(start, start + n)
        seg.append(np.stack([idx, np.roll(idx, -1)], axis=1))
        start += n
    segments = np.concatenate(seg)
    scaled_loops = [lp["uv"] * scale for lp in loops]
    pts = b_uv * scale
    tris = _cdt(pts, segments, None)
    cent = pts[tris].mean(axis=1)
    holes = cent[~_inside(cent, scaled_loops)]
    if seeds is not None and len(seeds):
        # no inside test needed: a seed outside the boundary polygon lies in a hole or concavity that Triangle
        # eats, so it is left unused
        pts = np.concatenate([pts, _apart(np.unique(seeds * scale, axis=0), pts, MIN_SPACING * tolerance)])
    tris = _cdt(pts, segments, holes)
    affine = surface.affine
    xyz = surface.evaluate(pts / scale)
    final_err = None
    known_code, known_err = np.zeros(0, np.int64), np.zeros(0)
    for _ in range(MAX_ROUNDS):
        uv = pts / scale
        if len(xyz) < len(pts):  # points are only ever appended: evaluate the new ones
            xyz = np.concatenate([xyz, surface.evaluate(uv[len(xyz):])])
        code = _triangle_codes(tris, len(pts))
        err = np.empty(len(tris))
        seen = np.zeros(len(tris), bool)
        if code is not None and len(known_code):
            pos = np.minimum(np.searchsorted(known_code, code), len(known_code) - 1)
            seen = known_code[pos] == code
            err[seen] = known_err[pos[seen]]
        fresh = ~seen
        err[fresh] = triangle_chordal_error(xyz[tris[fresh]], uv[tris[fresh]], surface, order, affine=affine)
        if code is not None:
            order_ = np.argsort(code)
            known_code, known_err = code[order_], err[order_]
        bad = err > tolerance
        if not bad.any():
            final_err = err
            break
        seg_code = np.sort(segments.min(axis=1) * (len(pts) + 1) + segments.max(axis=1))
        new = _apart(_insertion_points(pts, tris[bad], seg_code, len(pts) + 1), pts, MIN_SPACING * tolerance)
        if not len(new):
            break
        pts = np.concatenate([pts, new])
        tris = _cdt(pts, segments, holes)
    uv = pts / scale
    if len(xyz) < len(pts):
        xyz = np.concatenate([xyz, surface.evaluate(uv[len(xyz):])])
    if final_err is None:  # rounds ran out after a last insertion: measure the triangles kept
        final_err = triangle_chordal_error(xyz[tris], uv[tris], surface, order, affine=affine)
    k = len(pts)
    if face.Orientation() == TopAbs_REVERSED:
        tris = tris[:, [0, 2, 1]]
    # CDT triangles are counter-clockwise in (u,v): outward when the surface normal S_u × S_v points out
    node_vertex = np.full(k, -1, np.int64)
    node_edge = np.full(k, -1, np.int64)
    node_param = np.full(k, np.nan)
    node_vertex[:nb] = np.concatenate([lp["vertex"] for lp in loops])
    node_edge[:nb] = np.concatenate([lp["edge"] for lp in loops])
    node_param[:nb] = np.concatenate([lp["param"] for lp in loops])
    return FacePatch(face_id, xyz, uv, tris, node_vertex, node_edge, node_param, meshed_by="fallback",
                     error=final_err)


_CODE_BASE = 1 << 20


def _triangle_codes(tris: np.ndarray, n_points: int) -> np.ndarray | None:
    """(t,) int64 code of each triangle's sorted vertex triple (a·B² + b·B + c), None past 2^20 points."""
    if n_points >= _CODE_BASE:
        return None
    s = np.sort(tris, axis=1).astype(np.int64)
    return (s[:, 0] * _CODE_BASE + s[:, 1]) * _CODE_BASE + s[:, 2]


def _apart(new: np.ndarray, pts: np.ndarray, eps: float) -> np.ndarray:
    """The new (k, 2) points farther than eps from every existing point and from each other (the first kept): two
    nodes closer than that gain nothing and may round to one vertex in a float32 STL (a degenerate triangle)."""
    if not len(new):
        return new
    far = cKDTree(pts).query(new, distance_upper_bound=eps)[0] > eps
    new = new[far]
    if len(new) > 1:
        pairs = cKDTree(new).query_pairs(eps, output_type="ndarray")
        if len(pairs):
            drop = np.zeros(len(new), bool)
            for i, j in pairs[np.argsort(pairs[:, 1])]:  # keep the lower index of each close pair
                if not drop[i]:
                    drop[j] = True
            new = new[~drop]
    return new


def _insertion_points(pts: np.ndarray, bad: np.ndarray, seg_code: np.ndarray, base: int) -> np.ndarray:
    """(k, 2) one new point per bad triangle (k, 3): midpoint of its longest edge that is not a boundary
    segment, else its centroid; seg_code: codes lo·base + hi of the boundary segments."""
    a, b = bad, np.roll(bad, -1, axis=1)
    code = np.minimum(a, b) * base + np.maximum(a, b)
    length = np.linalg.norm(pts[a] - pts[b], axis=2)
    length[np.isin(code, seg_code)] = -1.0
    k = length.argmax(axis=1)
    rows = np.arange(len(bad))
    mid = 0.5 * (pts[a[rows, k]] + pts[b[rows, k]])
    centroid = pts[bad].mean(axis=1)
    out = np.where((length[rows, k] > 0)[:, None], mid, centroid)
    return np.unique(out, axis=0)
