"""Edges discretised once and shared by both faces they bound: each edge's points to the chord tolerance, the
quality mesher's grading of those points to the faces' widths, the collapse of edges under the spacing, and the
faces with a pole (a degenerated edge)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from OCP.BRep import BRep_Tool
from OCP.BRepAdaptor import BRepAdaptor_Curve
from OCP.GCPnts import GCPnts_TangentialDeflection
from OCP.Geom2dAdaptor import Geom2dAdaptor_Curve
from OCP.TopAbs import TopAbs_EDGE, TopAbs_WIRE
from OCP.TopoDS import TopoDS, TopoDS_Edge, TopoDS_Face

from amprep.geometry.cad.occt_arrays import curve_values
from amprep.geometry.cad.surfaces import CYLINDER, SPHERE, TORUS, Surface, uv_extent
from amprep.geometry.cad.topology import Topology, explore, face_edges
from amprep.geometry.core.progress import checkpoint
from amprep.geometry.core.vectors import cross
from amprep.geometry.meshing.uv_cdt import MIN_SPACING, difference_step, surface_speeds
from amprep.geometry.meshing.uv_seed import BOUNDED_MEDIANS, LOCAL_FLOOR, median_speeds, standing_error
from amprep.geometry.parallel.face_pool import map_faces


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
    pts = curve_values(curve, params)
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
    pts = curve_values(curve, params)
    fr = np.array([0.25, 0.5, 0.75])
    mids = params[:-1, None] + fr[None, :] * np.diff(params)[:, None]
    mid_pts = curve_values(curve, mids.ravel()).reshape(-1, 3, 3)
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


def edge_length(edge: TopoDS_Edge, params: np.ndarray, topo: Topology | None = None) -> float:
    """The length of an edge's discretisation at params (n,): Σ of its chords; given its topology, kept there while
    the edge's params are that same array."""
    if topo is None:
        return float(np.linalg.norm(np.diff(edge_points(edge, params), axis=0), axis=1).sum())
    ei = topo.edge_index(edge)
    known = topo._lengths.get(ei)
    if known is None or known[0] is not params:
        known = topo._lengths[ei] = (params, edge_length(edge, params))
    return known[1]


#: a face whose perimeter is under this × the collapse length keeps its edges (collapse_short_edges)
TINY_FACE = 8.0


def collapse_short_edges(faces: list[TopoDS_Face], topo: Topology, shortest: float) -> None:
    """Identify the two vertices of every edge of `faces` whose discretised length is under `shortest` (a CAD edge of
    a few µm: kept, its triangles collapse to slivers that a float32 STL makes degenerate), by topology
    (Topology.merge_vertices, as BRepMesh collapses an edge under its min size): the weld then drops the triangles
    that collapse with it, on both faces. Not an edge of a face whose perimeter is under TINY_FACE × `shortest`: a
    face that small would collapse whole (a solid under the tolerance would vanish), so it keeps its edges."""
    edges: dict[int, tuple[int, int, np.ndarray, float]] = {}  # ei: its vertices, params, discretised length
    tiny: set[int] = set()
    for face in faces:
        perimeter, own = 0.0, []
        for edge in face_edges(face):
            ei, v1, _, v2, _, degenerate = topo.edge_facts(edge)
            params = topo.edge_params.get(ei)
            if degenerate or params is None:
                continue
            if ei not in edges:
                edges[ei] = (v1, v2, params, edge_length(edge, params, topo))
            perimeter += edges[ei][3]
            own.append(ei)
        if perimeter < TINY_FACE * shortest:
            tiny.update(own)
    for ei, (v1, v2, params, length) in edges.items():
        if v1 != v2 and ei not in tiny and length < shortest:
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
#: an analytic face's area costs OCCT about this × a free-form face's (Topology.measure_areas)
ANALYTIC_AREA = 0.2
#: a boundary segment may be at most its distance from the nearer end × this, plus the shortest segment there
GROWTH = 1.0
#: and is cut into at most this many parts (a sliver face's width can be near zero)
MAX_PARTS = 64
#: a face narrower than the chord tolerance holds needles whatever its segments: they are cut to GRADE × the tolerance,
#: not to GRADE × its width (1 µm steps of KiCad's pin sockets had every edge near them, and the planes beside them,
#: cut at the tolerance), but no longer than this × its width (a needle's smallest angle then ≥ 1.2°: out of the
#: paper's first bin, under 0.3°)
NEEDLE = 95.0
#: a face narrower (face_width) than this × the chord tolerance has no width: its edges are not cut
SLIVER = 1e-3
#: a boundary segment of a curved face is cut where a triangle standing on it with this height × its length
#: would be over the target (bend_sizes): tan 30° / 2, Triangle's 30° minimum angle at both ends of the segment
APEX = 0.29
#: and where that triangle's error would be over this × the target on a free-form face (the rest is room for the
#: triangles the face's interior actually gives it; an analytic face's triangles get the whole target)
ROOM = 0.8
#: a segment up to this much longer than that is not cut (a cut would double it; its triangle then stays under
#: ROOM × (1 + BEND_SLACK)² ≈ 0.97 × the target)
BEND_SLACK = 0.1
#: the curvature there is taken over steps of this × the target on the surface (a fold far finer, as a fitted
#: B-spline's overshoot by 1 µm along a side where its speed vanishes, is not the face's shape)
STENCIL = 2.0
#: bend_sizes_many's work on one surface, in points' worth beside its points (three a segment); it forks where all of it
#: is this much or more (about a tenth of a second)
BEND_PER_SURFACE = 200
BEND_PARALLEL_MIN = 20_000
#: a pcurve is straight in (u,v) when its points lie within this × its (u,v) chord of the chord
UV_STRAIGHT = 1e-6


