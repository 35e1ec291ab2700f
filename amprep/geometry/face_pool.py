"""Mesh independent faces side by side: after a short serial start, the remaining faces go to forked worker
processes (a face's mesh depends only on the shared edge discretisation, fixed before they start), so Triangle's
CDT and the numpy bookkeeping of refinement use every core. Serial where forking is unsafe or not allowed."""

from __future__ import annotations

import multiprocessing as mp
import os
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from .errors import AmprepError, ErrorCode

#: work that finishes within this many seconds serially is not worth forking for
SERIAL_SECONDS = 0.3
#: at most this many worker processes
MAX_WORKERS = 4

_job: Callable[[int], Any] | None = None  # the function the forked children run (inherited, never pickled)


def _run(i: int) -> tuple[int, Any]:
    assert _job is not None
    return i, _job(i)


def cores() -> int:
    """CPU cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def can_fork() -> bool:
    """True when worker processes may be forked here: the fork start method exists, this is not a daemonic process
    (a Celery prefork child, whose parallelism is its siblings), and numba's threads (if loaded) survive a fork."""
    if "fork" not in mp.get_all_start_methods() or mp.current_process().daemon or cores() < 2:
        return False
    layer = os.environ.get("NUMBA_THREADING_LAYER", "workqueue")
    return layer in ("workqueue", "tbb")


def map_faces(fn: Callable[[int], Any], ids: Sequence[int], ready: Callable[[], bool] = lambda: True,
              serial_seconds: float | None = None, workers: int | None = None) -> dict[int, Any]:
    """{i: fn(i)} for every id, taken in the order given (cheapest first pays best): serially until serial_seconds
    have passed and ready() (the caller's results no longer depend on which process computes them), then the rest
    in forked processes when can_fork(). fn must not change shared state (its children's changes are lost); a child
    that dies raises meshing_failed."""
    global _job
    serial_seconds = SERIAL_SECONDS if serial_seconds is None else serial_seconds
    out: dict[int, Any] = {}
    start = time.perf_counter()
    ids = list(ids)
    k = 0
    while k < len(ids) and (time.perf_counter() - start < serial_seconds or not ready() or not can_fork()):
        out[ids[k]] = fn(ids[k])
        k += 1
    rest = ids[k:]
    if not rest:
        return out
    n = min(workers or cores(), MAX_WORKERS, len(rest))
    _job = fn
    try:
        with ProcessPoolExecutor(n, mp_context=mp.get_context("fork")) as pool:
            for i, result in pool.map(_run, rest[::-1], chunksize=1):  # costliest first: the tail balances
                out[i] = result
    except BrokenProcessPool:
        raise AmprepError(ErrorCode.MESHING_FAILED, "a worker process meshing faces died") from None
    finally:
        _job = None
    return out
