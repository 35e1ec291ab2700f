"""Mesh one face ourselves: constrained Delaunay in its (u,v) domain from the shared edge discretisation,
refined until the chord tolerance holds (the approach of seed paper 000)."""

from __future__ import annotations

import numpy as np
from OCP.BRep import BRep_Tool
from OCP.BRepTools import BRepTools_WireExplorer
from OCP.Geom2dAdaptor import Geom2dAdaptor_Curve
from OCP.TopAbs import TopAbs_EDGE, TopAbs_REVERSED, TopAbs_WIRE
from OCP.TopoDS import TopoDS, TopoDS_Edge, TopoDS_Face

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.cad.occt_arrays import curve_values
from amprep.geometry.cad.pcurve_shifts import ordered_edges
from amprep.geometry.cad.surfaces import CONE, CYLINDER, Surface
from amprep.geometry.cad.topology import Topology, explore, face_edges, winds_inward
from amprep.geometry.core.progress import checkpoint, within_budget
from amprep.geometry.measure.chordal import exact_over, triangle_chordal_error
from amprep.geometry.meshing.lattice import rectangle_sides, zip_rows
from amprep.geometry.meshing.local_refine import (
    flip_flat_triangles,
    flip_for_angles,
    refine_patch,
    smooth_on_surface,
    unfold,
)
from amprep.geometry.meshing.occt_read import FacePatch
from amprep.geometry.meshing.shared_edges import ANALYTIC, bare_straight_edges, discretize_missing_edges, has_pole
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

#: two nodes of one B-rep vertex within this × the shorter boundary segment at either are one node (a pinch)
PINCH_REACH = 0.05


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
    """Each wire of the face as a closed polygon in (u,v): uv (n, 2), vertex (n,), edge (n,), param (n,), segment
    (n,) the B-rep edge of the segment from each node to the next and span (n, 2) its parameters there at both ends;
    an edge with no discretisation yet gets one. Read-only arrays, made once while the face's edges keep the same
    params arrays and collapses (kept in topo.loops: the quality mesher's plan and its meshing ask for them both)."""
    known = topo.loops.get(face)
    if known is not None and _same_edges(topo, known[0]):
        return known[1]  # type: ignore[no-any-return]
    discretize_missing_edges(face, topo, tolerance, angular)
    loops, made_of = [], []
    for wire in explore(face, TopAbs_WIRE, TopoDS.Wire_s):
        uvs, verts, edges, pars, segs, spans = [], [], [], [], [], []
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
            made_of.append((ei, topo.edge_params[ei], v1, v2, topo.root(v1) == topo.root(v2)))
            if not degenerate and v1 != v2 and topo.root(v1) == topo.root(v2) and len(params) == 2:
                continue  # an edge collapse_short_edges collapsed: its two ends are one node, the next edge's
            n = len(params) - 1  # the last point starts the next edge
            uvs.append(curve_values(Geom2dAdaptor_Curve(pcurve), params[:n]).reshape(-1, 2))
            vtx = np.full(n, -1, np.int64)
            vtx[0] = v1 if abs(params[0] - p1) <= abs(params[0] - p2) else v2
            if degenerate:
                vtx[:] = vtx[0]
            verts.append(vtx)
            edges.append(np.where(vtx >= 0, -1, ei))
            pars.append(np.where(vtx >= 0, np.nan, params[:n]))
            segs.append(np.full(n, ei, np.int64))
            spans.append(np.stack([params[:n], params[1:n + 1]], axis=1))
        if uvs:
            loops.append(dict(uv=np.concatenate(uvs), vertex=np.concatenate(verts), edge=np.concatenate(edges),
                              param=np.concatenate(pars), segment=np.concatenate(segs), span=np.concatenate(spans)))
    for arr in (a for lp in loops for a in lp.values()):
        arr.flags.writeable = False
    topo.loops[face] = (tuple(made_of), loops)
    return loops


def _same_edges(topo: Topology, made_of: tuple) -> bool:  # type: ignore[type-arg]
    """True when every edge boundary_loops met (edge index, its params, its ends, whether they were one node) has those
    same params (the same array) and collapses now."""
    return all(topo.edge_params.get(ei) is params and (topo.root(v1) == topo.root(v2)) == joined
               for ei, params, v1, v2, joined in made_of)