def edge_points(edge, params: np.ndarray) -> np.ndarray:  # type: ignore[no-untyped-def]
    """(n, 3) the edge curve's points at params (n,)."""
    return curve_values(BRepAdaptor_Curve(edge), params).reshape(-1, 3)


def _straight(edge, params: np.ndarray) -> bool:  # type: ignore[no-untyped-def]
    """True when the edge is a straight line in space (whatever its curve type: a STEP may store a line as a B-spline):
    its points at the ends, the middle and the quarters lie within 1e-6 × its chord of the chord."""
    t = np.interp([0, 0.25, 0.5, 0.75, 1], [0, 1], [params[0], params[-1]])
    p = edge_points(edge, t)
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
    uv = curve_values(Geom2dAdaptor_Curve(pc), t)
    chord = uv[-1] - uv[0]
    length = float(np.linalg.norm(chord))
    if length <= 0:
        return True
    off = (uv[:, 0] - uv[0, 0]) * chord[1] - (uv[:, 1] - uv[0, 1]) * chord[0]
    return bool(np.abs(off).max() > UV_STRAIGHT * length * length)


#: surface types on which a straight edge's pcurve is a straight line too
LINES_STAY_LINES = ("plane", "cylinder", "cone")


def bare_straight_edges(faces: list[TopoDS_Face], topo: Topology, allowed: Callable[[int], bool]) -> None:
    """Drop the interior points of each straight edge of `faces` (in topo.edge_params) whose index is `allowed`:
    BRepMesh leaves one at a third of every line, which the quality mesher's grading (grade_edges: the faces' widths,
    the segments at the ends, the standing rule) would only add to. The caller allows edges whose faces all keep
    lines straight in (u,v) (LINES_STAY_LINES), so the two ends alone are its pcurves. A wire left with under three
    segments (a face of no width: two edges out and back along a line, or two lines whose short ends
    collapse_short_edges made points; run after it) keeps its edges' points."""
    bared: dict[int, np.ndarray] = {}
    for face in faces:
        for edge in face_edges(face):
            ei = topo.edge_index(edge)
            params = topo.edge_params.get(ei)
            if (ei not in bared and params is not None and len(params) > 2 and not BRep_Tool.Degenerated_s(edge)
                    and allowed(ei) and _straight(edge, params)):
                bared[ei] = params
                topo.edge_params[ei] = params[[0, -1]]
    for wire in (w for face in faces for w in explore(face, TopAbs_WIRE, TopoDS.Wire_s)) if bared else ():
        own = [topo.edge_facts(e) for e in explore(wire, TopAbs_EDGE, TopoDS.Edge_s)]
        kept = [ei for ei, v1, _, v2, _, degenerate in own  # an edge collapse_short_edges made a point is no segment
                if not degenerate and (v1 == v2 or topo.root(v1) != topo.root(v2))]
        if sum(len(topo.edge_params.get(ei, ())) - 1 for ei in kept) < 3:
            topo.edge_params.update((ei, bared[ei]) for ei, *_ in own if ei in bared)


