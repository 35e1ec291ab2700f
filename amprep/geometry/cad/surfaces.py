"""Exact evaluation S(u,v) of a face's surface, vectorised: closed forms and rational B-splines in numpy."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property, partial

import numpy as np
from OCP.BRepAdaptor import BRepAdaptor_Surface
from OCP.GeomAbs import (
    GeomAbs_BezierSurface,
    GeomAbs_BSplineSurface,
    GeomAbs_Cone,
    GeomAbs_Cylinder,
    GeomAbs_OffsetSurface,
    GeomAbs_Plane,
    GeomAbs_Sphere,
    GeomAbs_SurfaceOfExtrusion,
    GeomAbs_SurfaceOfRevolution,
    GeomAbs_Torus,
)
from OCP.GeomConvert import GeomConvert
from OCP.TopoDS import TopoDS_Face

from amprep.geometry.cad.bspline import (
    COMPILED_MIN_POINTS,
    eval_homogeneous,
    fork_safe_threads,
    homogeneous_poles,
    kernel_arguments,
)
from amprep.geometry.cad.occt_arrays import array1, vec
from amprep.geometry.cad.swept import curve_of, extrusion, revolution
from amprep.geometry.core.compiled import use_compiled
from amprep.geometry.core.vectors import cross

SURFACE_TYPES = {
    GeomAbs_Plane: "plane", GeomAbs_Cylinder: "cylinder", GeomAbs_Cone: "cone", GeomAbs_Sphere: "sphere",
    GeomAbs_Torus: "torus", GeomAbs_BSplineSurface: "bspline", GeomAbs_BezierSurface: "bezier",
    GeomAbs_SurfaceOfRevolution: "revolution", GeomAbs_SurfaceOfExtrusion: "extrusion",
    GeomAbs_OffsetSurface: "offset",
}


def _frame(ax3) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # type: ignore[no-untyped-def]
    return vec(ax3.Location()), vec(ax3.XDirection()), vec(ax3.YDirection()), vec(ax3.Direction())


@dataclass(frozen=True, eq=False)
class Surface:
    """A face's surface in world coordinates (mm); `evaluate(uv (N, 2)) -> (N, 3)`; `exact_numpy` False
    where it falls back to OCCT's point-by-point evaluator."""

    surface_type: str
    evaluate: Callable[[np.ndarray], np.ndarray]
    exact_numpy: bool = True
    data: dict | None = None
    periods: tuple[float | None, float | None] = (None, None)  # period of u and of v where periodic
    bounds: tuple[float, float, float, float] | None = None  # (u1, u2, v1, v2) of the face
    closed_form: tuple[int, np.ndarray] | None = None  # (kind, O X Y Z a b) for the compiled chordal kernel

    @cached_property
    def folds(self) -> tuple[tuple[int, float], ...]:
        """The lines of (u,v) inside the face that S maps to one point (fold_lines; none without bounds)."""
        return () if self.bounds is None else tuple(fold_lines(self, self.bounds))

    @property
    def affine(self) -> bool:
        """True when S is affine in (u,v) (a plane): chordal error then has an exact corner bound."""
        return self.surface_type == "plane"


def uv_extent(surface: Surface) -> np.ndarray:
    """(2,) the face's (u,v) extent (1 where unknown), the scale of tangents' difference steps."""
    if surface.bounds is None:
        return np.array([1.0, 1.0])
    u1, u2, v1, v2 = surface.bounds
    return np.array([max(u2 - u1, 1e-9), max(v2 - v1, 1e-9)])


def parameter_box(surface: Surface) -> tuple[np.ndarray, np.ndarray]:
    """((2,) low, (2,) high) (u,v) of the face's bounds (to 1e-9 of its extent) in each non-periodic parameter, ±inf
    in a periodic or unbounded one: where S is the face's surface (a B-spline past its knots is an extrapolation)."""
    lo, hi = np.full(2, -np.inf), np.full(2, np.inf)
    if surface.bounds is not None:
        span = uv_extent(surface)
        u1, u2, v1, v2 = surface.bounds
        for k, (a, b) in enumerate(((u1, u2), (v1, v2))):
            if not surface.periods[k] and np.isfinite(a) and np.isfinite(b):
                lo[k], hi[k] = a - 1e-9 * span[k], b + 1e-9 * span[k]
    return lo, hi