def mesh_face(face_id: int, face: TopoDS_Face, topo: Topology, surface: Surface, tolerance: float,
              angular: float, order: int = 6, seeds: np.ndarray | None = None, min_area: float = 0.0,
              curvature_sized: bool = True, quality: bool = False) -> FacePatch:
    """_mesh_face. A face with a pole whose quality mesh folds there (weld.pole_folds: a point joined to two of the
    pole's nodes, one point in space, on either side of another) is meshed again without the row along its pole's
    line (uv_seed.clear_poles: refinement can still insert between the two), then, if that folds too, as before the
    quality mesher, from its boundary and refinement alone; so is a face the quality path fails on (MESHING_FAILED).
    Any other error (a cancel seen at a checkpoint) is raised."""
    args = (face_id, face, topo, surface, tolerance, angular, order, seeds, min_area)
    if not quality:
        return _mesh_face(*args, curvature_sized, False)
    pole = has_pole(face)
    try:
        for rows in (True, False) if pole else (True,):
            patch = _mesh_face(*args, curvature_sized, True, pole_rows=rows)
            if not (pole and patch.meshed_by == "quality" and pole_folds(patch)):
                return patch
    except AmprepError as exc:
        if exc.code != ErrorCode.MESHING_FAILED:
            raise
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
    length_scale = scale = metric_scale(surface, np.concatenate([lp["uv"] for lp in loops]))
    b_uv, b_vertex, b_edge, b_param, segments = _boundary_nodes(loops, length_scale, tolerance)
    nb = len(b_uv)
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
    node_vertex, node_edge, node_param = _node_keys(b_vertex, b_edge, b_param, len(pts))
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


def _boundary_nodes(loops: list[dict], length_scale: np.ndarray,  # type: ignore[type-arg]
                    tolerance: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(uv (nb, 2), vertex, edge, param each (nb,), segments (s, 2) into them): the closed loops' nodes and segments,
    with a face's pinch made one node: the nodes of one B-rep vertex met twice (two loops that touch there, or one
    loop through it twice), outside a pole's run, whose (u,v) · length_scale (2,) lie within MIN_SPACING × tolerance
    or PINCH_REACH × the shorter segment at either (the copies of a seam vertex lie a period apart). Triangle needs
    them one point: their pcurves' ends differ by rounding (1e-16 mm), or by a reader's fit (a STEP: 1.1e-4 mm), and
    two segments from points that near cross."""
    uv = np.concatenate([lp["uv"] for lp in loops])
    vertex = np.concatenate([lp["vertex"] for lp in loops])
    seg, start, run = [], 0, []
    for lp in loops:
        idx = np.arange(start, start + len(lp["uv"]))
        seg.append(np.stack([idx, np.roll(idx, -1)], axis=1))
        v = lp["vertex"]
        run.append((v >= 0) & ((v == np.roll(v, 1)) | (v == np.roll(v, -1))))
        start += len(idx)
    segments, first = np.concatenate(seg), np.arange(len(uv))
    side = np.linalg.norm((uv[segments[:, 1]] - uv[segments[:, 0]]) * length_scale, axis=1)
    shortest = np.full(len(uv), np.inf)
    np.minimum.at(shortest, segments.ravel(), np.repeat(side, 2))  # the shorter segment at each node
    candidates = np.flatnonzero((vertex >= 0) & ~np.concatenate(run))
    by_vertex = candidates[np.argsort(vertex[candidates], kind="stable")]  # each vertex's nodes in loop order
    _, at, count = np.unique(vertex[by_vertex], return_index=True, return_counts=True)
    for a, c in zip(at[count > 1].tolist(), count[count > 1].tolist()):  # only a vertex met twice can pinch
        nodes = by_vertex[a:a + c]
        for k in range(1, len(nodes)):
            reach = np.maximum(MIN_SPACING * tolerance, PINCH_REACH * np.minimum(shortest[nodes[:k]], shortest[nodes[k]]))
            near = np.linalg.norm((uv[nodes[:k]] - uv[nodes[k]]) * length_scale, axis=1) <= reach
            if near.any():
                first[nodes[k]] = first[nodes[:k][near][0]]
    keep = first == np.arange(len(uv))
    compact = np.cumsum(keep) - 1
    keys = [np.concatenate([lp[k] for lp in loops])[keep] for k in ("vertex", "edge", "param")]
    return uv[keep], keys[0], keys[1], keys[2], compact[first[segments]]


def _node_keys(vertex: np.ndarray, edge: np.ndarray, param: np.ndarray,
               n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertex, edge, param) each (n,) of n nodes whose first ones are the boundary nodes' (−1/nan after)."""
    k = n - len(vertex)
    return (np.concatenate([vertex, np.full(k, -1, np.int64)]), np.concatenate([edge, np.full(k, -1, np.int64)]),
            np.concatenate([param, np.full(k, np.nan)]))


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
        checkpoint()
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
        within_budget(len(tris) + 2 * len(new))
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