def face_width(face: TopoDS_Face, topo: Topology) -> float:
    """2A/P of a face: its area (Topology.face_area) over half its perimeter (its edges' discretisations)."""
    perimeter = 0.0
    for edge in face_edges(face):
        if BRep_Tool.Degenerated_s(edge):
            continue
        params = topo.edge_params.get(topo.edge_index(edge))
        if params is not None and len(params) > 1:
            perimeter += edge_length(edge, params, topo)
    return 2 * topo.face_area(face) / perimeter if perimeter > 0 else np.inf


def split_segments(params: np.ndarray, parts: np.ndarray) -> np.ndarray:
    """Sorted params (n,) with segment i cut into parts[i] (n−1,) equal parameter steps."""
    new = [params[-1:]]
    for k in np.unique(parts):
        rows = parts == k
        new.append((params[:-1][rows, None] + np.diff(params)[rows, None] * (np.arange(k) / k)[None, :]).ravel())
    return np.unique(np.concatenate(new))


def grade_edges(faces: list[TopoDS_Face], surfaces: list[Surface], topo: Topology, floor: float = 0.0,
                target: float = 0.0, shortest: float = 0.0) -> None:
    """Cut the discretised edges of `faces` (on `surfaces`; their params in topo.edge_params) where a
    segment is longer than GRADE × the narrower width of the faces it bounds, or than GROWTH × its distance from the
    nearer end plus the shortest segment at that end's vertex (over every edge there): a long segment beside a
    short one can only make slivers, so sizes grow along an edge from its ends (twice: the first cuts shorten the ends;
    not on a straight edge of a free-form face); and, with a `target`, than a triangle of a curved face it bounds
    can stand on within it (bend_sizes; not on such a straight edge). No size is set
    below `floor` (the chord tolerance: finer steps buy no regularity, only needles by a tiny segment), and none for
    the widths or the growth below `shortest` (the user's min_size: fewer, thinner triangles on thin walls)."""
    wide = max(floor, shortest)
    topo.measure_areas(faces, [ANALYTIC_AREA if s.surface_type in ANALYTIC else 1.0 for s in surfaces])  # face_width's
    cap: dict[int, tuple[float, object]] = {}
    bent: dict[int, list[tuple[TopoDS_Face, Surface]]] = {}
    straight: set[int] = set()  # straight edges curved in the (u,v) of a B-spline or other free-form face, or of one
    # with a pole: their points, cut finer, make ears of three, flat in space, that the face's Delaunay keeps
    # not cut: the edges of a face of no width (two edges on one line, out and back, as FreeCAD's SOD-323 has): a
    # point cut into one would have no partner on the other, and the face no room for triangles to join them
    frozen: set[int] = set()
    for face, surface in zip(faces, surfaces, strict=True):
        kind = surface.surface_type
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
            limit = GRADE * w if w >= wide else min(GRADE * wide, NEEDLE * w)
            if ei in topo.edge_params and (ei not in cap or limit < cap[ei][0]):
                cap[ei] = (limit, edge)
            if target > 0 and kind != "plane":
                bent.setdefault(ei, []).append((face, surface))
    seen: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # the last pass's params and points of each edge
    bends: dict[int, np.ndarray] = {}
    for _ in range(2):
        same = {ei for ei, (params, _) in seen.items() if params is topo.edge_params[ei]}  # not cut by the last pass
        points = {ei: seen[ei][1] if ei in same else edge_points(edge, topo.edge_params[ei])
                  for ei, (_, edge) in cap.items() if len(topo.edge_params[ei]) >= 2}
        seen = {ei: (topo.edge_params[ei], pts) for ei, pts in points.items()}
        standing = [ei for ei in points if ei in bent and ei not in straight and ei not in same
                    and not _stands_anyway(bent[ei], points[ei], target)]
        bends = {ei: b for ei, b in bends.items() if ei in same} | dict(zip(standing, bend_sizes_many(
            [(cap[ei][1], topo.edge_params[ei], points[ei], bent[ei]) for ei in standing], target), strict=True))
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
            parts = np.ceil(seg / np.maximum(size, max(wide, 1e-12)))
            if ei in bends:  # a segment a little over keeps its target (ROOM): not halved
                bend = np.maximum(bends[ei], floor)
                parts = np.maximum(parts, np.ceil(seg / np.maximum(bend, 1e-12) - BEND_SLACK))
            parts = np.minimum(parts, MAX_PARTS).astype(np.int64)
            if (parts > 1).any() and ei not in frozen:
                topo.edge_params[ei] = split_segments(topo.edge_params[ei], parts)


