"""Mesh one face ourselves: constrained Delaunay in its (u,v) domain from the shared edge discretisation,
refined until the chord tolerance holds (the approach of seed paper 000)."""

from __future__ import annotations

import numpy as np
from OCP.BRep import BRep_Tool
from OCP.BRepAdaptor import BRepAdaptor_Curve
from OCP.BRepGProp import BRepGProp
from OCP.BRepTools import BRepTools_WireExplorer
from OCP.GCPnts import GCPnts_TangentialDeflection
from OCP.GProp import GProp_GProps
from OCP.TopAbs import TopAbs_EDGE, TopAbs_REVERSED, TopAbs_WIRE
from OCP.TopoDS import TopoDS, TopoDS_Edge, TopoDS_Face

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.cad.pcurve_shifts import ordered_edges
from amprep.geometry.cad.surfaces import Surface
from amprep.geometry.cad.topology import Topology, explore, face_edges, winds_inward
from amprep.geometry.core.vectors import cross
from amprep.geometry.measure.chordal import exact_over, triangle_chordal_error
from amprep.geometry.meshing.local_refine import (
    flip_flat_triangles,
    flip_for_angles,
    refine_patch,
    smooth_on_surface,
    unfold,
)
from amprep.geometry.meshing.occt_read import FacePatch
from amprep.geometry.meshing.uv_cdt import (
    MAX_ROUNDS,
    MIN_SPACING,
    apart,
    insertion_points,
    inside_loops,
    metric_scale,
    metric_uniform,
    min_spacing,
    quality_pslg,
    recall_errors,
    triangle_codes,
    triangulate_pslg,
)
from amprep.geometry.meshing.uv_seed import clear_poles, curvature_seeds
from amprep.geometry.meshing.weld import pole_folds


def discretize_edge(edge: TopoDS_Edge, tolerance: float, angular: float) -> np.ndarray:
    """(n,) sorted parameters of an edge with no mesh yet, at the chord tolerance and angle (OCCT's GCPnts)."""
    first, last = BRep_Tool.Range_s(edge)
    if BRep_Tool.Degenerated_s(edge):
        return np.linspace(first, last, 9)
    curve = BRepAdaptor_Curve(edge)
    disc = GCPnts_TangentialDeflection(curve, angular, tolerance, 3)
    params = np.array([disc.Parameter(i) for i in range(1, disc.NbPoints() + 1)])
    params = np.unique(np.clip(np.concatenate([[first, last], params]), first, last))
    # GCPnts may return a parameter a hair from an end (seen: 2e-6 mm on CTC-02): a segment that short makes a
    # needle with any third point; drop interior points nearer than MIN_SPACING × tolerance to the point before
    # them or to the end
    pts = np.array([curve.Value(t).Coord() for t in params])
    eps = MIN_SPACING * tolerance
    if (np.linalg.norm(np.diff(pts, axis=0), axis=1) > eps).all() and (
            np.linalg.norm(pts[-1] - pts[1:-1], axis=1) > eps).all():
        return params  # the usual case: no point too near another, nothing to walk
    keep = np.ones(len(params), bool)
    last_kept = pts[0]
    for i in range(1, len(params) - 1):  # a drop moves the reference point: sequential, on the rare edge
        if np.linalg.norm(pts[i] - last_kept) <= eps or np.linalg.norm(pts[-1] - pts[i]) <= eps:
            keep[i] = False
        else:
            last_kept = pts[i]
    return params[keep]


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


def discretize_missing_edges(face: TopoDS_Face, topo: Topology, tolerance: float, angular: float) -> None:
    """Give every edge of the face with no discretisation yet its own (discretize_edge), in topo.edge_params."""
    for edge in face_edges(face):
        ei = topo.edge_index(edge)
        if ei not in topo.edge_params:
            topo.edge_params[ei] = discretize_edge(edge, tolerance, angular)


def edge_length(edge: TopoDS_Edge, params: np.ndarray) -> float:
    """The length of an edge's discretisation at params (n,): Σ of its chords."""
    return float(np.linalg.norm(np.diff(_edge_points(edge, params), axis=0), axis=1).sum())


