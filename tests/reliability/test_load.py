"""A load through the real stack (bench/load.py's run_load, smaller than the benchmark's 1,000 jobs): concurrent
clients, a 2-process worker, the Redis server stopped and started again mid-load. Every job is accepted once (by
its Idempotency-Key), ends, succeeds and is closed; the API answers 503 with Retry-After while Redis is down, never
a 500."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

from tests.conftest import corpus

_spec = importlib.util.spec_from_file_location("bench_load", Path(__file__).resolve().parents[2] / "bench" / "load.py")
load = importlib.util.module_from_spec(_spec)  # type: ignore[arg-type]
sys.modules["bench_load"] = load  # its dataclasses look their module up
_spec.loader.exec_module(load)  # type: ignore[union-attr]


def test_nothing_lost_or_duplicated_when_redis_restarts_mid_load():
    jobs, clients = 120, 12
    with load.stack(workers=2) as s:
        r = load.run_load(s, corpus("cq_cube_cylinder_colors.step"), jobs, clients, restart_at=0.3, down=2.0,
                          timeout=900)
        api_log = (s.data / "api.log").read_text()
    assert len(r.ids) == jobs and len(set(r.ids.values())) == jobs  # one job per key, none shared
    assert r.listed == jobs  # and no other job made
    assert r.succeeded == jobs and r.closed == jobs
    assert r.unavailable > 0, "Redis was down but no client saw a 503"
    bad = [line for line in api_log.splitlines() if '"code": 500' in line or "Traceback" in line
           or '"level": "error"' in line]
    assert not bad, bad[:5]
