"""Which evaluator a computation uses, numpy or the compiled (numba) kernels: decided by its input, never by what
this process happens to have loaded. The two agree only to the last bits, so a choice made by timing (kernels warmed
beside a reading child, preloaded by a worker) would change which faces are refined, and so the mesh."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar

_forced: ContextVar[bool | None] = ContextVar("amprep_compiled", default=None)


@contextmanager
def compiled(on: bool) -> Iterator[None]:
    """Every evaluation inside runs the compiled kernels (on) or numpy (off), whatever its size: a whole conversion
    decides once from its part's size. Forked children inherit the choice."""
    token = _forced.set(on)
    try:
        yield
    finally:
        _forced.reset(token)


def use_compiled(points: int, threshold: int) -> bool:
    """True when a call of `points` evaluations runs the compiled kernels: as the enclosing computation decided,
    else when the call alone is at least `threshold` points."""
    forced = _forced.get()
    return forced if forced is not None else points >= threshold
