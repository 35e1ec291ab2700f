"""Vectorised (rational) B-spline evaluation from poles, weights and flat knot vectors."""

from __future__ import annotations

import os

import numpy as np

from amprep.geometry.core.compiled import use_compiled


def find_span(knots: np.ndarray, degree: int, t: np.ndarray) -> np.ndarray:
    """(N,) int: the span i with knots[i] ≤ t < knots[i+1], clamped to [degree, n_poles − 1]."""
    n_poles = len(knots) - degree - 1
    span = np.searchsorted(knots, t, side="right") - 1
    return np.clip(span, degree, n_poles - 1)


def basis_functions(knots: np.ndarray, degree: int, t: np.ndarray, span: np.ndarray) -> np.ndarray:
    """(N, degree+1) non-zero basis values N_{span−p+a, p}(t) by the Cox–de Boor triangle (Piegl–Tiller A2.2), each
    row of the triangle at once: N_r ← right_{r+1}·N_r/(right_{r+1} + left_{j−r}) + left_{j−r+1}·N_{r−1}/(…), a
    zero denominator giving 0 (the same sums as A2.2's inner loop, in the same order)."""
    n = len(t)
    basis = np.ones((n, 1))
    steps = np.arange(1, degree + 1)
    left = t[:, None] - knots[span[:, None] + 1 - steps]  # (N, p): column j − 1 is left_j = t − knots[span + 1 − j]
    right = knots[span[:, None] + steps] - t[:, None]  # column j − 1 is right_j = knots[span + j] − t
    for j in range(1, degree + 1):
        r_, l_ = right[:, :j], left[:, j - 1::-1]  # right_{r+1} and left_{j−r} for r = 0 … j − 1
        denom = r_ + l_
        denom[denom == 0] = np.inf  # N_r / ∞ = 0: A2.2's skipped term
        temp = basis / denom
        out = np.empty((n, j + 1))
        out[:, :j] = r_ * temp
        out[:, j] = 0.0
        out[:, 1:] += l_ * temp
        basis = out
    return basis


def numpy_cost(udeg: int, vdeg: int) -> float:
    """numpy's cost of one point of a degree (p, q) surface over a bicubic's, max(1, (p+1)(q+1)/16): its (p+1)(q+1)
    homogeneous poles gathered and summed per point, the Cox–de Boor loops per call growing with the degrees (a
    point measured 1.1 µs bicubic, 2.0 µs at degree 5, 4.7 µs at 10, in calls of 560; a call's fixed part grows more)."""
    return max(1.0, (udeg + 1) * (vdeg + 1) / 16)


def eval_curve(poles: np.ndarray, weights: np.ndarray, knots: np.ndarray, degree: int, t: np.ndarray) -> np.ndarray:
    """(N, d) C(t) = Σ N_i(t) w_i P_i / Σ N_i(t) w_i of a (rational) B-spline curve: poles (n, d), weights (n,), flat
    knots (n + degree + 1,), at t (N,)."""
    span = find_span(knots, degree, t)
    idx = (span - degree)[:, None] + np.arange(degree + 1)
    w = basis_functions(knots, degree, t, span) * weights[idx]
    return np.einsum("ij,ijk->ik", w, poles[idx]) / w.sum(axis=1, keepdims=True)


#: a call of this many points runs the compiled kernel unless the enclosing computation chose (core/compiled.py)
COMPILED_MIN_POINTS = 100_000
_kernel = None  # (parallel kernel, serial kernel, points per parallel block) once loaded
_CHUNK = 65536


def _eval_surface_numpy(pw: np.ndarray, uknots: np.ndarray, vknots: np.ndarray, udeg: int, vdeg: int,
                        uv: np.ndarray) -> np.ndarray:
    """(N, 3) the same sum in numpy: spans by searchsorted, basis by basis_functions, one batched matmul."""
    out = np.empty((len(uv), 3))
    a = np.arange(udeg + 1)[None, :, None]
    b = np.arange(vdeg + 1)[None, None, :]
    for s in range(0, len(uv), _CHUNK):
        u, v = uv[s:s + _CHUNK, 0], uv[s:s + _CHUNK, 1]
        su, sv = find_span(uknots, udeg, u), find_span(vknots, vdeg, v)
        nu, nv = basis_functions(uknots, udeg, u, su), basis_functions(vknots, vdeg, v, sv)
        flat = ((su - udeg)[:, None, None] + a) * pw.shape[1] + ((sv - vdeg)[:, None, None] + b)
        block = pw.reshape(-1, 4)[flat.reshape(len(u), -1)]  # (n, (p+1)(q+1), 4)
        basis = (nu[:, :, None] * nv[:, None, :]).reshape(len(u), 1, -1)  # (n, 1, (p+1)(q+1))
        h = np.matmul(basis, block)[:, 0]  # (n, 4)
        out[s:s + _CHUNK] = h[:, :3] / h[:, 3:4]
    return out