def collapse_short_edges(faces: list[TopoDS_Face], topo: Topology, shortest: float) -> None:
    """Identify the two vertices of every edge of `faces` whose discretised length is under `shortest` (a CAD edge of
    a few µm: kept, its triangles collapse to slivers that a float32 STL makes degenerate), by topology
    (Topology.merge_vertices, as BRepMesh collapses an edge under its min size): the weld then drops the triangles
    that collapse with it, on both faces."""
    for face in faces:
        for edge in face_edges(face):
            ei, v1, _, v2, _, degenerate = topo.edge_facts(edge)
            params = topo.edge_params.get(ei)
            if degenerate or params is None or v1 == v2:
                continue
            if edge_length(edge, params) < shortest:
                topo.merge_vertices(v1, v2)
                topo.edge_params[ei] = params[[0, -1]]


# ---- the quality mesher's edge grading
# A triangle with good angles on a segment of length s is about 0.87 s high; a face narrower than that (a chamfer
# strip, a short cylinder band, a plate's long side) can only hold skinny triangles on it, and Triangle may not
# split a shared edge to mend them. So, before any face of the quality mesher is meshed, each face's width is taken
# as w = 2A/P (its area over half its perimeter: b for an a × b strip with a ≫ b, the height of a cylinder band)
# and every segment of the shared edge discretisation longer than GRADE × the smaller width of its two faces is cut
# into equal parameter steps. The edges stay shared: both faces see the same points.

#: a boundary segment may be at most this many times the width of its narrower face
GRADE = 3.0
#: surface types (Surface.surface_type) whose (u,v) maps boundary lines and circles to lines in (u,v)
ANALYTIC = ("plane", "cylinder", "cone", "sphere", "torus")
#: a boundary segment may be at most its distance from the nearer end × this, plus the shortest segment there
GROWTH = 1.0
#: and is cut into at most this many parts (a sliver face's width can be near zero)
MAX_PARTS = 64
#: a face narrower (face_width) than this × the chord tolerance has no width: its edges are not cut
SLIVER = 1e-3
#: a pcurve is straight in (u,v) when its points lie within this × its (u,v) chord of the chord
UV_STRAIGHT = 1e-6


def _edge_points(edge, params: np.ndarray) -> np.ndarray:  # type: ignore[no-untyped-def]
    curve = BRepAdaptor_Curve(edge)
    return np.array([curve.Value(float(t)).Coord() for t in params]).reshape(-1, 3)


def _straight(edge, params: np.ndarray) -> bool:  # type: ignore[no-untyped-def]
    """True when the edge is a straight line in space (whatever its curve type: a STEP may store a line as a B-spline):
    its points at the ends, the middle and the quarters lie within 1e-6 × its chord of the chord."""
    t = np.interp([0, 0.25, 0.5, 0.75, 1], [0, 1], [params[0], params[-1]])
    p = _edge_points(edge, t)
    chord = p[-1] - p[0]
    length = float(np.linalg.norm(chord))
    if length <= 0:
        return False
    off = cross(p - p[0], chord / length)
    return bool(np.linalg.norm(off, axis=1).max() <= 1e-6 * length)


def _curved_in_uv(edge, face: TopoDS_Face, params: np.ndarray) -> bool:  # type: ignore[no-untyped-def]
    """True when the edge's pcurve on the face is not a straight line in (u,v): its points at the ends, the middle and
    the quarters farther than UV_STRAIGHT × its (u,v) chord from that chord (True where it has no pcurve)."""
    pc = BRep_Tool.CurveOnSurface_s(edge, face, 0.0, 0.0)
    if pc is None:
        return True
    t = np.interp([0, 0.25, 0.5, 0.75, 1], [0, 1], [params[0], params[-1]])
    uv = np.array([[q.X(), q.Y()] for q in (pc.Value(float(x)) for x in t)])
    chord = uv[-1] - uv[0]
    length = float(np.linalg.norm(chord))
    if length <= 0:
        return True
    off = (uv[:, 0] - uv[0, 0]) * chord[1] - (uv[:, 1] - uv[0, 1]) * chord[0]
    return bool(np.abs(off).max() > UV_STRAIGHT * length * length)


def face_width(face: TopoDS_Face, topo: Topology) -> float:
    """2A/P of a face: its area (OCCT's surface integral) over half its perimeter (its edges' discretisations)."""
    props = GProp_GProps()
    BRepGProp.SurfaceProperties_s(face, props)
    perimeter = 0.0
    for edge in face_edges(face):
        if BRep_Tool.Degenerated_s(edge):
            continue
        params = topo.edge_params.get(topo.edge_index(edge))
        if params is not None and len(params) > 1:
            perimeter += edge_length(edge, params)
    return 2 * abs(props.Mass()) / perimeter if perimeter > 0 else np.inf