#: a strip's two long edges are cut alike when their points' fractions of length differ by under this × a segment
STRIP_MATCH = 1e-3


def stagger_strips(faces: list[TopoDS_Face], surfaces: list[Surface], topo: Topology,
                   movable: Callable[[int], bool]) -> None:
    """On plane strips (_strip: a thin face whose two long edges are cut alike, so its triangles are right, 22° in a
    strip 2.5 segments wide) one long edge's points are moved to the middles of its segments, its end segments half
    long: the strip's triangles are then isosceles (39°). Strips that share long edges (a bar's sides) are two-coloured
    edge by edge so that each has one edge moved where the chain allows; only `movable` edges are moved (every face
    they bound a plane: no lattice's rows stand on them)."""
    links: list[tuple[int, int]] = []
    fractions: dict[int, np.ndarray] = {}
    for face, surface in zip(faces, surfaces, strict=True):
        strip = _strip(face, surface, topo)
        if strip is not None:
            links.append((strip[0], strip[1]))
            fractions.update(strip[2])
    colour = _two_colours(links, movable)
    for ei in sorted(e for e, c in colour.items() if c == 1 and movable(e)):
        params, f = topo.edge_params[ei], fractions[ei]
        topo.edge_params[ei] = np.concatenate([params[:1], np.interp((f[:-1] + f[1:]) / 2, f, params), params[-1:]])


def _strip(face: TopoDS_Face, surface: Surface, topo: Topology) -> tuple[int, int, dict[int, np.ndarray]] | None:
    """(long edge, the other, each one's points' fractions of its length (n,)) of a plane strip: one wire of four
    straight edges, the two short ones shorter than the longest segment of the two long ones, which are cut (into 3
    or more) at the same fractions of their lengths (STRIP_MATCH); None for any other face."""
    if surface.surface_type != "plane" or len(explore(face, TopAbs_WIRE, TopoDS.Wire_s)) != 1:
        return None
    sides = {topo.edge_index(e): e for e in face_edges(face) if not BRep_Tool.Degenerated_s(e)}
    if len(sides) != 4 or any(ei not in topo.edge_params for ei in sides):
        return None
    ends = {ei: _ends_by_param(topo, e) for ei, e in sides.items()}
    pairs = [(a, b) for a in sides for b in sides if a < b and not set(ends[a]) & set(ends[b])]
    if len(pairs) != 2 or any(len(set(v)) != 2 for v in ends.values()):
        return None
    chords = {ei: np.linalg.norm(np.diff(edge_points(e, topo.edge_params[ei]), axis=0), axis=1)
              for ei, e in sides.items()}
    (a, c), short = sorted(pairs, key=lambda pair: -min(chords[ei].sum() for ei in pair))
    if (max(chords[ei].sum() for ei in short) >= max(chords[a].max(), chords[c].max())  # wider than a segment: not a strip
            or min(len(chords[a]), len(chords[c])) < 3
            or not all(_straight(e, topo.edge_params[ei]) for ei, e in sides.items())):
        return None
    ahead = any({ends[a][0], ends[c][0]} == set(ends[ei]) for ei in short)  # c runs from a's start's side too
    fa, fc = (along / along[-1] for along in (np.concatenate([[0.0], np.cumsum(chords[ei])]) for ei in (a, c)))
    if len(fa) != len(fc) or np.abs(fa - (fc if ahead else 1.0 - fc[::-1])).max() > STRIP_MATCH * np.diff(fa).min():
        return None
    return a, c, {a: fa, c: fc}


