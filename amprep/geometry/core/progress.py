"""Progress, cancellation and triangle-budget callbacks shared by long geometry functions."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar

from amprep.errors import AmprepError, ErrorCode

#: progress(stage, fraction in [0, 1]); may raise to cancel.
ProgressFn = Callable[[str, float], None]


class Progress:
    """Maps sub-steps onto an overall fraction: `span(start, end)` scales a child's 0..1 into start..end."""

    def __init__(self, fn: ProgressFn | None = None, start: float = 0.0, end: float = 1.0) -> None:
        self._fn = fn
        self._start = start
        self._end = end

    def __call__(self, stage: str, fraction: float) -> None:
        if self._fn is not None:
            f = min(max(fraction, 0.0), 1.0)
            self._fn(stage, self._start + (self._end - self._start) * f)

    def span(self, start: float, end: float) -> Progress:
        """A child whose 0..1 maps to start..end of this one's range."""
        width = self._end - self._start
        return Progress(self._fn, self._start + width * start, self._start + width * end)



_CHECK: ContextVar[Callable[[], None] | None] = ContextVar("amprep_checkpoint", default=None)


def checkpoint() -> None:
    """Run the current job's cancel check (set by `checking`), if any: a loop over blocks of one long computation
    calls it between blocks, so a cancel is seen within a block's time (a time limit, raised by a signal, is seen
    there too, since Python runs between blocks)."""
    fn = _CHECK.get()
    if fn is not None:
        fn()


@contextmanager
def checking(fn: Callable[[], None] | None) -> Iterator[None]:
    """Inside the block, checkpoint() calls `fn` (which raises to cancel)."""
    token = _CHECK.set(fn)
    try:
        yield
    finally:
        _CHECK.reset(token)


_BUDGET: ContextVar[tuple[int, int] | None] = ContextVar("amprep_triangle_budget", default=None)


def grew_over(limit: int) -> AmprepError:
    """output_too_large for a mesh that outgrew `limit` triangles while it was made (an estimate let it start)."""
    return AmprepError(ErrorCode.OUTPUT_TOO_LARGE, f"the mesh grew over the limit of {limit:,} triangles while it "
                       "was made: use a coarser tolerance, the default mesher or a higher max_triangles")


def within_budget(triangles: int) -> None:
    """output_too_large when `triangles` (what the face being meshed has, or is about to have) exceed the budget set by
    `budgeted`, if any: one face's refinement stops there, not once the face is done (a 30 M-triangle terrain face
    estimated at 7 M refined for over 300 s)."""
    budget = _BUDGET.get()
    if budget is not None and triangles > budget[0]:
        raise grew_over(budget[1])


@contextmanager
def budgeted(left: int, limit: int) -> Iterator[None]:
    """Inside the block, within_budget(n) raises output_too_large for n > `left` (the job's `limit` less the
    triangles already made)."""
    token = _BUDGET.set((left, limit))
    try:
        yield
    finally:
        _BUDGET.reset(token)