def split_segments(params: np.ndarray, parts: np.ndarray) -> np.ndarray:
    """Sorted params (n,) with segment i cut into parts[i] (n−1,) equal parameter steps."""
    new = [params[-1:]]
    for k in np.unique(parts):
        rows = parts == k
        new.append((params[:-1][rows, None] + np.diff(params)[rows, None] * (np.arange(k) / k)[None, :]).ravel())
    return np.unique(np.concatenate(new))


def grade_edges(faces: list[TopoDS_Face], kinds: list[str], topo: Topology, floor: float = 0.0) -> None:
    """Cut the discretised edges of `faces` (surface types `kinds`; their params in topo.edge_params) where a
    segment is longer than GRADE × the narrower width of the faces it bounds, or than GROWTH × its distance from the
    nearer end plus the shortest segment at that end's vertex (over every edge there): a long segment beside a
    short one can only make slivers, so sizes grow along an edge from its ends (twice: the first cuts shorten the ends;
    not on a straight edge of a free-form face). No size is set
    below `floor` (the chord tolerance: finer steps buy no regularity, only needles by a tiny segment)."""
    cap: dict[int, tuple[float, object]] = {}
    straight: set[int] = set()  # straight edges curved in the (u,v) of a B-spline or other free-form face, or of one
    # with a pole: their points, cut finer, make ears of three, flat in space, that the face's Delaunay keeps
    # not cut: the edges of a face of no width (two edges on one line, out and back, as FreeCAD's SOD-323 has): a
    # point cut into one would have no partner on the other, and the face no room for triangles to join them
    frozen: set[int] = set()
    for face, kind in zip(faces, kinds, strict=True):
        w, pole = face_width(face, topo), has_pole(face)
        for edge in face_edges(face):
            if BRep_Tool.Degenerated_s(edge):
                continue
            ei = topo.edge_index(edge)
            if w <= SLIVER * floor:
                frozen.add(ei)
            if (kind not in ANALYTIC and ei in topo.edge_params and _straight(edge, topo.edge_params[ei])
                    and (pole or _curved_in_uv(edge, face, topo.edge_params[ei]))):
                straight.add(ei)
            if ei in topo.edge_params and (ei not in cap or GRADE * w < cap[ei][0]):
                cap[ei] = (GRADE * w, edge)
    for _ in range(2):
        points = {ei: _edge_points(edge, topo.edge_params[ei]) for ei, (_, edge) in cap.items()
                  if len(topo.edge_params[ei]) >= 2}
        at_vertex: dict[int, float] = {}
        for ei, pts in points.items():
            seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
            v1, _, v2, _ = topo.edge_ends(cap[ei][1])  # type: ignore[arg-type]
            for v, s in ((v1, seg[0]), (v2, seg[-1])):
                at_vertex[v] = min(at_vertex.get(v, np.inf), float(s))
        for ei, pts in points.items():
            limit, edge = cap[ei]
            seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
            along = np.concatenate([[0.0], np.cumsum(seg)])
            mid = (along[:-1] + along[1:]) / 2
            v1, _, v2, _ = topo.edge_ends(edge)  # type: ignore[arg-type]
            size = np.minimum(at_vertex[v1] + GROWTH * mid, at_vertex[v2] + GROWTH * (along[-1] - mid))
            if ei in straight:
                size = np.full_like(seg, np.inf)
            if np.isfinite(limit) and limit > 0:
                size = np.minimum(size, limit)
            size = np.maximum(size, floor)
            parts = np.minimum(np.ceil(seg / np.maximum(size, 1e-12)), MAX_PARTS).astype(np.int64)
            if (parts > 1).any() and ei not in frozen:
                topo.edge_params[ei] = split_segments(topo.edge_params[ei], parts)


def has_pole(face: TopoDS_Face) -> bool:
    """True when the face has a degenerated edge (a pole or apex: a line of its (u,v) maps to one point)."""
    return any(BRep_Tool.Degenerated_s(e) for e in face_edges(face))


def pole_runs(loops: list[dict]) -> list[np.ndarray]:  # type: ignore[type-arg]
    """Each pole or apex of the loops (boundary_loops'): the (u,v) of its run of nodes on one B-rep vertex (a degenerate
    edge's line), with the node before and the node after it: (k + 3, 2) for a run of k segments."""
    runs = []
    for lp in loops:
        vertex, n = lp["vertex"], len(lp["vertex"])
        same = (vertex >= 0) & (vertex == np.roll(vertex, -1))  # node i and node i + 1 are one vertex
        if same.all():
            continue
        for start in np.flatnonzero(same & ~np.roll(same, 1)):
            k = int(np.argmin(np.roll(same, -int(start))))  # the run's length: up to the first False after it
            runs.append(lp["uv"][(start - 1 + np.arange(k + 3)) % n])
    return runs


