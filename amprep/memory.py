"""A job's memory bound: the address space (RLIMIT_AS) of the process that runs it, and of every child it forks,
held to what the process had mapped when the job started plus a budget. An allocation past it fails (MemoryError in
Python, Standard_OutOfMemory in OCCT): the job ends with memory_limit, the machine and the other jobs are untouched."""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager

try:
    import resource
except ImportError:  # not on Windows: no limit there
    resource = None  # type: ignore[assignment]


def address_space() -> int:
    """Bytes of address space this process has mapped now (VmSize; 0 where /proc is missing)."""
    try:
        with open("/proc/self/statm") as fh:
            return int(fh.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return 0


@contextmanager
def memory_budget(megabytes: int) -> Iterator[None]:
    """Inside the block, RLIMIT_AS = address_space() + megabytes MiB (at most the hard limit); the soft limit that
    was there before comes back after. megabytes ≤ 0, no /proc or no resource module: no limit."""
    base = address_space()
    if megabytes <= 0 or resource is None or base == 0:
        yield
        return
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    limit = base + megabytes * 2**20
    if hard != resource.RLIM_INFINITY:
        limit = min(limit, hard)
    resource.setrlimit(resource.RLIMIT_AS, (limit, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))
