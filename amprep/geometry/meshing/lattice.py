"""The quality mesher's lattice for curved faces whose (u,v) domain is a rectangle bounded by iso-lines: rows of
constant v, spaced and filled from the surface's curvatures (closed forms on cylinders, cones, spheres and tori;
sampled on B-splines and other surfaces evaluated in numpy) so that every triangle keeps the chord tolerance, zipped
into triangles row by row, with no Delaunay and no refinement rounds (seed 000's grid on curved faces, cut here to the
face by its own iso-lines)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from OCP.BRep import BRep_Tool
from OCP.TopoDS import TopoDS_Face

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.cad.occt_arrays import params_at_v, pcurve_values
from amprep.geometry.cad.surfaces import CONE, CYLINDER, SPHERE, TORUS, Surface
from amprep.geometry.cad.topology import Topology, face_edges, winds_inward
from amprep.geometry.core.progress import checkpoint
from amprep.geometry.measure.chordal import triangle_chordal_error
from amprep.geometry.meshing.local_refine import refine_patch
from amprep.geometry.meshing.occt_read import FacePatch
from amprep.geometry.meshing.shared_edges import ANALYTIC, MAX_PARTS, bend_sizes, edge_points, has_pole, split_segments
from amprep.geometry.meshing.uv_cdt import surface_speeds
from amprep.geometry.meshing.uv_seed import DIFF_STEP, polygon_area, second_form
from amprep.geometry.parallel.face_pool import map_faces

#: closed_form kinds (cad/surfaces.py) the lattice meshes: cylinder, cone, sphere, torus
KINDS = (CYLINDER, CONE, SPHERE, TORUS)
#: the share of the tolerance the lattice's own bound (|κu|·b² + |κv|·h²)/8 aims at, for what this second-order bound
#: leaves out (the curvature's change across a triangle): the measured worst is 0.93 of the tolerance on the sphere
#: and torus at 0.001 mm, and a triangle over it is refined like any other
SAFETY = 0.95
#: base over height b/h of the lattice's triangles: from 0.75 (rows 1.33 b apart where the surface is flat across the
#: rows: a staggered triangle's smallest angle 41°) to 1.5 (rows b/1.5 apart where it curves most across them: 53°);
#: 2 would save a tenth of a torus's triangles for a mean angle regularity of 0.60 instead of 0.77
ASPECT = (0.75, 1.5)
#: a row has at most this many times fewer points than the given boundary row before it
GROW = 1.6
#: samples of v where the row spacing is worked out
SAMPLES = 129
#: samples per direction of a surface with no closed form (its curvature taken there), and a first look's: a face
#: whose first look expects under half LATTICE_MIN triangles is not sampled further
SAMPLED = 33
GLANCE = 5
#: plan_lattices forks for the faces' fields where they sample this many points or more (about a tenth of a second)
FIELDS_PARALLEL_MIN = 60_000
#: a sampled surface is latticed only when the row step its curvature asks for varies by at most this factor along
#: its rows (the median row; the rows take the smallest step, so a larger spread makes flat triangles where it is
#: larger): a B-spline cylinder's is 1, a sheet whose parametrisation crowds toward one corner 20
ROW_SPREAD = 4.0
#: a boundary segment up to this much longer than the row's node step beside it is not cut (a cut would double it)
SPLIT_SLACK = 0.25
#: the left and right sides' nodes make one row when their v differ by under this × the rows' smallest spacing (two
#: pcurves inverted apart, occt_arrays.params_at_v)
ROW_MATCH = 1e-3
#: samples of a side edge's pcurve where its parameter is found for each row's v
PCURVE_SAMPLES = 257
#: a face needing more rows is left to the Delaunay path
MAX_ROWS = 100_000
#: a face whose lattice would have fewer triangles is left to the Delaunay path, whose refinement gives small faces
#: better angles (a short row's staggered ends, a given boundary row's count meeting the lattice's) and costs little.
#: At 100 a torus fillet band whose curvature along it changes across it (8,701 Delaunay triangles, OCCT 905) is a
#: lattice of 712, and OCCT's sample parts take 10 % fewer; but as1's bolts, tight in their plates' holes, then
#: get rows at the plates' faces, node on node with the holes' edges: distinct vertices one float32 apart, 430
#: non-manifold edges in the STL at 0.01 mm. Kept at 1,000 until rows keep clear of other solids' nodes
LATTICE_MIN = 1_000


@dataclass(frozen=True)
class Sides:
    """A face's boundary as the four sides of its (u,v) rectangle [u0,u1]×[v0,v1]: node indices into the loop, left and
    right (u = u0, u1) sorted by v, bottom and top (v = v0, v1) sorted by u; `pole` (bottom, top): the side is one
    point (a degenerated edge), its B-rep vertex or −1; `edges` (left, right, bottom, top): the one B-rep edge each
    side runs along, −1 where it runs along several."""

    u0: float
    u1: float
    v0: float
    v1: float
    left: np.ndarray
    right: np.ndarray
    bottom: np.ndarray
    top: np.ndarray
    pole: tuple[int, int]
    edges: tuple[int, int, int, int]


def rectangle_sides(loop: dict) -> Sides | None:  # type: ignore[type-arg]
    """The loop's Sides when every boundary segment runs along a side of its (u,v) bounding box and the loop goes once
    round it (its area is the box's); None otherwise (a face trimmed by anything but iso-lines)."""
    uv = loop["uv"]
    if len(uv) < 4:
        return None
    (u0, v0), (u1, v1) = uv.min(axis=0), uv.max(axis=0)
    if not (u1 - u0 > 0 and v1 - v0 > 0):
        return None
    eps_u, eps_v = 1e-9 * (1 + abs(u0) + abs(u1)), 1e-9 * (1 + abs(v0) + abs(v1))
    on = np.stack([abs(uv[:, 0] - u0) <= eps_u, abs(uv[:, 0] - u1) <= eps_u,
                   abs(uv[:, 1] - v0) <= eps_v, abs(uv[:, 1] - v1) <= eps_v], axis=1)  # left right bottom top
    if not (on & np.roll(on, -1, axis=0)).any(axis=1).all():
        return None
    area = polygon_area(uv)
    if abs(abs(area) - (u1 - u0) * (v1 - v0)) > 1e-6 * (u1 - u0) * (v1 - v0):
        return None
    idx = [np.flatnonzero(on[:, k]) for k in range(4)]
    idx = [i[np.argsort(uv[i, 1 if k < 2 else 0], kind="stable")] for k, i in enumerate(idx)]

    def pole(side: np.ndarray) -> int:
        vtx = loop["vertex"][side]
        return int(vtx[0]) if vtx[0] >= 0 and (vtx == vtx[0]).all() else -1

    def edge(k: int) -> int:
        seg = loop["segment"][on[:, k] & np.roll(on[:, k], -1)]
        return int(seg[0]) if len(seg) and (seg == seg[0]).all() else -1

    return Sides(float(u0), float(u1), float(v0), float(v1), *idx, pole=(pole(idx[2]), pole(idx[3])),
                 edges=(edge(0), edge(1), edge(2), edge(3)))


def _metric(surface: Surface, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(ρ, g, κu, κv) each (n,) at v on a closed-form surface: the row's radius (the length of S_u), the length of
    S_v, and the absolute normal curvatures along u and v (the principal ones: these surfaces are of revolution)."""
    kind, d = surface.closed_form  # type: ignore[misc]
    a, b = float(d[12]), float(d[13])
    one = np.ones_like(v)
    if kind == CYLINDER:  # radius a
        return a * one, one, one / a, 0 * one
    if kind == CONE:  # reference radius a, semi-angle b
        rho = np.abs(a + v * np.sin(b))
        return rho, one, np.abs(np.cos(b)) / np.maximum(rho, 1e-300), 0 * one
    if kind == SPHERE:  # radius a
        return np.abs(a * np.cos(v)), a * one, one / a, one / a
    rho = a + b * np.cos(v)  # torus, major a, minor b
    return rho, b * one, np.abs(np.cos(v)) / np.maximum(np.abs(rho), 1e-300), one / b


def spacing(ku: np.ndarray, kv: np.ndarray, tolerance: float, angular: float) -> tuple[np.ndarray, np.ndarray, bool]:
    """(b, h) each (n,): the spacing along a row (u) and between rows (v), in mm, where the curvatures (a bound of
    them) along u and v are ku, kv: b = λh with λ = √(κv/κu) clipped to ASPECT (the largest triangle for the bound)
    and (κu·b² + κv·h²)/8 = SAFETY × tolerance; neither over the arc of `angular` radians (the edges' angular
    deflection), b/h kept in ASPECT, neither under the tolerance (near a cone's apex, where κu grows without bound);
    and True when curvature alone set them (no arc cap) on at least 3/4 of the samples."""
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = np.where(ku > 0, np.clip(np.sqrt(kv / ku), *ASPECT), ASPECT[1])
    flat = (ku <= 0) & (kv <= 0)  # a flat patch of a curved face: sized like its curved part's gentlest
    h = np.sqrt(8 * SAFETY * tolerance / np.where(flat, 1.0, ku * lam**2 + kv))
    if flat.any():
        h = np.where(flat, h[~flat].max() if (~flat).any() else np.inf, h)
    b_arc = np.where(ku > 0, angular / np.maximum(ku, 1e-300), np.inf)
    h_arc = np.where(kv > 0, angular / np.maximum(kv, 1e-300), np.inf)
    by_curvature = bool(np.mean((lam * h > b_arc) | (h > h_arc)) <= 0.25) and bool(np.isfinite(h).all())
    b = np.minimum(lam * h, b_arc)
    h = np.minimum(np.minimum(h, h_arc), b / ASPECT[0])
    b = np.minimum(b, h * ASPECT[1])
    return np.maximum(b, tolerance), np.maximum(h, tolerance), by_curvature


@dataclass(frozen=True)
class Field:
    """The steps a lattice takes over a face's (u,v) rectangle, in parameters: `dv` (nv,) between rows at the samples
    `vs` (nv,) (the smallest over u); `per_u` (nv, nu) a row's nodes per unit of u at (us (nu,), vs), the inverse of
    their step (0 at a pole); `by_curvature` as spacing's."""

    us: np.ndarray
    vs: np.ndarray
    dv: np.ndarray
    per_u: np.ndarray
    by_curvature: bool
    expected: float = 0.0  # the triangles its rows make, about (expected_triangles), once plan_lattices planned it

    def per_u_at(self, v: np.ndarray) -> np.ndarray:
        """(k, nu) per_u at the rows v (k,), linear between the samples."""
        j = np.clip(np.searchsorted(self.vs, v) - 1, 0, len(self.vs) - 2)
        t = np.clip((v - self.vs[j]) / np.maximum(self.vs[j + 1] - self.vs[j], 1e-300), 0, 1)[:, None]
        return (1 - t) * self.per_u[j] + t * self.per_u[j + 1]


def field_of(surface: Surface, sides: Sides, tolerance: float, angular: float, samples: int = 33) -> Field | None:
    """The Field of a closed-form surface (exact curvatures, steps uniform along u) or of another surface evaluated in
    numpy (B-spline, Bézier, swept: |S_u|, |S_v| and the second form sampled on a `samples` × `samples` grid, the twist
    |M| added to both curvatures, which bounds the cross term 2M·du·dv); None for one evaluated by OCCT, or whose
    row step varies along a row by more than ROW_SPREAD."""
    if surface.closed_form is not None and surface.closed_form[0] in KINDS:
        vs = np.linspace(sides.v0, sides.v1, SAMPLES)
        rho, g, ku, kv = _metric(surface, vs)
        b, h, ok = spacing(ku, kv, tolerance, angular)
        per_u = rho / b
        return Field(np.array([sides.u0, sides.u1]), vs, h / g, np.stack([per_u, per_u], axis=1), ok)
    if not surface.exact_numpy or surface.closed_form is not None:
        return None
    t = (np.arange(samples) + 0.5) / samples
    us, vs = sides.u0 + (sides.u1 - sides.u0) * t, sides.v0 + (sides.v1 - sides.v0) * t
    grid = np.stack(np.meshgrid(us, vs), -1).reshape(-1, 2)  # row-major in v
    box = np.array([[sides.u0, sides.v0], [sides.u1, sides.v1]])
    su, sv = surface_speeds(surface, grid, box)
    L, M, N = second_form(surface, grid, DIFF_STEP * (box[1] - box[0]))
    if not (np.isfinite(su).all() and np.isfinite(sv).all()):
        return None
    su, sv = np.maximum(su, 1e-12), np.maximum(sv, 1e-12)
    twist = np.abs(M) / (su * sv)
    b, h, ok = spacing(np.abs(L) / su**2 + twist, np.abs(N) / sv**2 + twist, tolerance, angular)
    shape = (samples, samples)
    dv = (h / sv).reshape(shape)
    with np.errstate(divide="ignore", invalid="ignore"):  # a flat face (dv all inf): no spread, and not by_curvature
        spread = np.median(dv.max(axis=1) / dv.min(axis=1))
    if spread > ROW_SPREAD:  # no one row step fits: flat rows where it is larger
        return None
    return Field(us, vs, dv.min(axis=1), (su / b).reshape(shape), ok)


def row_values(field: Field, v0: float, v1: float) -> np.ndarray | None:
    """(N+1,) the rows' v from v0 to v1: equal steps of ∫ dv / field.dv, the rows' count, N its ceiling; None over
    MAX_ROWS, or where the edges' angular deflection rather than curvature sets the size (a coarse tolerance on a
    small radius: there the Delaunay path's grading makes fewer, better triangles)."""
    if not field.by_curvature:
        return None
    vs = np.concatenate([[v0], field.vs, [v1]])
    f = 1 / np.concatenate([field.dv[:1], field.dv, field.dv[-1:]])
    count = np.concatenate([[0.0], np.cumsum((f[1:] + f[:-1]) / 2 * np.diff(vs))])
    if not count[-1] < MAX_ROWS:
        return None
    n = max(1, int(np.ceil(count[-1] - 1e-9)))
    rows = np.interp(np.linspace(0, count[-1], n + 1), count, vs)
    rows[0], rows[-1] = v0, v1
    return rows


def _row_counts(field: Field, u0: float, u1: float, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(us (nu+2,), count (k, nu+2)): each row's cumulative node count ∫ per_u du from u0 along the samples."""
    us = np.concatenate([[u0], field.us, [u1]])
    d = field.per_u_at(rows)
    f = np.concatenate([d[:, :1], d, d[:, -1:]], axis=1)
    return us, np.concatenate([np.zeros((len(rows), 1)), np.cumsum((f[:, 1:] + f[:, :-1]) / 2 * np.diff(us), axis=1)],
                              axis=1)


def expected_triangles(field: Field, sides: Sides, rows: np.ndarray) -> float:
    """2 Σ_k (the row's node count) over the rows: about the lattice's triangle count."""
    return float(2 * _row_counts(field, sides.u0, sides.u1, rows)[1][:, -1].sum())


# ---- planning: before any face is meshed, the rows are written into the shared edge discretisation
def plan_lattices(faces: list[TopoDS_Face], surfaces: list[Surface], loops: list[list[dict]], topo: Topology,  # type: ignore[type-arg]
                  tolerance: float, angular: float, max_triangles: int = 10**12) -> list[Field | None]:
    """For each face a lattice can mesh (one loop, rectangle_sides, a field_of its surface, at least LATTICE_MIN
    triangles): its left and right side edges discretised at its rows (row_values), or, where an earlier face set
    one, the face takes those rows when both sides agree; its bottom and top edges' segments split to the steps of
    the row beside them. Returns each face's Field, None where it is not planned (only planned faces are meshed by
    mesh_lattice). output_too_large, before any node is made, when the planned lattices would exceed max_triangles.
    The faces' fields and rows (_field_and_rows) are worked out first, side by side: only the sides are shared."""
    fixed: set[int] = getattr(topo, "_lattice_edges", set())
    planned: list[Field | None] = [None] * len(faces)
    expected = 0.0
    free_form: dict[int, list[tuple[int, TopoDS_Face, Surface]]] = {}  # edge: the free-form faces it bounds
    for k, (face, surface) in enumerate(zip(faces, surfaces, strict=True)):
        if surface is not None and surface.surface_type not in ANALYTIC:
            for e in face_edges(face):
                free_form.setdefault(topo.edge_index(e), []).append((k, face, surface))
    candidates = {k: sides for k, (surface, lps) in enumerate(zip(surfaces, loops, strict=True))
                  if surface is not None and len(lps) == 1 and (sides := rectangle_sides(lps[0])) is not None
                  and min(sides.edges[:2]) >= 0}
    order = sorted(candidates, key=lambda k: (surfaces[k].closed_form is not None, k))  # the sampled ones cost more
    fields = map_faces(lambda k: _field_and_rows(surfaces[k], candidates[k], tolerance, angular), order,
                       cost=[1.0 if surfaces[k].closed_form is not None else SAMPLED**2 for k in order],
                       parallel_min=FIELDS_PARALLEL_MIN)
    for k, (face, surface) in enumerate(zip(faces, surfaces, strict=True)):
        checkpoint()
        if fields.get(k) is None:
            continue
        sides, (field, rows) = candidates[k], fields[k]
        n = expected_triangles(field, sides, rows)
        if n < LATTICE_MIN and not (surface.closed_form is not None and has_pole(face)):
            continue
        edges = {e: edge for e, edge in ((topo.edge_index(x), x) for x in face_edges(face))}
        lr = sides.edges[:2]
        given = [np.sort(pcurve_values(face, edges[e], topo.edge_params[e])[:, 1]) for e in lr if e in fixed]
        if given:
            if any(len(g) != len(given[0]) or not np.allclose(g, given[0], rtol=0, atol=1e-9) for g in given):
                continue
            rows = given[0]
        else:
            neighbours = {e: [(f, s) for j, f, s in free_form.get(e, []) if j != k] for e in set(lr)}
            rows = _rows_for_neighbours(face, edges, neighbours, rows, tolerance)  # type: ignore[arg-type]
            if rows is None:
                continue
            n = expected_triangles(field, sides, rows)  # type: ignore[arg-type]
        expected += n
        if expected > max_triangles:
            raise AmprepError(ErrorCode.OUTPUT_TOO_LARGE, f"at {tolerance:g} mm the quality mesher's rows alone would "
                              f"make about {expected:,.0f} triangles, over the limit of {max_triangles:,}: use a "
                              "coarser tolerance, the default mesher or a higher max_triangles")
        new = {e: params_at_v(face, edges[e], rows, PCURVE_SAMPLES) for e in set(lr) if e not in fixed}
        if any(p is None for p in new.values()):
            continue
        for e, p in new.items():
            topo.edge_params[e] = p
            fixed.add(e)
        for e, v in ((sides.edges[2], rows[0]), (sides.edges[3], rows[-1])):
            if e >= 0 and e not in fixed and not BRep_Tool.Degenerated_s(edges[e]):
                _split_to_field(face, edges[e], topo, field, float(v))  # type: ignore[arg-type]
        planned[k] = replace(field, expected=n)  # type: ignore[arg-type]
    topo._lattice_edges = fixed  # type: ignore[attr-defined]
    return planned


def _field_and_rows(surface: Surface, sides: Sides, tolerance: float,
                    angular: float) -> tuple[Field, np.ndarray] | None:
    """(field_of the face's surface on its sides, its row_values) or None: no field or rows, or (a sampled field) too
    few triangles by a GLANCE² sampling to be worth SAMPLED²; the same in any process (plan_lattices forks for them)."""
    if surface.closed_form is None:
        glance = field_of(surface, sides, tolerance, angular, GLANCE)
        rows = None if glance is None else row_values(glance, sides.v0, sides.v1)
        if rows is None or expected_triangles(glance, sides, rows) < LATTICE_MIN / 2:  # type: ignore[arg-type]
            return None
    field = field_of(surface, sides, tolerance, angular, SAMPLED)
    rows = None if field is None else row_values(field, sides.v0, sides.v1)
    return None if rows is None else (field, rows)  # type: ignore[return-value]


def _rows_for_neighbours(face: TopoDS_Face, edges: dict, neighbours: dict[int, list[tuple[TopoDS_Face, Surface]]],  # type: ignore[type-arg]
                         rows: np.ndarray, tolerance: float) -> np.ndarray | None:
    """The rows (N+1,) with each step cut where a side edge's segment at them is longer than a free-form face on its
    other side allows (shared_edges.bend_sizes: a triangle of that face on a longer segment is a sliver); None when a
    side's v is not monotone along it (occt_arrays.params_at_v)."""
    parts = np.ones(len(rows) - 1, np.int64)
    for e, others in neighbours.items():
        if not others:
            continue
        params = params_at_v(face, edges[e], rows, PCURVE_SAMPLES)
        if params is None:
            return None
        seg = np.linalg.norm(np.diff(edge_points(edges[e], params), axis=0), axis=1)
        need = np.clip(np.ceil(seg / bend_sizes(edges[e], params, others, tolerance) - SPLIT_SLACK), 1, MAX_PARTS)
        pc = BRep_Tool.CurveOnSurface_s(edges[e], face, 0.0, 0.0)
        if (pc.Value(float(params[0])).Y() > pc.Value(float(params[-1])).Y()) != (rows[0] > rows[-1]):
            need = need[::-1]  # params run along the edge, rows along v
        parts = np.maximum(parts, need.astype(np.int64))
    if not (parts > 1).any():
        return rows
    up = rows[0] <= rows[-1]
    cut = split_segments(rows if up else rows[::-1], parts if up else parts[::-1])
    return cut if up else cut[::-1]


def _split_to_field(face: TopoDS_Face, edge, topo: Topology, field: Field, v: float) -> None:  # type: ignore[no-untyped-def]
    """Cut the segments of an iso-v edge (a bottom or top side) longer in u than the field's node step at that row."""
    ei = topo.edge_index(edge)
    params = topo.edge_params[ei]
    u = pcurve_values(face, edge, params)[:, 0]
    density = np.interp((u[:-1] + u[1:]) / 2, field.us, field.per_u_at(np.array([v]))[0])
    parts = np.maximum(np.ceil(np.abs(np.diff(u)) * density - SPLIT_SLACK), 1).astype(np.int64)
    if (parts > 1).any():
        topo.edge_params[ei] = split_segments(params, parts)


# ---- meshing
def zip_rows(a: np.ndarray, au: np.ndarray, b: np.ndarray, bu: np.ndarray, pair: np.ndarray,
         pb: np.ndarray) -> np.ndarray:
    """(m, 3) triangles, counter-clockwise in (u,v), between consecutive rows: a, au (n,) the lower rows' node ids and
    u, concatenated, `pair` (n,) which pair each belongs to (sorted); b, bu, pb the upper rows'. Each pair's segments,
    merged by their midpoints' u (a lower one first on a tie), make one triangle each: a lower segment with the
    upper node reached by then, or an upper segment with the lower node reached. The merge is two searchsorted calls
    over keys pair·W + u (W wider than every row), so no sort."""
    ia = np.flatnonzero(pair[:-1] == pair[1:])  # segment starts: consecutive nodes of one pair
    ib = np.flatnonzero(pb[:-1] == pb[1:])
    ka, kb = (au[ia] + au[ia + 1]) / 2, (bu[ib] + bu[ib + 1]) / 2
    lo = min(au.min(initial=0.0), bu.min(initial=0.0))
    width = max(au.max(initial=0.0), bu.max(initial=0.0)) - lo + 1.0
    key_a, key_b = pair[ia] * width + (ka - lo), pb[ib] * width + (kb - lo)
    # the node reached on the other row: its segments before this midpoint, plus one node per earlier pair
    b_at = np.searchsorted(key_b, key_a, side="left") + pair[ia]
    a_at = np.searchsorted(key_a, key_b, side="right") + pb[ib]
    lower = np.stack([a[ia], a[ia + 1], b[b_at]], axis=1)
    upper = np.stack([a[a_at], b[ib + 1], b[ib]], axis=1)
    return np.concatenate([lower, upper])


def _row_nodes(field: Field, sides: Sides, rows: np.ndarray, n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(row (m,), u (m,)): the nodes of the rows (k,) strictly between u0 and u1, n (k,) segments each at equal steps
    of their cumulative count (_row_counts); every odd row staggered half a step (its end segments half long)."""
    if not len(rows):  # one strip: no row between the two sides
        return np.zeros(0, np.int64), np.zeros(0)
    stagger = np.arange(len(rows)) % 2 == 1
    us, count = _row_counts(field, sides.u0, sides.u1, rows)
    per = np.where(stagger, n, n - 1)
    row = np.repeat(np.arange(len(rows)), per)
    j = np.arange(len(row)) - np.repeat(np.cumsum(per) - per, per)
    target = count[row, -1] * (j + np.where(stagger[row], 0.5, 1.0)) / n[row]
    big = float(count[:, -1].max()) + 1.0  # rows laid end to end: one monotone interpolation for all
    offset = np.arange(len(rows))[:, None] * big
    return row, np.interp(target + row * big, (count + offset).ravel(), np.tile(us, len(rows)))


def mesh_lattice(face_id: int, face: TopoDS_Face, loops: list[dict], surface: Surface, field: Field,  # type: ignore[type-arg]
                 tolerance: float, order: int = 6) -> FacePatch | None:
    """A FacePatch of the face's lattice (its Field from plan_lattices), measured (and refined locally where a triangle
    is over the tolerance); None when the face is no longer a rectangle or its left and right sides' rows disagree
    (an edge cut since the plan), or a local refinement cannot be made."""
    if len(loops) != 1:
        return None
    loop = loops[0]
    sides = rectangle_sides(loop)
    if sides is None or len(sides.left) != len(sides.right) or len(sides.left) < 2:
        return None
    uv_loop = loop["uv"]
    left, right = uv_loop[sides.left, 1], uv_loop[sides.right, 1]
    if np.abs(left - right).max() > ROW_MATCH * np.diff(left).min():  # the two sides' nodes make the same rows
        return None
    rows = (left + right) / 2
    rows[0], rows[-1] = sides.v0, sides.v1
    built = _lattice_nodes(loop, sides, rows, surface, field)
    if built is None:
        return None
    uv, vertex, edge, param, tris = built
    xyz = surface.evaluate(uv)
    err = triangle_chordal_error(xyz[tris], uv[tris], surface, order, stop=tolerance)
    patch = FacePatch(face_id, xyz, uv, tris[:, [0, 2, 1]] if winds_inward(face) else tris, vertex, edge, param,
                      meshed_by="lattice", error=err)
    if (err > tolerance).any():
        return refine_patch(patch, err, surface, tolerance, order)
    return patch


def _lattice_nodes(loop: dict, sides: Sides, rows: np.ndarray, surface: Surface,  # type: ignore[type-arg]
                   field: Field) -> tuple[np.ndarray, ...] | None:
    """(uv (k, 2), vertex, edge, param (k,), tris (t, 3)) of the lattice: the loop's nodes, the interior rows' nodes
    and, at a pole, one node per triangle of its fan (all keyed to the pole's vertex, each at its triangle's u)."""
    uv_loop = loop["uv"]
    nb, nrow = len(uv_loop), len(rows)
    full = surface.periods[0] is not None and abs(sides.u1 - sides.u0 - surface.periods[0]) <= 1e-9
    n = np.maximum(np.ceil(_row_counts(field, sides.u0, sides.u1, rows)[1][:, -1] - 1e-9).astype(np.int64),
                   3 if full else 1)
    k = np.arange(nrow)
    for end, side, dist in ((0, sides.bottom, k), (1, sides.top, nrow - 1 - k)):
        if sides.pole[end] < 0:  # a row near a finely cut boundary row is graded towards it
            far = np.minimum(dist, 1000).astype(float)  # 1.6^1000 ~ 1e204: every side's count is under one there
            n = np.maximum(n, np.ceil((len(side) - 1) / GROW ** far).astype(np.int64))
    r_row, r_u = _row_nodes(field, sides, rows[1:-1], n[1:-1])
    r_row += 1
    # each row's node ids in u order: left end, interior, right end (the loop's side nodes)
    ids_inner = nb + np.arange(len(r_row))
    row_ids = [sides.bottom, *([] for _ in range(nrow - 2)), sides.top]
    row_u = [uv_loop[sides.bottom, 0], *([] for _ in range(nrow - 2)), uv_loop[sides.top, 0]]
    splits = np.searchsorted(r_row, np.arange(1, nrow))
    for i in range(1, nrow - 1):
        sl = slice(splits[i - 1], splits[i])
        row_ids[i] = np.concatenate([[sides.left[i]], ids_inner[sl], [sides.right[i]]])
        row_u[i] = np.concatenate([[sides.u0], r_u[sl], [sides.u1]])
    uv = np.concatenate([uv_loop, np.stack([r_u, rows[r_row]], axis=1)])
    vertex = np.concatenate([loop["vertex"], np.full(len(r_row), -1, np.int64)])
    edge = np.concatenate([loop["edge"], np.full(len(r_row), -1, np.int64)])
    param = np.concatenate([loop["param"], np.full(len(r_row), np.nan)])
    lo = [p for p in range(nrow - 1) if not (p == 0 and sides.pole[0] >= 0) and not (p == nrow - 2 and sides.pole[1] >= 0)]
    tris = [np.zeros((0, 3), np.int64)]
    if lo:
        a = np.concatenate([row_ids[p] for p in lo])
        au = np.concatenate([row_u[p] for p in lo])
        pair = np.repeat(np.arange(len(lo)), [len(row_ids[p]) for p in lo])
        bb = np.concatenate([row_ids[p + 1] for p in lo])
        bu = np.concatenate([row_u[p + 1] for p in lo])
        pb = np.repeat(np.arange(len(lo)), [len(row_ids[p + 1]) for p in lo])
        tris.append(zip_rows(a, au, bb, bu, pair, pb))
    extra_uv, extra_v = [uv], [vertex]
    count = len(uv)
    for end in (0, 1):  # fans at poles
        if sides.pole[end] < 0:
            continue
        if nrow < 3:
            return None
        ring = row_ids[1] if end == 0 else row_ids[-2]
        ru = row_u[1] if end == 0 else row_u[-2]
        m = len(ring) - 1
        pole_ids = count + np.arange(m)
        count += m
        extra_uv.append(np.stack([(ru[:-1] + ru[1:]) / 2, np.full(m, rows[0] if end == 0 else rows[-1])], axis=1))
        extra_v.append(np.full(m, sides.pole[end], np.int64))
        fan = np.stack([pole_ids, ring[1:], ring[:-1]], axis=1) if end == 0 else \
            np.stack([ring[:-1], ring[1:], pole_ids], axis=1)
        tris.append(fan)
    uv = np.concatenate(extra_uv)
    vertex = np.concatenate(extra_v)
    k_extra = len(uv) - len(edge)
    edge = np.concatenate([edge, np.full(k_extra, -1, np.int64)])
    param = np.concatenate([param, np.full(k_extra, np.nan)])
    tris = np.concatenate(tris)
    used = np.zeros(len(uv), bool)
    used[tris] = True
    remap = np.cumsum(used) - 1
    return uv[used], vertex[used], edge[used], param[used], remap[tris]