def wire_edges(face: TopoDS_Face, wire) -> list[TopoDS_Edge]:  # type: ignore[no-untyped-def]
    """The wire's oriented edges in the order it runs them on the face: OCCT's BRepTools_WireExplorer, or where it
    stops before the last edge, pcurve_shifts.ordered_edges; MESHING_FAILED when neither walks the whole wire."""
    found, wexp = [], BRepTools_WireExplorer(wire, face)
    while wexp.More():
        found.append(TopoDS.Edge_s(wexp.Current()))
        wexp.Next()
    if len(found) == len(explore(wire, TopAbs_EDGE, TopoDS.Edge_s)):
        return found
    walked = ordered_edges(face, wire)
    if walked is None:
        raise AmprepError(ErrorCode.MESHING_FAILED, "the edges of a wire do not join up into one loop")
    return walked


def boundary_loops(face: TopoDS_Face, topo: Topology, tolerance: float, angular: float) -> list[dict]:  # type: ignore[type-arg]
    """Each wire of the face as a closed polygon in (u,v): uv (n, 2), vertex (n,), edge (n,), param (n,), and segment
    (n,) the B-rep edge of the segment from each node to the next; an edge with no discretisation yet gets one."""
    discretize_missing_edges(face, topo, tolerance, angular)
    loops = []
    for wire in explore(face, TopAbs_WIRE, TopoDS.Wire_s):
        uvs, verts, edges, pars, segs = [], [], [], [], []
        for edge in wire_edges(face, wire):
            ei = topo.edge_index(edge)
            degenerate = BRep_Tool.Degenerated_s(edge)
            params = topo.edge_params[ei]
            if edge.Orientation() == TopAbs_REVERSED:
                params = params[::-1]
            pcurve = BRep_Tool.CurveOnSurface_s(edge, face, 0.0, 0.0)
            if pcurve is None:
                raise AmprepError(ErrorCode.MESHING_FAILED, "an edge of face has no curve on its surface")
            v1, p1, v2, p2 = topo.edge_ends(edge)
            if not degenerate and v1 != v2 and topo.root(v1) == topo.root(v2) and len(params) == 2:
                continue  # an edge collapse_short_edges collapsed: its two ends are one node, the next edge's
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
            segs.append(np.full(n, ei, np.int64))
        if uvs:
            loops.append(dict(uv=np.array(uvs, float), vertex=np.concatenate(verts),
                              edge=np.concatenate(edges), param=np.concatenate(pars), segment=np.concatenate(segs)))
    return loops


def mesh_face(face_id: int, face: TopoDS_Face, topo: Topology, surface: Surface, tolerance: float,
              angular: float, order: int = 6, seeds: np.ndarray | None = None, min_area: float = 0.0,
              curvature_sized: bool = True, quality: bool = False) -> FacePatch:
    """_mesh_face. A face with a pole whose quality mesh folds there (weld.pole_folds: a point joined to two of the
    pole's nodes, one point in space, on either side of another) is meshed again without the row along its pole's
    line (uv_seed.clear_poles: refinement can still insert between the two), then, if that folds too, as before the
    quality mesher, from its boundary and refinement alone."""
    args = (face_id, face, topo, surface, tolerance, angular, order, seeds, min_area)
    pole = quality and has_pole(face)
    for rows in (True, False) if pole else (True,):
        patch = _mesh_face(*args, curvature_sized, quality, pole_rows=rows)
        if not (pole and patch.meshed_by == "quality" and pole_folds(patch)):
            return patch
    return _mesh_face(*args, False, False)


