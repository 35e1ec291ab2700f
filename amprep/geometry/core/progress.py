"""Progress and cancellation callbacks shared by long geometry functions."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar

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