def tangents(surface: Surface, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(S_u, S_v) (n, 3) each at (n, 2) uv, by central differences of 1e-6 × uv_extent."""
    h = 1e-6 * uv_extent(surface)
    n = len(uv)
    s = surface.evaluate(np.concatenate([uv + [h[0], 0], uv - [h[0], 0], uv + [0, h[1]], uv - [0, h[1]]]))  # one call
    return (s[:n] - s[n:2 * n]) / (2 * h[0]), (s[2 * n:3 * n] - s[3 * n:]) / (2 * h[1])


def value_and_tangents(surface: Surface, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(S, S_u, S_v) (n, 3) each at (n, 2) uv, tangents as `tangents` gives them, from one evaluation of 5n points."""
    h = 1e-6 * uv_extent(surface)
    n = len(uv)
    s = surface.evaluate(np.concatenate([uv, uv + [h[0], 0], uv - [h[0], 0], uv + [0, h[1]], uv - [0, h[1]]]))
    return s[:n], (s[n:2 * n] - s[2 * n:3 * n]) / (2 * h[0]), (s[3 * n:4 * n] - s[4 * n:]) / (2 * h[1])


def surface_normals(surface: Surface, uv: np.ndarray) -> np.ndarray:
    """(n, 3) unit normals S_u × S_v / |S_u × S_v| at (n, 2) uv; zero where the two are parallel (a pole, an apex)."""
    su, sv = tangents(surface, np.asarray(uv, float))
    n = cross(su, sv)
    size = np.linalg.norm(n, axis=1, keepdims=True)
    scale = np.linalg.norm(su, axis=1, keepdims=True) * np.linalg.norm(sv, axis=1, keepdims=True)
    return np.where(size > 1e-9 * scale, n / np.where(size > 0, size, 1.0), 0.0)


def project_points(surface: Surface, points: np.ndarray, uv0: np.ndarray, iterations: int = 12,
                   within: bool = False, settle: float = 1e-12) -> tuple[np.ndarray, np.ndarray]:
    """Gauss–Newton on |S(u,v) − p|² from uv0, all points at once, derivatives by central differences:
    ((n, 2) (u,v), (n,) distance |S(u,v) − p|), stopping once no point moves by `settle` × the (u,v) extent. within:
    each non-periodic parameter kept in the face's bounds (points of the face lie there; a closed B-spline's far
    half, or its extrapolation past the knots, is another face's)."""
    uv, dist, _ = project_settled(surface, points, uv0, iterations, within, settle)
    return uv, dist


def project_settled(surface: Surface, points: np.ndarray, uv0: np.ndarray, iterations: int = 12,
                    within: bool = False, settle: float = 1e-12) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """project_points' ((n, 2) uv, (n,) distance) and (n,) bool: the points whose last step moved them by under
    `settle` × the extent (the others ran out of iterations: bouncing off an apex the bounds hold them at, say). Each
    point stops at its own settling, so its result does not depend on the other points of the call."""
    uv = np.array(uv0, dtype=float)
    last = np.zeros(len(uv))
    span = uv_extent(surface)
    lo, hi = parameter_box(surface) if within else (np.full(2, -np.inf), np.full(2, np.inf))
    kernel = _compiled_projection(surface, len(uv))
    if kernel is not None:
        dist = np.empty(len(uv))
        uv = np.ascontiguousarray(uv)
        kernel(np.ascontiguousarray(points, dtype=float), uv, lo, hi, span, int(iterations), float(settle), dist, last)
        return uv, dist, last < settle
    uv = np.clip(uv, lo, hi)
    live = np.arange(len(uv))
    for _ in range(iterations):
        if not len(live):
            break
        q = uv[live]
        at, su, sv = value_and_tangents(surface, q)
        r = at - points[live]
        a, b, c = (su * su).sum(1), (su * sv).sum(1), (sv * sv).sum(1)
        gu, gv = (su * r).sum(1), (sv * r).sum(1)
        det = a * c - b * b
        ok = np.abs(det) > 1e-30
        du = np.where(ok, -(c * gu - b * gv) / np.where(ok, det, 1), 0.0)
        dv = np.where(ok, -(a * gv - b * gu) / np.where(ok, det, 1), 0.0)
        step = np.stack([du, dv], 1)
        limit = 0.25 * span  # no jumps across the domain from a bad start
        new = np.clip(q + np.clip(step, -limit, limit), lo, hi)
        last[live] = np.abs((new - q) / span).max(axis=1, initial=0)
        uv[live] = new
        live = live[last[live] >= settle]  # the step taken: a point held at its face's bounds asks to go on out
    return uv, np.linalg.norm(surface.evaluate(uv) - points, axis=1), last < settle


_projection = None  # the _projection_kernel module once loaded


def _compiled_projection(surface: Surface, points: int) -> Callable[..., None] | None:
    """The compiled form of project_settled's loop for a closed-form or B-spline surface (_projection_kernel.py), where
    core.compiled.use_compiled says (the computation's choice, else a call of ≥ COMPILED_MIN_POINTS points); None:
    numpy's."""
    kind = surface.closed_form
    d = surface.data if surface.surface_type in ("bspline", "bezier") else None
    if (kind is None and d is None) or not use_compiled(points, COMPILED_MIN_POINTS):
        return None
    global _projection
    if _projection is None:  # imported once: a placement asks for it in thousands of calls of a few points
        fork_safe_threads()
        from amprep.geometry.cad import _projection_kernel

        _projection = _projection_kernel
    if kind is not None:
        return partial(_projection.project_closed_form, kind[0], kind[1])
    return partial(_projection.project_bspline, *kernel_arguments(d))


def plane(o: np.ndarray, x: np.ndarray, y: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    """S(u,v) = O + u·X + v·Y."""
    return lambda uv: o + uv[:, :1] * x + uv[:, 1:2] * y


def cylinder(o: np.ndarray, x: np.ndarray, y: np.ndarray, z: np.ndarray, r: float) -> Callable[[np.ndarray], np.ndarray]:
    """S(u,v) = O + r(cos u·X + sin u·Y) + v·Z."""
    return lambda uv: o + r * (np.cos(uv[:, :1]) * x + np.sin(uv[:, :1]) * y) + uv[:, 1:2] * z


def cone(o: np.ndarray, x: np.ndarray, y: np.ndarray, z: np.ndarray, r: float, a: float) -> Callable[[np.ndarray], np.ndarray]:
    """S(u,v) = O + (R + v sin α)(cos u·X + sin u·Y) + v cos α·Z."""
    def f(uv: np.ndarray) -> np.ndarray:
        rad = r + uv[:, 1:2] * np.sin(a)
        return o + rad * (np.cos(uv[:, :1]) * x + np.sin(uv[:, :1]) * y) + uv[:, 1:2] * np.cos(a) * z
    return f


def sphere(o: np.ndarray, x: np.ndarray, y: np.ndarray, z: np.ndarray, r: float) -> Callable[[np.ndarray], np.ndarray]:
    """S(u,v) = O + r cos v (cos u·X + sin u·Y) + r sin v·Z."""
    def f(uv: np.ndarray) -> np.ndarray:
        cv = np.cos(uv[:, 1:2])
        return o + r * cv * (np.cos(uv[:, :1]) * x + np.sin(uv[:, :1]) * y) + r * np.sin(uv[:, 1:2]) * z
    return f


def torus(o: np.ndarray, x: np.ndarray, y: np.ndarray, z: np.ndarray, big: float, small: float) -> Callable[[np.ndarray], np.ndarray]:
    """S(u,v) = O + (R + r cos v)(cos u·X + sin u·Y) + r sin v·Z."""
    def f(uv: np.ndarray) -> np.ndarray:
        rad = big + small * np.cos(uv[:, 1:2])
        return o + rad * (np.cos(uv[:, :1]) * x + np.sin(uv[:, :1]) * y) + small * np.sin(uv[:, 1:2]) * z
    return f


def bspline_data(surf) -> dict:  # type: ignore[no-untyped-def]
    """Poles (nu, nv, 3), weights (nu, nv), flat knots and degrees of a Geom_BSplineSurface (made non-periodic);
    `uperiod`/`vperiod` = (first, last) of a periodic direction, into which parameters are wrapped."""
    u1, u2, v1, v2 = surf.Bounds()
    uperiod = (u1, u2) if surf.IsUPeriodic() else None
    vperiod = (v1, v2) if surf.IsVPeriodic() else None
    if surf.IsUPeriodic() or surf.IsVPeriodic():
        surf = surf.Copy()
        if surf.IsUPeriodic():
            surf.SetUNotPeriodic()
        if surf.IsVPeriodic():
            surf.SetVNotPeriodic()
    nu, nv = surf.NbUPoles(), surf.NbVPoles()
    poles = np.array([[vec(surf.Pole(i, j)) for j in range(1, nv + 1)] for i in range(1, nu + 1)])
    if surf.IsURational() or surf.IsVRational():
        weights = np.array([[surf.Weight(i, j) for j in range(1, nv + 1)] for i in range(1, nu + 1)])
    else:  # OCCT keeps no weight array for a polynomial surface (its copy may report 0)
        weights = np.ones((nu, nv))
    return dict(
        poles=poles.reshape(nu, nv, 3), weights=weights.reshape(nu, nv),
        uknots=array1(surf.UKnotSequence()), vknots=array1(surf.VKnotSequence()),
        udeg=surf.UDegree(), vdeg=surf.VDegree(), uperiod=uperiod, vperiod=vperiod,
    )


def wrap_periodic(uv: np.ndarray, uperiod: tuple[float, float] | None, vperiod: tuple[float, float] | None) -> np.ndarray:
    """(N, 2) parameters with each periodic one moved into its base period: t ← a + (t − a) mod (b − a)."""
    if uperiod is None and vperiod is None:
        return uv
    out = np.array(uv, dtype=float)
    for k, per in ((0, uperiod), (1, vperiod)):
        if per is not None:
            a, b = per
            out[:, k] = a + np.mod(out[:, k] - a, b - a)
    return out


def nearest_copy(uv: np.ndarray, guess: np.ndarray, periods: tuple[float | None, float | None]) -> np.ndarray:
    """uv shifted by whole periods to lie nearest `guess` (both (N, 2)); `periods` a Surface's (None: not periodic)."""
    out = uv.copy()
    for d, per in enumerate(periods):
        if per:
            out[:, d] += np.round((guess[:, d] - uv[:, d]) / per) * per
    return out


#: Surface.closed_form's kinds (the compiled kernels' and the lattice's codes)
PLANE, CYLINDER, CONE, SPHERE, TORUS = 0, 1, 2, 3, 4


def _closed_form(kind: int, frame: tuple[np.ndarray, ...], a: float = 0.0, b: float = 0.0) -> tuple[int, np.ndarray]:
    """(kind, (14,) O X Y Z a b): the compiled kernel's description of a closed-form surface (_chordal_kernel.py)."""
    return kind, np.concatenate([*frame, [a, b]]).astype(np.float64)


def _occt_loop(adaptor: BRepAdaptor_Surface) -> Callable[[np.ndarray], np.ndarray]:
    def f(uv: np.ndarray) -> np.ndarray:
        return np.array([adaptor.Value(u, v).Coord() for u, v in uv], dtype=float).reshape(-1, 3)
    return f


def surface_of(face: TopoDS_Face) -> Surface:
    """The exact surface of a face, located in world coordinates, with a vectorised evaluator."""
    from dataclasses import replace

    ad = BRepAdaptor_Surface(face, True)
    surf = _surface(ad)
    periods = (ad.UPeriod() if ad.IsUPeriodic() else None, ad.VPeriod() if ad.IsVPeriodic() else None)
    bounds = (ad.FirstUParameter(), ad.LastUParameter(), ad.FirstVParameter(), ad.LastVParameter())
    return replace(surf, periods=periods, bounds=bounds)


#: an iso-line is one point when its samples lie within this fraction of the surface's largest iso-line of each other
FOLD_SPREAD = 1e-6
#: iso-lines sampled across a free-form face each way in the search for folds (an n × n grid), and points along each
FOLD_SAMPLES, FOLD_POINTS = 9, 9


def fold_lines(surface: Surface, bounds: tuple[float, float, float, float]) -> list[tuple[int, float]]:
    """(direction, t) of each iso-line (0: u = t, 1: v = t) strictly inside the face's bounds (u1, u2, v1, v2) that
    S maps to one point, with no degenerated edge to mark it: a horn or spindle torus's (r ≥ R) axis point at
    cos v = −R/r, a cone's apex at v = −R/sin α; on B-spline, Bézier and revolved faces the iso-lines' spread
    sampled and each interior dip followed to its minimum."""
    if not np.isfinite(bounds).all():
        return []
    lo, hi = np.array(bounds[::2]), np.array(bounds[1::2])
    margin = 1e-9 * np.maximum(hi - lo, 1e-300)
    if surface.closed_form is not None:
        kind, prm = surface.closed_form
        if kind == TORUS and prm[13] >= prm[12]:
            c = np.arccos(-prm[12] / prm[13])
            t = np.array([c, -c])
            t = t + np.ceil((lo[1] + margin[1] - t) / (2 * np.pi)) * 2 * np.pi  # the first copy past v1
        elif kind == CONE and np.sin(prm[13]) != 0:
            t = np.array([-prm[12] / np.sin(prm[13])])
        else:
            return []
        return [(1, float(x)) for x in np.unique(t) if lo[1] + margin[1] < x < hi[1] - margin[1]]
    if surface.surface_type not in ("bspline", "bezier", "revolution") or not surface.exact_numpy:
        return []
    g = [np.linspace(lo[d], hi[d], FOLD_SAMPLES) for d in (0, 1)]
    xyz = surface.evaluate(np.stack(np.meshgrid(*g, indexing="ij"), axis=-1).reshape(-1, 2))
    xyz = xyz.reshape(FOLD_SAMPLES, FOLD_SAMPLES, 3)
    spreads = (np.abs(xyz - xyz[:, :1]).max(axis=(1, 2)), np.abs(xyz - xyz[:1]).max(axis=(0, 2)))  # u = t, v = t
    size = max(spreads[0].max(), spreads[1].max())
    if not size > 0:
        return []
    found = []
    for d, (t, s) in enumerate(zip(g, spreads, strict=True)):
        dip = np.flatnonzero((s[1:-1] <= s[:-2]) & (s[1:-1] <= s[2:]) & (s[1:-1] < 0.25 * s.max())) + 1
        for i in dip:
            x = _narrowed(surface, d, t[i - 1], t[i + 1], lo, hi, FOLD_SPREAD * size)
            if x is not None and lo[d] + margin[d] < x < hi[d] - margin[d]:
                found.append((d, x))
    return found


def _spread(surface: Surface, d: int, t: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(n,) max |S − S₀| over FOLD_POINTS points of each iso-line (direction d) at t (n,) across the face."""
    uv = np.empty((len(t), FOLD_POINTS, 2))
    uv[..., d], uv[..., 1 - d] = t[:, None], np.linspace(lo[1 - d], hi[1 - d], FOLD_POINTS)[None, :]
    xyz = surface.evaluate(uv.reshape(-1, 2)).reshape(len(t), FOLD_POINTS, 3)
    return np.abs(xyz - xyz[:, :1]).max(axis=(1, 2))


def _narrowed(surface: Surface, d: int, a: float, b: float, lo: np.ndarray, hi: np.ndarray,
              point: float) -> float | None:
    """t in [a, b] where the iso-line's spread is at most `point`, by golden section on its minimum (60 steps), or
    None; given up once ten steps shrink the least spread seen less than tenfold (a fold's falls as |t − t*|^k,
    by over a hundred)."""
    g = (np.sqrt(5) - 1) / 2
    x1, x2 = b - g * (b - a), a + g * (b - a)
    f1, f2 = _spread(surface, d, np.array([x1, x2]), lo, hi)
    before = min(f1, f2)
    for step in range(1, 61):
        if min(f1, f2) <= point:
            return float(x1 if f1 <= f2 else x2)
        if f1 <= f2:
            b, x2, f2 = x2, x1, f1
            x1 = b - g * (b - a)
            f1 = _spread(surface, d, np.array([x1]), lo, hi)[0]
        else:
            a, x1, f1 = x1, x2, f2
            x2 = a + g * (b - a)
            f2 = _spread(surface, d, np.array([x2]), lo, hi)[0]
        if step % 10 == 0:
            if min(f1, f2) > before / 10:
                return None
            before = min(f1, f2)
    return None


def _surface(ad: BRepAdaptor_Surface) -> Surface:
    kind = ad.GetType()
    name = SURFACE_TYPES.get(kind, "other")
    if kind == GeomAbs_Plane:
        o, x, y, z = _frame(ad.Plane().Position())
        return Surface(name, plane(o, x, y), closed_form=_closed_form(PLANE, (o, x, y, z)))
    if kind == GeomAbs_Cylinder:
        c = ad.Cylinder()
        o, x, y, z = _frame(c.Position())
        return Surface(name, cylinder(o, x, y, z, c.Radius()), data=dict(radius=c.Radius(), origin=o, axis=z),
                       closed_form=_closed_form(CYLINDER, (o, x, y, z), c.Radius()))
    if kind == GeomAbs_Cone:
        c = ad.Cone()
        fr = _frame(c.Position())
        return Surface(name, cone(*fr, c.RefRadius(), c.SemiAngle()),
                       closed_form=_closed_form(CONE, fr, c.RefRadius(), c.SemiAngle()))
    if kind == GeomAbs_Sphere:
        s = ad.Sphere()
        fr = _frame(s.Position())
        return Surface(name, sphere(*fr, s.Radius()), closed_form=_closed_form(SPHERE, fr, s.Radius()))
    if kind == GeomAbs_Torus:
        t = ad.Torus()
        fr = _frame(t.Position())
        return Surface(name, torus(*fr, t.MajorRadius(), t.MinorRadius()),
                       closed_form=_closed_form(TORUS, fr, t.MajorRadius(), t.MinorRadius()))
    if kind in (GeomAbs_BSplineSurface, GeomAbs_BezierSurface):
        geom = ad.BSpline() if kind == GeomAbs_BSplineSurface else GeomConvert.SurfaceToBSplineSurface_s(ad.Bezier())
        d = bspline_data(geom)
        pw = homogeneous_poles(d["poles"], d["weights"])
        uk, vk = (np.ascontiguousarray(d[k], dtype=np.float64) for k in ("uknots", "vknots"))
        return Surface(name, lambda uv: eval_homogeneous(pw, uk, vk, d["udeg"], d["vdeg"],
                                                         wrap_periodic(uv, d["uperiod"], d["vperiod"]), d), data=d)
    if kind in (GeomAbs_SurfaceOfRevolution, GeomAbs_SurfaceOfExtrusion):
        swept = _swept(ad, kind)
        if swept is not None:
            return Surface(name, swept)
    return Surface(name, _occt_loop(ad), exact_numpy=False)


def _swept(ad: BRepAdaptor_Surface, kind) -> Callable[[np.ndarray], np.ndarray] | None:  # type: ignore[no-untyped-def]
    """The numpy evaluator of a surface of revolution or extrusion, or None when its basis curve has none or it
    disagrees with OCCT's own evaluation (checked on a 5 × 5 grid of the face's (u,v) to 1e-9 of its size)."""
    curve = curve_of(ad.BasisCurve())
    if curve is None:
        return None
    if kind == GeomAbs_SurfaceOfRevolution:
        ax = ad.AxeOfRevolution()
        f = revolution(vec(ax.Location()), vec(ax.Direction()), curve)
    else:
        f = extrusion(vec(ad.Direction()), curve)
    u = np.linspace(ad.FirstUParameter(), ad.LastUParameter(), 5)
    v = np.linspace(ad.FirstVParameter(), ad.LastVParameter(), 5)
    if not (np.isfinite(u).all() and np.isfinite(v).all()):
        return None
    uv = np.stack(np.meshgrid(u, v, indexing="ij"), axis=-1).reshape(-1, 2)
    want = _occt_loop(ad)(uv)
    got = f(uv)
    if not np.abs(got - want).max() <= 1e-9 * (1.0 + np.abs(want).max()):
        return None
    return f


RULED_TYPES = (GeomAbs_Plane, GeomAbs_Cylinder, GeomAbs_Cone, GeomAbs_SurfaceOfExtrusion)


def is_ruled(face: TopoDS_Face) -> bool:
    """True for a plane, cylinder, cone, extrusion, or a B-spline or Bézier surface of degree 1 with 2 poles in u or
    v: straight through every point one way, so a triangle between two rulings deviates from the surface about as
    much as its chord across them, which the boundary edges' discretisation sets."""
    s = BRepAdaptor_Surface(face, False)
    kind = s.GetType()
    if kind in RULED_TYPES:
        return True
    if kind in (GeomAbs_BSplineSurface, GeomAbs_BezierSurface):
        return (s.UDegree() == 1 and s.NbUPoles() == 2) or (s.VDegree() == 1 and s.NbVPoles() == 2)
    return False
