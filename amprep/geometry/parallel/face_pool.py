"""Mesh independent faces side by side: this process and forked children take the faces one at a time, costliest
first, from a shared counter (a face's mesh depends only on the shared edge discretisation, fixed before they
start), so Triangle's CDT and the numpy bookkeeping of refinement use every core and no core waits while work is
left. Serial where forking is unsafe or not allowed, and for work too small to pay a fork."""

from __future__ import annotations

import multiprocessing as mp
import os
import sys
from collections.abc import Callable, Sequence
from itertools import accumulate
from typing import Any

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.parallel.forked import Forked, cores, fork_available

#: work whose estimated cost (the caller's unit: mesher.py counts triangles) is under this runs serially
PARALLEL_MIN_COST = 20_000
#: an id that costs this many times all those after it together runs here first, its numba kernels on every thread
#: (in parallel it would be the last to finish, on one thread: the DTMB hull's main face is 92 % of its triangles)
DOMINANT = 2.0
#: at most this many processes in all (this one included)
MAX_WORKERS = 4


class SharedCount:
    """A running total shared by this process and the children map_faces forks after it is made (a fork-context
    Value, or a plain int where forking is not available): add(k) adds k and returns the new total."""

    def __init__(self, start: int = 0) -> None:
        self._shared = mp.get_context("fork").Value("q", start) if fork_available() else None
        self._local = start

    @property
    def value(self) -> int:
        """The total now."""
        if self._shared is None:
            return self._local
        with self._shared.get_lock():
            return int(self._shared.value)

    def add(self, k: int) -> int:
        if self._shared is None:
            self._local += k
            return self._local
        with self._shared.get_lock():
            self._shared.value += k
            return int(self._shared.value)


def can_fork() -> bool:
    """True when worker processes may be forked here: the fork start method exists, this is not a daemonic process
    (a Celery prefork child, whose parallelism is its siblings), and numba's threads (if loaded) survive a fork."""
    if not fork_available():
        return False
    layer = os.environ.get("NUMBA_THREADING_LAYER", "workqueue")
    if "numba" in sys.modules:  # the layer numba launched, or will launch
        import numba

        try:
            layer = numba.threading_layer()
        except ValueError:  # no parallel kernel ran yet
            layer = numba.config.THREADING_LAYER if numba.config.THREADING_LAYER != "default" else layer
    return layer in ("workqueue", "tbb")


def _numba_threads(n: int | None) -> int | None:
    """Set numba's threads for this thread to n (when numba is loaded); returns the number before."""
    if "numba" not in sys.modules:
        return None
    import numba

    before = numba.get_num_threads()
    if n is not None:
        numba.set_num_threads(n)
    return before


def map_faces(fn: Callable[[int], Any], ids: Sequence[int], ready: Callable[[], bool] = lambda: True,
              cost: Sequence[float] | None = None, parallel_min: float | None = None,
              workers: int | None = None) -> dict[int, Any]:
    """{i: fn(i)} for every id, taken in the order given (costliest first balances best): serially while ready() is
    False (the caller's results still depend on which process computes them), the cost left (cost[k] of ids[k];
    every id 1 when None) is under parallel_min or the next id is DOMINANT; then this process and forked children
    take the rest one id at a time, each with one numba thread. fn must not change shared state (a child's changes are lost). An AmprepError
    in a child is raised here; a child that dies or fails otherwise raises meshing_failed."""
    parallel_min = PARALLEL_MIN_COST if parallel_min is None else parallel_min
    ids = list(ids)
    left = list(cost) if cost is not None else [1.0] * len(ids)
    after = [*accumulate(reversed(left))][::-1] + [0.0]  # after[k]: the cost of ids[k:]
    out: dict[int, Any] = {}
    k = 0
    while k < len(ids) and (not ready() or after[k] < parallel_min or not can_fork()
                            or left[k] >= DOMINANT * after[k + 1]):
        out[ids[k]] = fn(ids[k])
        k += 1
    rest = ids[k:]
    n = min(workers or cores(), MAX_WORKERS, len(rest))
    if n < 2:
        out.update((i, fn(i)) for i in rest)
        return out
    counter = mp.get_context("fork").Value("q", 0)

    def take() -> int:
        with counter.get_lock():
            j = counter.value
            counter.value += 1
        return j

    died = (ErrorCode.MESHING_FAILED, "a worker process meshing faces died")
    children = [Forked(_work, fn, rest, take, died=died) for _ in range(n - 1)]
    threads = _numba_threads(1)
    try:
        while (j := take()) < len(rest):
            out[rest[j]] = fn(rest[j])
    except BaseException:
        for child in children:
            child.kill()
        raise
    finally:
        _numba_threads(threads)
    results = []
    for child in children:  # every child is collected before an error of one is raised
        try:
            results.append(child.result())
        except AmprepError as exc:
            results.append(exc)
    for r in results:
        if isinstance(r, AmprepError):
            raise r
        out.update(r)
    return out


def _work(fn: Callable[[int], Any], ids: list[int], take: Callable[[], int]) -> dict[int, Any]:
    """{ids[j]: fn(ids[j])} for j = take() until none is left, with one numba thread (a forked worker's loop)."""
    _numba_threads(1)
    done: dict[int, Any] = {}
    while (j := take()) < len(ids):
        done[ids[j]] = fn(ids[j])
    return done