# ---- ruled faces, the default mesher's: a face ruled along one parameter (a cone or a cylinder along its generators, a
# B-spline of degree 1 that way: each such iso-line one straight segment) meshed from its boundary alone, a strip of
# triangles between its two iso-line sides or, at an apex, a fan, one triangle per segment of the edge across from
# it. A flat triangle between two straight lines of the surface leaves it by no more than its chords on the boundary
# do, so where those keep the tolerance the strip or fan does too (each is measured, and refused when a triangle is
# over): the fewest triangles the shared edge discretisation allows. BRepMesh's grid on a cone (its ConeRangeSplitter)
# is far over the tolerance at the apex, and re-meshed from that grid it made ten times the fan.


def ruled_direction(surface: Surface) -> int | None:
    """The parameter along which S is a straight segment: 1 (v) for a cone or a cylinder (their v-lines are
    generators), 0 or 1 for a B-spline of degree 1 in u or in v with one knot span there (one segment, not a polyline),
    None otherwise."""
    if surface.closed_form is not None:
        return 1 if surface.closed_form[0] in (CONE, CYLINDER) else None
    d = surface.data
    if surface.surface_type != "bspline" or d is None:
        return None
    for k, (deg, knots) in enumerate(((d["udeg"], d["uknots"]), (d["vdeg"], d["vknots"]))):
        if deg == 1 and len(np.unique(knots)) == 2:
            return k
    return None


def bare_ruled_seam(face: TopoDS_Face, surface: Surface, topo: Topology) -> None:
    """Drop the interior points of a ruled face's seam (a straight edge of this face alone, met on both of its sides:
    a cone's or a cylinder's generator where its (u,v) closes), so its strip or fan stands on the seam's ends alone;
    BRepMesh cuts a cone's seam for its grid. No other face has points on it."""
    if ruled_direction(surface) is not None:
        seams = {topo.edge_index(e) for e in face_edges(face) if BRep_Tool.IsClosed_s(e, face)}
        bare_straight_edges([face], topo, seams.__contains__)


def ruled_patch(face_id: int, face: TopoDS_Face, loops: list[dict], surface: Surface, tolerance: float,  # type: ignore[type-arg]
                order: int = 6) -> FacePatch | None:
    """A FacePatch of the face's strip or fan (the comment above), measured; None when the surface is not ruled, the face
    is not one (u,v) rectangle whose two ruled sides are single segments, both of its other sides are poles, or a
    triangle is over the tolerance."""
    way = ruled_direction(surface)
    if way is None or len(loops) != 1:
        return None
    loop = loops[0]
    swap = way == 0  # the ruled parameter made the second: its iso-lines, the sides, at u0 and u1
    uv_loop = loop["uv"][:, ::-1] if swap else loop["uv"]
    sides = rectangle_sides({**loop, "uv": uv_loop})
    if sides is None or len(sides.left) != 2 or len(sides.right) != 2 or min(sides.pole) >= 0:
        return None
    bottom, top = sides.bottom, sides.top
    uv, vertex = [uv_loop], [loop["vertex"]]
    if max(sides.pole) < 0:  # a strip from one iso-line edge to the other
        tris = zip_rows(bottom, uv_loop[bottom, 0], top, uv_loop[top, 0], np.zeros(len(bottom), np.int64),
                        np.zeros(len(top), np.int64))
    else:  # a fan: one node at the apex per segment across from it, at that segment's middle u, keyed to its vertex
        at_bottom = sides.pole[0] >= 0
        ring = top if at_bottom else bottom
        ru = uv_loop[ring, 0]
        m = len(ring) - 1
        apex = len(uv_loop) + np.arange(m)
        uv.append(np.stack([(ru[:-1] + ru[1:]) / 2, np.full(m, sides.v0 if at_bottom else sides.v1)], axis=1))
        vertex.append(np.full(m, max(sides.pole), np.int64))
        tris = np.stack([apex, ring[1:], ring[:-1]] if at_bottom else [ring[:-1], ring[1:], apex], axis=1)
    all_uv = np.concatenate(uv)
    used = np.zeros(len(all_uv), bool)
    used[tris] = True
    tris = (np.cumsum(used) - 1)[tris]
    k_new = len(all_uv) - len(uv_loop)
    node_uv = all_uv[used][:, ::-1] if swap else all_uv[used]
    xyz = surface.evaluate(node_uv)
    err = triangle_chordal_error(xyz[tris], node_uv[tris], surface, order, stop=tolerance)
    if not len(tris) or (err > tolerance).any():
        return None
    flip = winds_inward(face) != swap  # made counter-clockwise in (u,v) swapped: clockwise in the face's own (u,v)
    return FacePatch(face_id, xyz, node_uv, tris[:, [0, 2, 1]] if flip else tris, np.concatenate(vertex)[used],
                     np.concatenate([loop["edge"], np.full(k_new, -1, np.int64)])[used],
                     np.concatenate([loop["param"], np.full(k_new, np.nan)])[used], meshed_by="ruled", error=err)
