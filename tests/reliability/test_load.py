"""A load through the real stack (bench/load.py's run_load, smaller than the benchmark's 1,000 jobs): concurrent
clients, a 2-process worker, the Redis server stopped and started again mid-load. Every job is accepted once (by
its Idempotency-Key), ends, succeeds and is closed; the API answers 503 with Retry-After while Redis is down, never
a 500."""

from __future__ import annotations

import importlib.util
import sys
import time
from pathlib import Path

import httpx

from tests.conftest import corpus
from tests.service.conftest import submit, wait_status

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


def test_a_worker_survives_losing_redis_while_a_job_runs():
    """A worker of two processes, one running a job (its message unacknowledged until the job ends: acks_late), the
    other waiting on the queue (a BRPOP in flight): Redis restarts. The worker reconnects, the job ends once and the
    next job runs. Celery 5.7.0's worker exits here ("Unrecoverable error: AttributeError", kombu's Redis channel
    rebuilding its pool from a transport the consumer had cleared); pyproject keeps celery under 5.7."""
    with load.stack(workers=2) as s, httpx.Client(base_url=s.url, timeout=120) as c:
        r = submit(c, corpus("nist_ctc02_ap242.stp"), params='{"tolerance": 0.01, "reuse": false}')
        assert r.status_code == 202, r.text
        long_job = r.json()["id"]
        wait_status(c, long_job, ("running",), timeout=300)
        s.restart_redis(1.0)
        first = load._ended(c, long_job, time.monotonic() + 600, s)
        r = submit(c, corpus("cq_cube_cylinder_colors.step"), params='{"reuse": false}')
        assert r.status_code == 202, r.text
        after = load._ended(c, r.json()["id"], time.monotonic() + 300, s)
        worker_log = (s.data / "worker.log").read_text()
    assert first["status"] == "succeeded" and after["status"] == "succeeded"
    assert "Unrecoverable" not in worker_log
