"""Chordal error: distance from the exact surface to each triangle's plane, sampled in the face's (u,v)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from functools import lru_cache

import numpy as np

from amprep.geometry.cad import bspline as _bspline
from amprep.geometry.cad.surfaces import (
    Surface,
    parameter_box,
    project_points,
    project_settled,
    surface_normals,
    uv_extent,
)
from amprep.geometry.core.compiled import compiled, use_compiled
from amprep.geometry.core.progress import checkpoint
from amprep.geometry.core.vectors import norms, unit_normals
from amprep.geometry.measure.angles import load_angle_kernels, warm_angle_kernels

_CHUNK_POINTS = 1_000_000
#: triangles per call of a compiled kernel (~0.1 s of a B-spline face at order 6 here): checkpoint() between calls
CALL_TRIANGLES = 100_000
_kernels = None  # the _chordal_kernel module once loaded
_warm = False  # warm_kernels ran in this process
#: numba's start-up (~0.6 s per process) pays for itself from about 100k triangles at order 6 (the kernels run
#: ~3× numpy's speed on 2 cores): a call this large runs them unless the enclosing computation chose
#: (core/compiled.py; the mesher chooses for a whole part)
COMPILED_MIN_POINTS = 3_000_000
#: the same for free-form work (free_form_work): the default mesher's rounds in numpy cost 90–400 µs more per weighted
#: triangle than in the kernels (the 45-face IGES and CTC-02's B-spline twin ~90–100, the lens ~200, OCCT's top.brep,
#: of degree up to 11, ~400), and most of the start-up is paid while the file is read (read_ahead's warm-up): from
#: ~2,700 triangles at order 6
FREE_FORM_MIN_POINTS = COMPILED_MIN_POINTS // 40


def load_kernels() -> None:
    """Load the compiled kernels now (mesh_model does when the whole part is large): every later call uses them."""
    global _kernels
    if _kernels is None:
        _bspline.fork_safe_threads()
        from amprep.geometry.measure import _chordal_kernel

        _kernels = _chordal_kernel
        _bspline.load_kernel()
        load_angle_kernels()


def warm_kernels(stop: Callable[[], bool] | None = None) -> None:
    """load_kernels(), then calls of each kernel (serial and parallel, and the projection's) on a cylinder and a
    B-spline face with the types of real calls: numba's first dispatch (its typing registry, ~0.3 s) is paid here, e.g.
    while another process reads the file. numba is imported first (~0.3 s); when `stop()` is then True (the file is
    read already: a small part, whose numpy measures cost less than the ~0.5 s left) nothing is loaded and the kernels
    stay unused."""
    _bspline.fork_safe_threads()  # imports numba
    if stop is not None and stop():
        return
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeCylinder
    from OCP.GeomAPI import GeomAPI_PointsToBSplineSurface
    from OCP.gp import gp_Pnt
    from OCP.TColgp import TColgp_Array2OfPnt
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    from amprep.geometry.cad.surfaces import surface_of

    load_kernels()
    from amprep.geometry.cad._bspline_kernel import EVAL_BLOCK

    grid = TColgp_Array2OfPnt(1, 4, 1, 4)
    for i in range(1, 5):
        for j in range(1, 5):
            grid.SetValue(i, j, gp_Pnt(i, j, 0.1 * i * j))
    patch = BRepBuilderAPI_MakeFace(GeomAPI_PointsToBSplineSurface(grid).Surface(), 1e-6).Face()
    cylinder = TopoDS.Face_s(TopExp_Explorer(BRepPrimAPI_MakeCylinder(1.0, 1.0).Shape(), TopAbs_FACE).Current())
    uv = np.array([[[0.1, 0.1], [0.5, 0.1], [0.1, 0.5]]])
    with compiled(True):
        for face in (cylinder, patch):
            surface = surface_of(face)
            corners = surface.evaluate(uv[0])[None]
            for tris, points in ((1, 1), (_kernels.BLOCK + 1, EVAL_BLOCK + 1)):  # serial, then parallel kernels
                surface.evaluate(np.repeat(uv[0], points, axis=0))
                triangle_chordal_error(np.repeat(corners, tris, axis=0), np.repeat(uv, tris, axis=0), surface)
            project_settled(surface, corners[0], uv[0], within=True)
    warm_angle_kernels()
    global _warm
    _warm = True


def kernels_warm() -> bool:
    """True once warm_kernels has dispatched every kernel in this process (loading them, load_kernels, does not)."""
    return _warm


def worth_compiling(triangles: int, order: int, free_form: float = 0.0) -> bool:
    """True when measuring `triangles` on the order-k grid pays numba's start-up, or their free-form work alone does
    (free_form_work: B-spline and Bézier faces, which numpy evaluates far slower): the choice a whole computation
    makes (core.compiled)."""
    points = len(barycentric_grid(order))
    return triangles * points >= COMPILED_MIN_POINTS or free_form * points >= FREE_FORM_MIN_POINTS


def free_form_work(counts: Sequence[float], surfaces: Sequence[Surface | None]) -> float:
    """Σ counts[i] · bspline.numpy_cost of face i's degrees over the B-spline and Bézier faces (surfaces[i].data):
    the triangles of those faces, each weighted by what numpy pays to evaluate a point of its surface."""
    return float(sum(n * _bspline.numpy_cost(sf.data["udeg"], sf.data["vdeg"])
                     for n, sf in zip(counts, surfaces, strict=True)
                     if sf is not None and sf.data is not None and sf.surface_type in ("bspline", "bezier")))


def kernels_loaded() -> bool:
    """True once the compiled kernels are loaded in this process (which evaluator a call uses is core.compiled's
    choice, not this)."""
    return _kernels is not None


@lru_cache(maxsize=32)
def barycentric_grid(order: int) -> np.ndarray:
    """((k+1)(k+2)/2, 3) barycentric weights (i, j, k−i−j)/k of the order-k grid on a triangle (k=6: 28)."""
    pts = [(i, j, order - i - j) for i in range(order + 1) for j in range(order + 1 - i)]
    w = np.array(pts, dtype=float) / order
    w.flags.writeable = False
    return w


def _grid_order(points: int) -> int:
    """k of the order-k barycentric grid with `points` = (k+1)(k+2)/2 points."""
    k = int(round((np.sqrt(8 * points + 1) - 3) / 2))
    assert (k + 1) * (k + 2) // 2 == points, points
    return k


@lru_cache(maxsize=32)
def _interior_first(order: int) -> np.ndarray:
    """The order-k grid's points, those farthest from the triangle's sides first (where a curved surface leaves the
    triangle's plane most): a triangle over a stop value is found with few points."""
    w = barycentric_grid(order)
    out = w[np.argsort(-w.min(axis=1), kind="stable")]
    out.flags.writeable = False
    return out


def exact_over(err: np.ndarray, threshold: float, nodes: np.ndarray, uv: np.ndarray, tris: np.ndarray,
               surface: Surface, order: int = 6) -> np.ndarray:
    """err (t,) of triangles tris (t, 3) over nodes (n, 3) with (u,v) (n, 2), every value over the threshold measured
    again without a stop, so that it is the true maximum."""
    over = np.flatnonzero(err > threshold)
    if len(over):
        err = err.copy()
        t = tris[over]
        err[over] = triangle_chordal_error(nodes[t], uv[t], surface, order, affine=surface.affine)
    return err


def affine_chordal_bound(corners: np.ndarray, uv: np.ndarray, evaluate: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """(m,) max_i |S(u_i, v_i) − c_i| over the corners: the exact bound of ε_T when S is affine in (u,v) (a plane),
    since every S(Σ w_i uv_i) − (plane of T) = Σ w_i (S(uv_i) − c_i) · n̂."""
    exact = evaluate(uv.reshape(-1, 2)).reshape(-1, 3, 3)
    return norms(exact - corners).max(axis=1)


def _compiled(surface: Surface, corners: np.ndarray, uv: np.ndarray, w: np.ndarray,
              stop: float = np.inf) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(ε_T, the largest |S(q_p) − a_p|, `facing`'s cosine where the second is over TILT_SCREEN × the first, else 1)
    (m,) each by the fused, threaded kernel of _chordal_kernel.py, or None where
    the surface has none (OCCT-evaluated kinds) or core.compiled.use_compiled says numpy (the computation's choice,
    else a call too small to pay numba's start-up), whether or not the kernels are loaded."""
    kind = surface.closed_form
    d = surface.data if surface.surface_type in ("bspline", "bezier") else None
    if kind is None and d is None:
        return None
    if not use_compiled(len(corners) * len(w), COMPILED_MIN_POINTS):
        return None
    if _kernels is None:
        load_kernels()
    assert _kernels is not None
    out, off = np.empty(len(corners)), np.empty(len(corners))
    cos = np.empty(len(corners))
    h = 1e-6 * uv_extent(surface)  # surfaces.tangents' steps
    corners = np.ascontiguousarray(corners, dtype=np.float64)
    uv = np.ascontiguousarray(uv, dtype=np.float64)
    for s in range(0, len(corners), CALL_TRIANGLES):  # bounded calls: a cancel or time limit seen between them
        if s:
            checkpoint()
        sl = slice(s, s + CALL_TRIANGLES)
        _kernel_call(kind, d, corners[sl], uv[sl], w, stop, h, out[sl], off[sl], cos[sl])
    return out, off, cos


def _kernel_call(kind: tuple[int, np.ndarray] | None, d: dict | None, corners: np.ndarray,  # type: ignore[type-arg]
                 uv: np.ndarray, w: np.ndarray, stop: float, h: np.ndarray, out: np.ndarray, off: np.ndarray,
                 cos: np.ndarray) -> None:
    """One call of the analytic (`kind`) or B-spline (`d`) chordal kernel, writing `out`, `off` and `cos` (m,); h (2,)
    the B-spline's difference steps in u and v."""
    assert _kernels is not None
    serial = len(corners) <= _kernels.BLOCK
    if kind is not None:
        fn = _kernels.analytic_chordal_serial if serial else _kernels.analytic_chordal_kernel
        k = _grid_order(len(w))
        ij = np.ascontiguousarray(np.rint(w[:, :2] * k), dtype=np.int64)
        fn(kind[0], kind[1], corners, uv, np.ascontiguousarray(w), ij, k, float(stop), TILT_SCREEN, out, off, cos)
        return
    assert d is not None
    pw, ub, vb, udeg, vdeg, uper, vper = _bspline.kernel_arguments(d)
    fn = _kernels.bspline_chordal_serial if serial else _kernels.bspline_chordal_kernel
    fn(pw, ub, vb, udeg, vdeg, uper, vper, corners, uv, np.ascontiguousarray(w), float(stop), TILT_SCREEN,
       np.ascontiguousarray(h, dtype=np.float64), out, off, cos)


#: a triangle whose normal is over 10° off the surface's (|cos| under TILT_MAX) is also measured by its points' distance
#: from it; screened by its grid points lying over TILT_SCREEN = 1 / TILT_MAX × its measured error from S at their
#: (u,v), which every such triangle whose deviation lies along the surface's normal does. A triangle not screened is
#: measured to at least cos 10° of its points' distance (|S(q) − a| bounds it); a 60° bound let intermediate meshes'
#: triangles 12–19° off be measured at a twentieth to a third of their true distance (OCCT's top, default mesher, by
#: OCCT's own distance). The compiled kernels give the tilt's cosine of the screened triangles (`facing`'s)
TILT_MAX = float(np.cos(np.radians(10.0)))
TILT_SCREEN = 1.0 / TILT_MAX
#: Gauss–Newton steps toward a grid point's foot on the surface in tilted_bound, each point stopping once its step is
#: under TILT_SETTLE × the face's (u,v) extent (the distance to any surface point is an upper bound: a nearer foot
#: only makes it tighter, by the square of the step)
TILT_STEPS, TILT_SETTLE = 8, 1e-9


def facing(corners: np.ndarray, uv: np.ndarray, surface: Surface) -> np.ndarray:
    """(m,) |n̂_T · n̂_S| of triangles (corners (m, 3, 3), uv (m, 3, 2)): the cosine between each one's normal and the
    surface's at its (u,v) centroid (surface_normals: 0 at a pole or apex); 1 for a zero-area triangle."""
    unit, area = unit_normals(corners)
    cos = np.abs((surface_normals(surface, uv.mean(axis=1)) * unit).sum(axis=1))
    return np.where(area > 0, cos, 1.0)


def tilted_bound(corners: np.ndarray, uv: np.ndarray, surface: Surface, w: np.ndarray, err: np.ndarray,
                 off: np.ndarray, cos: np.ndarray | None = None) -> np.ndarray:
    """(m,) err raised, for the triangles tilted on the surface (normal over 10° off the surface's at their (u,v)
    centroid; screened by off (m,), the largest |S(q_p) − a_p| of their grid points, over TILT_SCREEN × err), to the
    largest of their grid points' distances from a surface point: the least of |S(q_p) − a_p|, _offset_bound's step
    and TILT_STEPS of Gauss–Newton from q_p, each an upper bound. err, the distance along a triangle's normal, sees
    its points' offset to the cosine of its tilt, and not at all where the triangle holds S(u,v) in its own plane
    (three points of one cross-section of a fillet, a needle beside a boundary chord off its face). cos (m,):
    `facing`'s values where the compiled kernel gave them, else computed for the screened triangles."""
    suspect = np.flatnonzero(off > TILT_SCREEN * err)
    if len(suspect):
        cos = facing(corners[suspect], uv[suspect], surface) if cos is None else cos[suspect]
        suspect = suspect[cos < TILT_MAX]
    if not len(suspect):
        return err
    out = err.copy()
    box = parameter_box(surface)
    step = max(1, _CHUNK_POINTS // (5 * TILT_STEPS * len(w)))  # S and its central differences each Gauss–Newton step
    for s in range(0, len(suspect), step):
        if s:
            checkpoint()
        t = suspect[s:s + step]
        pts_uv = np.matmul(w, uv[t]).reshape(-1, 2)
        xyz = surface.evaluate(pts_uv).reshape(len(t), -1, 3)
        near, nearest = _offset_bound(corners[t], uv[t], w, pts_uv, xyz, surface.evaluate, box)
        near = near.reshape(-1)
        far = np.flatnonzero(near > np.repeat(err[t], len(w)))  # only these can raise err
        if len(far):
            a = np.matmul(w, corners[t]).reshape(-1, 3)[far]
            foot = project_points(surface, a, nearest[far], iterations=TILT_STEPS, within=True, settle=TILT_SETTLE)[1]
            near[far] = np.minimum(near[far], foot)
        out[t] = np.maximum(out[t], near.reshape(len(t), -1).max(axis=1))
    return out


def _offset_bound(corners: np.ndarray, uv: np.ndarray, w: np.ndarray, pts_uv: np.ndarray, xyz: np.ndarray,
                  evaluate: Callable[[np.ndarray], np.ndarray],
                  box: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """((m, P) min(|S(q_p) − a_p|, |S(q_p + δ_p) − a_p|), (m·P, 2) the (u,v) of the nearer): each grid point a_p of a
    triangle against two surface points, so an upper bound of its distance from the surface; q_p its (u,v) (pts_uv
    (m·P, 2), S there xyz (m, P, 3)), δ_p = U (EᵀE)⁻¹ Eᵀ (a_p − S(q_p)) the step that the triangle's own affine map (edges E (m, 2, 3) over
    (u,v) edges U) takes to a_p: it removes the parametrisation's tangential drift, which is no distance. Taken only
    where E is well conditioned (|E₁ × E₂|² > 1e-12 (|E₁|² + |E₂|²)²) and (EᵀE)⁻¹ Eᵀ (a − S) is within ±1 (a step of
    at most the triangle's own (u,v) edges), then clipped to the face's parameter box (surfaces.parameter_box):
    a triangle degenerate in space but not in (u,v), at a pole, would otherwise step to u ~ 1e12."""
    a = np.matmul(w, corners)  # (m, P, 3)
    off = a - xyz
    best = norms(off)
    nearest = np.array(pts_uv, dtype=float).reshape(len(uv), -1, 2)
    e = corners[:, 1:] - corners[:, :1]
    g = np.matmul(e, e.transpose(0, 2, 1))  # EᵀE (m, 2, 2)
    det = g[:, 0, 0] * g[:, 1, 1] - g[:, 0, 1] * g[:, 1, 0]
    ok = np.flatnonzero(det > 1e-12 * np.maximum((g[:, 0, 0] + g[:, 1, 1]) ** 2, 1e-300))
    if len(ok):
        inv = np.stack([g[ok, 1, 1], -g[ok, 0, 1], -g[ok, 1, 0], g[ok, 0, 0]], axis=1).reshape(-1, 2, 2)
        inv /= det[ok, None, None]
        coef = np.matmul(off[ok], np.matmul(inv, e[ok]).transpose(0, 2, 1))  # (k, P, 2): (EᵀE)⁻¹ Eᵀ (a − S)
        small = np.abs(coef).max(axis=2) <= 1.0  # (k, P)
        step = np.matmul(np.where(small[..., None], coef, 0.0), uv[ok, 1:] - uv[ok, :1])
        to = np.clip(pts_uv.reshape(len(uv), -1, 2)[ok] + step, *box)
        moved = norms(evaluate(to.reshape(-1, 2)).reshape(step.shape[:2] + (3,)) - a[ok])
        nearer = moved < best[ok]
        best[ok] = np.where(nearer, moved, best[ok])
        nearest[ok] = np.where(nearer[..., None], to, nearest[ok])
    return best, nearest.reshape(-1, 2)


def triangle_chordal_error(
    corners: np.ndarray, uv: np.ndarray, surface: Surface | Callable[[np.ndarray], np.ndarray], order: int = 6,
    affine: bool = False, stop: float = np.inf,
) -> np.ndarray:
    """(m,) ε_T = max_p |(S(u_p, v_p) − a) · n̂| over the order-k barycentric grid in (u,v); on a Surface raised, for
    triangles tilted over 10° on it (tilted_bound) and on faces with a fold (surface.folds, _offset_bound), to an
    upper bound of the triangle's own points' distance from it;
    corners (m, 3, 3) mm, uv (m, 3, 2) on `surface` (a Surface, or its evaluate: (N, 2) → (N, 3)). Zero-area: 0.
    affine=True (planes): the corner bound of affine_chordal_bound instead of sampling. A Surface with a closed
    form or B-spline data is measured by the compiled kernel on large calls (same samples, same result); it may
    leave a triangle's points at the first over `stop` (interior points first): a value over `stop` is then only
    a lower bound (exact_over makes such values exact)."""
    m = len(corners)
    if m == 0:
        return np.zeros(0)
    evaluate = surface.evaluate if isinstance(surface, Surface) else surface
    if affine:
        return affine_chordal_bound(corners, uv, evaluate)
    w = barycentric_grid(order)
    folds = parameter_box(surface) if isinstance(surface, Surface) and surface.folds else None
    if isinstance(surface, Surface) and folds is None:
        fast = _compiled(surface, corners, uv, _interior_first(order) if stop < np.inf else w, stop)
        if fast is not None:
            return tilted_bound(corners, uv, surface, w, *fast)
    out, off = _sampled(corners, uv, evaluate, w, folds)
    return tilted_bound(corners, uv, surface, w, out, off) if isinstance(surface, Surface) else out


def _sampled(corners: np.ndarray, uv: np.ndarray, evaluate: Callable[[np.ndarray], np.ndarray], w: np.ndarray,
             folds: tuple[np.ndarray, np.ndarray] | None) -> tuple[np.ndarray, np.ndarray]:
    """(m,) triangle_chordal_error's measure in numpy, in chunks of _CHUNK_POINTS points, and (m,) the largest
    |S(q_p) − a_p| of each triangle's grid points (0 for a zero-area triangle), as the compiled kernels give; on a
    face with a fold (`folds`: its parameter box), raised to _offset_bound's."""
    m = len(corners)
    unit, area = unit_normals(corners)
    out, off = np.empty(m), np.empty(m)
    step = max(1, _CHUNK_POINTS // len(w))
    for s in range(0, m, step):
        if s:
            checkpoint()
        sl = slice(s, s + step)
        pts_uv = np.einsum("pk,mkd->mpd", w, uv[sl]).reshape(-1, 2)
        xyz = evaluate(pts_uv).reshape(-1, len(w), 3)
        out[sl] = np.abs(np.einsum("mpd,md->mp", xyz - corners[sl, None, 0], unit[sl])).max(axis=1)
        off[sl] = np.where(area[sl] > 0, norms(xyz - np.matmul(w, corners[sl])).max(axis=1), 0.0)
        if folds is not None:  # near a fold a triangle's own points may be far from the surface with S(u,v) near its plane
            out[sl] = np.maximum(out[sl], _offset_bound(corners[sl], uv[sl], w, pts_uv, xyz, evaluate, folds)[0].max(axis=1))
    return out, off