def fork_safe_threads() -> None:
    """Have numba start its threads with its workqueue layer unless the user chose one: GNU OpenMP's threads abort
    a forked child (face_pool forks workers)."""
    if "NUMBA_THREADING_LAYER" not in os.environ:
        from numba import config

        config.THREADING_LAYER = "workqueue"


def load_kernel() -> None:
    """Import numba and the compiled B-spline kernel (~0.7 s once per process; cached machine code after)."""
    global _kernel
    fork_safe_threads()
    from amprep.geometry.cad._bspline_kernel import EVAL_BLOCK, eval_surface_kernel, eval_surface_serial

    _kernel = (eval_surface_kernel, eval_surface_serial, EVAL_BLOCK)


def eval_surface(
    poles: np.ndarray, weights: np.ndarray, uknots: np.ndarray, vknots: np.ndarray,
    udeg: int, vdeg: int, uv: np.ndarray,
) -> np.ndarray:
    """(N, 3) S(u,v) = Σ N_i(u) N_j(v) w_ij P_ij / Σ N_i(u) N_j(v) w_ij; poles (nu, nv, 3), weights (nu, nv)."""
    return eval_homogeneous(homogeneous_poles(poles, weights), np.ascontiguousarray(uknots, dtype=np.float64),
                            np.ascontiguousarray(vknots, dtype=np.float64), udeg, vdeg, uv)


def homogeneous_poles(poles: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(nu, nv, 4) contiguous (w·P, w) of poles (nu, nv, 3) and weights (nu, nv): what eval_homogeneous takes."""
    return np.ascontiguousarray(np.concatenate([poles * weights[..., None], weights[..., None]], axis=2))


def eval_homogeneous(pw: np.ndarray, uknots: np.ndarray, vknots: np.ndarray, udeg: int, vdeg: int,
                     uv: np.ndarray, cache: dict | None = None) -> np.ndarray:  # type: ignore[type-arg]
    """eval_surface from homogeneous_poles and contiguous float64 knots, made once per surface (`cache`: where the
    kernel's Bernstein forms of the basis are kept, kernel_bases).

    The numba kernel of _bspline_kernel.py runs where core.compiled.use_compiled says (the computation's choice, or
    calls of ≥ COMPILED_MIN_POINTS points), numpy otherwise, so a small part never pays numba's ~0.7 s start-up and
    no result depends on whether the kernel happens to be loaded."""
    global _kernel
    if not use_compiled(len(uv), COMPILED_MIN_POINTS):
        return _eval_surface_numpy(pw, uknots, vknots, udeg, vdeg, np.asarray(uv, dtype=np.float64))
    if _kernel is None:
        load_kernel()
    assert _kernel is not None
    out = np.empty((len(uv), 3))
    parallel, serial, block = _kernel
    run = serial if len(uv) <= block else parallel
    ub, vb = kernel_bases(cache if cache is not None else {}, uknots, int(udeg), vknots, int(vdeg), pw.shape[:2])
    run(pw, ub, vb, int(udeg), int(vdeg), np.ascontiguousarray(uv, dtype=np.float64), out)
    return out


def kernel_bases(cache: dict, uknots: np.ndarray, udeg: int, vknots: np.ndarray, vdeg: int,  # type: ignore[type-arg]
                 n_poles: tuple[int, int]) -> tuple[tuple, tuple]:  # type: ignore[type-arg]
    """((knots, coef, inv_h) in u, the same in v): each direction's knots and the Bernstein form of its basis on each
    span (_bspline_kernel.span_bernstein), made once into `cache` (a surface's data dict) under "_bases"."""
    if "_bases" not in cache:
        from amprep.geometry.cad._bspline_kernel import span_bernstein

        out = []
        for knots, deg, n in ((uknots, udeg, n_poles[0]), (vknots, vdeg, n_poles[1])):
            knots = np.ascontiguousarray(knots, dtype=np.float64)
            out.append((knots, *span_bernstein(knots, deg, n)))
        cache["_bases"] = tuple(out)
    return cache["_bases"]


def kernel_arguments(d: dict) -> tuple:  # type: ignore[type-arg]
    """(pw (nu, nv, 4), ub, vb, udeg, vdeg, uper (2,), vper (2,)): a B-spline surface's data (surfaces.bspline_data's
    dict) as the compiled kernels take it, made once into `d`; a direction not periodic has per = (0, 0)."""
    if "_kernel_args" not in d:
        pw = homogeneous_poles(d["poles"], d["weights"])
        ub, vb = kernel_bases(d, d["uknots"], int(d["udeg"]), d["vknots"], int(d["vdeg"]), pw.shape[:2])
        per = [np.array(p if p is not None else (0.0, 0.0), dtype=np.float64) for p in (d["uperiod"], d["vperiod"])]
        d["_kernel_args"] = (pw, ub, vb, int(d["udeg"]), int(d["vdeg"]), per[0], per[1])
    return d["_kernel_args"]