def _mesh_face(face_id: int, face: TopoDS_Face, topo: Topology, surface: Surface, tolerance: float,
               angular: float, order: int = 6, seeds: np.ndarray | None = None, min_area: float = 0.0,
               curvature_sized: bool = True, quality: bool = False, pole_rows: bool = True) -> FacePatch:
    """A FacePatch for one face: CDT of its boundary loops in scaled (u,v) plus interior points (when
    `curvature_sized`, on a curved surface with a numpy evaluator and no pole, uv_seed.curvature_seeds' points in
    their stretched space; else `seeds` (k, 2) interior (u,v) points, e.g. an earlier mesh's), points inserted
    (longest inner edge midpoint, else centroid) in every triangle whose chordal error exceeds the tolerance, until
    none does; then flat triangles (area ≤ min_area, or needles) flipped away where a flip keeps the tolerance
    (patch_refine.flip_flat_triangles). With `quality` (the quality mesher) the interior points are cut near square
    on the surface (uv_seed, true_metric) and the triangles refined to a minimum angle where no boundary point is
    needed (uv_cdt.quality_pslg), in a space whose lengths are the surface's; on a face with no single scale to them
    (a strongly non-uniform B-spline) the cells are judged by the surface's lengths at each, and the mesh is finished
    by flips and smoothing measured in space (local_refine.smooth_on_surface)."""
    loops = boundary_loops(face, topo, tolerance, angular)
    if not loops:
        raise AmprepError(ErrorCode.MESHING_FAILED, f"face {face_id} has no boundary")
    b_uv = np.concatenate([lp["uv"] for lp in loops])
    nb = len(b_uv)
    length_scale = scale = metric_scale(surface, b_uv)
    pole = has_pole(face)
    # curvature decides the interior points, in its own space; not at a pole or apex, where a line of (u,v) is one
    # point: (u,v) cells there misjudge lengths, and the global re-triangulation works on an earlier mesh's points
    seedable = curvature_sized and not surface.affine and surface.exact_numpy and (quality or not pole)
    # no single scale to the surface's lengths: cells judged by their own, the mesh finished on the surface
    local = quality and not surface.affine and (pole or not metric_uniform(surface, b_uv))
    quality = quality and (not local or seedable)
    if seedable:
        seeded = curvature_seeds(surface, [lp["uv"] for lp in loops], tolerance, length_scale, true_metric=quality,
                                 local=local)
        if seeded is not None:
            seeds, scale = seeded
            if pole and pole_rows:  # points near a pole's line in (u,v) would join its nodes either side of others
                seeds = clear_poles(seeds, pole_runs(loops), scale, [lp["uv"] for lp in loops])
    spacing = min_spacing(tolerance, scale, length_scale)
    segments = _loop_segments(loops)
    scaled_loops = [lp["uv"] * scale for lp in loops]
    pts = b_uv * scale
    tris = triangulate_pslg(pts, segments)
    cent = pts[tris].mean(axis=1)
    holes = cent[~inside_loops(cent, scaled_loops)]
    if seeds is not None and len(seeds):
        # no inside test needed: a seed outside the boundary polygon lies in a hole or concavity that Triangle
        # eats; such seeds are dropped after
        pts = np.concatenate([pts, apart(np.unique(seeds * scale, axis=0), pts, spacing)])
    if quality and not local and (surface.affine or (scale == length_scale).all()):  # angles here are the surface's
        pts, tris = quality_pslg(pts, segments, holes)
    else:
        tris = triangulate_pslg(pts, segments, holes)
    used = np.zeros(len(pts), bool)
    used[:nb] = used[tris] = True
    tris, pts = ((np.cumsum(used) - 1)[tris], pts[used]) if not used.all() else (tris, pts)
    xyz = surface.evaluate(pts / scale)
    err = triangle_chordal_error(xyz[tris], (pts / scale)[tris], surface, order, affine=surface.affine,
                                 stop=tolerance)
    node_vertex, node_edge, node_param = _node_keys(loops, len(pts))
    # CDT triangles are counter-clockwise in (u,v): outward when the surface normal S_u × S_v points out
    flip = winds_inward(face)
    method = "quality" if quality else "fallback"
    patch = FacePatch(face_id, xyz, pts / scale, tris[:, [0, 2, 1]] if flip else tris, node_vertex, node_edge,
                      node_param, meshed_by=method, error=err)
    if (err > tolerance).any():
        # insertions re-triangulate only around them, except at a pole or apex (there a line of (u,v) is one point
        # and a local re-triangulation leaves tilted triangles in the fan)
        refined = None if pole else refine_patch(patch, err, surface, tolerance, order, scale=scale)
        if refined is None:
            pts, tris, xyz, err = _refine_globally(pts, tris, err, segments, holes, scale, xyz, surface, tolerance,
                                                   order, spacing, quality and not local)
            k = len(pts) - len(node_vertex)
            refined = FacePatch(face_id, xyz, pts / scale, tris[:, [0, 2, 1]] if flip else tris,
                                np.concatenate([node_vertex, np.full(k, -1, np.int64)]),
                                np.concatenate([node_edge, np.full(k, -1, np.int64)]),
                                np.concatenate([node_param, np.full(k, np.nan)]), meshed_by=method, error=err)
        patch = refined
    return _finish(patch, surface, tolerance, order, quality, local, min_area)


