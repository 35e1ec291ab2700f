"""B-spline data of ACIS subtypes: the `nubs` / `nurbs` block of a bs3_curve or bs3_surface, as OCCT wants it.

ACIS writes `nubs|nurbs degree(s)`, closure and singularity words (enumerations in SAB), the distinct knots'
count(s), then (knot, multiplicity) pairs and the control points (x y z, and w when rational), v-major for a
surface. The phantom end knots are omitted (an end's multiplicity is at most `degree`): OCCT gets each end's
multiplicity raised by one (capped at degree + 1, for writers that keep them), and the pole count is
Σ mult − degree − 1 of that vector. A procedural subtype (a blend, an offset, a
sweep) stores its approximation the same way, so the first such block of a subtype's own data is the surface or
curve to build (build.py checks that it passes through the face's vertices); `nullbs` or `summary` (no control points) means there is none. Counts are checked against the tokens present
before anything is allocated.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from amprep.geometry.cad.acis.records import Brace, Enum, Flag, Ref, Text, Token, fail

MAX_DEGREE = 25  # OCCT's Geom_BSplineCurve/Surface limit


@dataclass(frozen=True)
class BSplineData:
    """Knots (k,) and multiplicities (k,) per direction (OCCT's clamped form), poles (nv, nu, 3) or (n, 3), weights
    or None."""

    degrees: tuple[int, ...]
    knots: tuple[np.ndarray, ...]
    mults: tuple[np.ndarray, ...]
    poles: np.ndarray
    weights: np.ndarray | None


def _is_word(tok: Token) -> bool:
    """A closure or singularity word (SAT) or enumeration (SAB)."""
    if isinstance(tok, Enum):
        return True
    return type(tok) is str and tok[:1].isalpha() and tok not in ("I", "F", "T")


def _is_int(tok: Token) -> bool:
    return type(tok) is int or (type(tok) is str and tok.isdigit())


def find_block(tokens: list[Token], surface: bool) -> int | None:
    """Index of the first `nubs`/`nurbs` of the subtype's own data (not inside a nested subtype: an offset surface
    nests its progenitor) that starts a surface block (two degrees) or a curve block (one); None when the subtype
    stores none (`nullbs`, `summary`, or a type with no approximation)."""
    depth = 0
    for k, tok in enumerate(tokens):
        if isinstance(tok, Text):
            continue
        if tok == "{":
            depth += 1
        elif tok == "}":
            depth -= 1
        if depth or tok not in ("nubs", "nurbs"):  # noqa: PLR1714
            continue
        if surface and k + 3 < len(tokens) and _is_int(tokens[k + 1]) and _is_int(tokens[k + 2]) and _is_word(tokens[k + 3]):
            return k
        if not surface and k + 2 < len(tokens) and _is_int(tokens[k + 1]) and _is_word(tokens[k + 2]):
            return k
    return None


def _floats(tokens: list[Token], start: int, n: int, where: str) -> np.ndarray:
    chunk = tokens[start:start + n]
    if len(chunk) < n or any(isinstance(t, (Ref, Flag, Enum, Brace, Text)) for t in chunk):
        raise fail(f"{where}: the B-spline data is shorter than its counts say")
    try:
        out = np.asarray(chunk, dtype=float)
    except ValueError:
        raise fail(f"{where}: the B-spline data is shorter than its counts say") from None
    if not np.isfinite(out).all():
        raise fail(f"{where}: a non-finite B-spline value")
    return out


def _knot_vector(tokens: list[Token], pos: int, count: int, degree: int, where: str) -> tuple[np.ndarray, np.ndarray, int]:
    pairs = _floats(tokens, pos, 2 * count, where).reshape(count, 2)
    knots, mults = pairs[:, 0], pairs[:, 1]
    if count < 2 or np.any(np.diff(knots) <= 0) or np.any(mults < 1) or np.any(mults != np.round(mults)):
        raise fail(f"{where}: knots that do not increase or multiplicities that are not positive integers")
    mults = mults.astype(np.int64)
    if mults[0] > degree + 1 or mults[-1] > degree + 1 or np.any(mults[1:-1] > degree):
        raise fail(f"{where}: a knot multiplicity above the degree")
    mults[[0, -1]] = np.minimum(mults[[0, -1]] + 1, degree + 1)  # ACIS omits the phantom end knots
    return knots, mults, pos + 2 * count


def read_block(tokens: list[Token], k: int, surface: bool, where: str, dim: int = 3) -> BSplineData:
    """The B-spline starting at tokens[k] (`nubs`/`nurbs`), its points of `dim` coordinates (2: a pcurve's)."""
    rational = tokens[k] == "nurbs"
    pos = k + 1
    n_dir = 2 if surface else 1
    degrees = tuple(int(tokens[pos + d]) for d in range(n_dir))  # type: ignore[call-overload]  # find_block: ints
    pos += n_dir
    if any(not 1 <= d <= MAX_DEGREE for d in degrees):
        raise fail(f"{where}: B-spline degree {degrees} outside 1..{MAX_DEGREE}")
    while pos < len(tokens) and _is_word(tokens[pos]):  # closure, singularity (words or SAB enumerations)
        pos += 1
    counts = []
    for _ in range(n_dir):
        if pos >= len(tokens) or not _is_int(tokens[pos]):
            raise fail(f"{where}: the B-spline knot count is missing")
        counts.append(int(tokens[pos]))  # type: ignore[call-overload]
        pos += 1
    if any(c < 2 or 2 * c > len(tokens) for c in counts):
        raise fail(f"{where}: a B-spline knot count ({counts}) the data cannot hold")
    knots, mults = [], []
    for d in range(n_dir):
        kn, mu, pos = _knot_vector(tokens, pos, counts[d], degrees[d], where)
        knots.append(kn)
        mults.append(mu)
    n_poles = [int(m.sum()) - deg - 1 for m, deg in zip(mults, degrees)]
    if any(n < deg + 1 for n, deg in zip(n_poles, degrees)):
        raise fail(f"{where}: fewer control points than the degree needs")
    stride = dim + 1 if rational else dim
    total = int(np.prod(n_poles))
    if total * stride > len(tokens) - pos:
        raise fail(f"{where}: the B-spline data is shorter than its counts say")
    data = _floats(tokens, pos, total * stride, where).reshape(total, stride)
    weights = data[:, dim] if rational else None
    if weights is not None and np.any(weights <= 0):
        raise fail(f"{where}: a rational B-spline with a weight that is not positive")
    shape = (n_poles[1], n_poles[0]) if surface else (n_poles[0],)
    poles = data[:, :dim].reshape(*shape, dim)
    return BSplineData(degrees, tuple(knots), tuple(mults), poles,
                       None if weights is None else weights.reshape(shape))