def _two_colours(links: list[tuple[int, int]], movable: Callable[[int], bool]) -> dict[int, int]:
    """{edge: 0 or 1}: the strips' long edges coloured so that each link's two differ where the chain is not an odd
    cycle; each chain started (colour 0) from its least edge that may not move, else its least edge."""
    near: dict[int, list[int]] = {}
    for a, c in links:
        near.setdefault(a, []).append(c)
        near.setdefault(c, []).append(a)
    colour: dict[int, int] = {}
    for start in sorted(near, key=lambda e: (movable(e), e)):
        if start in colour:
            continue
        colour[start], queue = 0, [start]
        while queue:
            e = queue.pop(0)
            for n in sorted(near[e]):
                if n not in colour:
                    colour[n] = 1 - colour[e]
                    queue.append(n)
    return colour


def _ends_by_param(topo: Topology, edge: TopoDS_Edge) -> tuple[int, int]:
    """(vertex at the edge's smaller parameter, vertex at its larger), after collapses (Topology.root)."""
    v1, p1, v2, p2 = topo.edge_ends(edge)
    return (topo.root(v1), topo.root(v2)) if p1 <= p2 else (topo.root(v2), topo.root(v1))


def _stands_anyway(faces: list[tuple[TopoDS_Face, Surface]], points: np.ndarray, target: float) -> bool:
    """True when no segment of an edge (its points (n, 3)) can be cut by bend_sizes: every face it bounds is a cylinder,
    sphere or torus whose largest curvature κ keeps κ L² / 8 ≤ the target on its longest segment L (a triangle of
    APEX < ½ standing on a segment lies in the circle on it as diameter, where a quadratic of curvatures ≤ κ departs
    from its interpolation by at most κ (L/2)² / 2): a cylinder's circles, so their second forms need no sampling."""
    longest = float(np.max(np.sum(np.diff(points, axis=0) ** 2, axis=1), initial=0.0))
    for _, surface in faces:
        kind, prm = surface.closed_form if surface.closed_form is not None else (None, None)
        if kind in (CYLINDER, SPHERE):
            radius = abs(float(prm[12]))  # type: ignore[index]
        elif kind == TORUS:
            radius = min(abs(float(prm[13])), abs(float(prm[12])) - abs(float(prm[13])))  # type: ignore[index]
        else:
            return False
        if not (radius > 0 and longest / (8 * radius) <= target):
            return False
    return True


def bend_sizes(edge: TopoDS_Edge, params: np.ndarray, faces: list[tuple[TopoDS_Face, Surface]],
               target: float) -> np.ndarray:
    """(n−1,) the longest each segment of an edge (params (n,)) may be for a triangle of APEX height to stand on it
    within ROOM × the target on each free-form face, the target on an analytic one (its edges are discretised at the
    target, and a circle's segment then has its own chord's error): √(room target / e) with e uv_seed.standing_error
    at a quarter, half and three quarters of it (differences STENCIL × the target apart on the surface, the stencil
    moved inside the face's bounds). On a longer segment the only triangles that keep the target are slivers tilted
    off the surface, which a move of their corners by the B-rep's gap breaks."""
    return bend_sizes_many([(edge, params, edge_points(edge, params), faces)], target)[0]