def _finish(patch: FacePatch, surface: Surface, tolerance: float, order: int, quality: bool, local: bool,
            min_area: float) -> FacePatch:
    """A face's mesh finished on its surface: the quality mesher's flips (and smoothing, on a face with no single
    scale), else the unfolding flips alone; then flat triangles flipped away."""
    if quality and local:
        patch = flip_for_angles(smooth_on_surface(flip_for_angles(patch, surface, tolerance, order), surface,
                                                  tolerance, order), surface, tolerance, order)
    elif quality and surface.surface_type not in ANALYTIC:  # one scale only approximates the surface's lengths
        patch = flip_for_angles(patch, surface, tolerance, order)
    elif not surface.affine:
        patch = unfold(patch, surface, tolerance, order)
    return flip_flat_triangles(patch, surface, tolerance, order, min_area)


def _loop_segments(loops: list[dict]) -> np.ndarray:  # type: ignore[type-arg]
    """(s, 2) the closed loops' segments as indices into their concatenated nodes."""
    seg, start = [], 0
    for lp in loops:
        idx = np.arange(start, start + len(lp["uv"]))
        seg.append(np.stack([idx, np.roll(idx, -1)], axis=1))
        start += len(idx)
    return np.concatenate(seg)


def _node_keys(loops: list[dict], n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # type: ignore[type-arg]
    """(vertex, edge, param) each (n,) of n nodes whose first ones are the loops' boundary nodes (−1/nan after)."""
    nb = sum(len(lp["uv"]) for lp in loops)
    vertex, edge, param = np.full(n, -1, np.int64), np.full(n, -1, np.int64), np.full(n, np.nan)
    vertex[:nb] = np.concatenate([lp["vertex"] for lp in loops])
    edge[:nb] = np.concatenate([lp["edge"] for lp in loops])
    param[:nb] = np.concatenate([lp["param"] for lp in loops])
    return vertex, edge, param


def _refine_globally(pts: np.ndarray, tris: np.ndarray, err: np.ndarray, segments: np.ndarray, holes: np.ndarray,
                     scale: np.ndarray, xyz: np.ndarray, surface: Surface, tolerance: float,
                     order: int, spacing: float, quality: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The robust path when a local re-triangulation cannot be made: points inserted (no nearer than `spacing` to
    another, in the space of pts = uv · scale) in every triangle over the tolerance and the whole face triangulated
    again, until none is over (`err` (t,): the error of the first `tris`); returns (pts, tris, xyz, error)."""
    affine = surface.affine
    final_err = None
    known_code, known_err = triangle_codes(tris, len(pts)), err
    for _ in range(MAX_ROUNDS):
        uv = pts / scale
        if len(xyz) < len(pts):  # points are only ever appended: evaluate the new ones
            xyz = np.concatenate([xyz, surface.evaluate(uv[len(xyz):])])
        code = triangle_codes(tris, len(pts))
        seen, err = recall_errors(len(tris), code, known_code, known_err)
        fresh = ~seen
        err[fresh] = triangle_chordal_error(xyz[tris[fresh]], uv[tris[fresh]], surface, order, affine=affine,
                                            stop=tolerance)
        known_code, known_err = code, err
        bad = err > tolerance
        if not bad.any():
            final_err = err
            break
        seg_code = np.sort(segments.min(axis=1) * (len(pts) + 1) + segments.max(axis=1))
        new = apart(insertion_points(pts, tris[bad], seg_code, len(pts) + 1), pts, spacing)
        if not len(new):
            break
        pts = np.concatenate([pts, new])
        if quality:  # the quality mesher's minimum angle kept through the refinement
            pts, tris = quality_pslg(pts, segments, holes)
        else:
            tris = triangulate_pslg(pts, segments, holes)
    uv = pts / scale
    if len(xyz) < len(pts):
        xyz = np.concatenate([xyz, surface.evaluate(uv[len(xyz):])])
    if final_err is None:  # rounds ran out after a last insertion: measure the triangles kept
        final_err = triangle_chordal_error(xyz[tris], uv[tris], surface, order, affine=affine)
    return pts, tris, xyz, exact_over(final_err, tolerance, xyz, uv, tris, surface, order)