def bend_sizes_many(edges: list[tuple[TopoDS_Edge, np.ndarray, np.ndarray, list[tuple[TopoDS_Face, Surface]]]],
                    target: float) -> list[np.ndarray]:
    """bend_sizes of each (edge, params (n,), its points there (n, 3), its faces), the points of all the edges on one
    face evaluated on its surface together, the surfaces side by side (face_pool.map_faces, the most points first:
    each surface's numbers are the same in any process); each (edge, face) pair keeps its own difference steps and
    floor."""
    out = [np.zeros(3 * (len(params) - 1)) for _, params, _, _ in edges]
    by_face: dict[int, tuple[Surface, list]] = {}  # type: ignore[type-arg]
    for k, (edge, params, points, faces) in enumerate(edges):
        t = (params[:-1, None] + np.array([0.25, 0.5, 0.75])[None] * np.diff(params)[:, None]).ravel()
        chord = np.repeat(np.diff(points, axis=0), 3, axis=0)
        for face, surface in faces:
            by_face.setdefault(id(surface), (surface, []))[1].append((k, edge, face, t, chord))
    work = list(by_face.values())
    cost = [BEND_PER_SURFACE + sum(len(t) for *_, t, _ in pairs) for _, pairs in work]
    order = sorted(range(len(work)), key=lambda g: (-cost[g], g))
    found = map_faces(lambda g: _standing_on(work[g][0], work[g][1], target), order,
                      cost=[cost[g] for g in order], parallel_min=BEND_PARALLEL_MIN)
    for g, (surface, _) in enumerate(work):
        errors, median = found[g]
        if median is not None:  # made in a forked child: kept here for the next pass
            BOUNDED_MEDIANS.setdefault(surface, median)
        for k, error in errors:
            out[k] = np.maximum(out[k], error)
    with np.errstate(divide="ignore"):
        return [np.where(b > 0, np.sqrt(target / b), np.inf) for b in (b.reshape(-1, 3).max(axis=1) for b in out)]


def _standing_on(surface: Surface, pairs: list[tuple[int, TopoDS_Edge, TopoDS_Face, np.ndarray, np.ndarray]],
                 target: float) -> tuple[list[tuple[int, np.ndarray]], np.ndarray | None]:
    """([(k, error (3m,))], the surface's median_speeds over its bounds or None): standing_error / ROOM at each
    pair's params t (3m,) of its edge k on one face of `surface` (chords (3m, 3)), the stencil's steps STENCIL × the
    target on the surface and inside its bounds; pairs whose edge has no pcurve on the face are left out."""
    checkpoint()
    found = []
    for k, edge, face, t, chord in pairs:
        pcurve = BRep_Tool.CurveOnSurface_s(edge, face, 0.0, 0.0)
        if pcurve is not None:
            found.append((k, curve_values(Geom2dAdaptor_Curve(pcurve), t).reshape(-1, 2), chord))
    if not found:
        return [], None
    median = median_speeds(surface) if surface.bounds is not None else None
    uv = np.concatenate([uv for _, uv, _ in found])
    floor = LOCAL_FLOOR * np.concatenate([np.broadcast_to(median if median is not None else median_speeds(
        surface, (*np.sort(q[[0, -1], 0]), *np.sort(q[[0, -1], 1]))), q.shape) for _, q, _ in found])  # its ends' box
    h = np.concatenate([np.full(len(q), difference_step(q)) for _, q, _ in found])  # each pair's own step
    speeds = np.stack(surface_speeds(surface, uv, uv, step=h), axis=1)
    step = np.minimum(STENCIL * target / np.maximum(np.maximum(speeds, floor), 1e-300), uv_extent(surface) / 8)
    if surface.bounds is not None:  # the stencil inside the face: past its bounds a surface may be clamped
        u1, u2, v1, v2 = surface.bounds
        uv = np.clip(uv, np.array([u1, v1]) + step, np.array([u2, v2]) - step)
    room = ROOM if surface.surface_type not in ANALYTIC else 1.0  # an analytic face's edges are at the target
    error = standing_error(surface, uv, step, floor, np.concatenate([c for _, _, c in found]), APEX) / room
    bounds = np.cumsum([0] + [len(q) for _, q, _ in found])
    return [(k, error[a:b]) for (k, _, _), a, b in zip(found, bounds[:-1], bounds[1:], strict=True)], median


def has_pole(face: TopoDS_Face) -> bool:
    """True when the face has a degenerated edge (a pole or apex: a line of its (u,v) maps to one point)."""
    return any(BRep_Tool.Degenerated_s(e) for e in face_edges(face))
