"""Tasks the broker loses, forced: a job whose message vanished from its queue (taken by a worker at the moment
Redis went down, never written to kombu's unacked set) and one whose reservation a worker dropped (its connection
went: the message sits in kombu's unacked set until its visibility timeout, hours) are sent again by the API's
watch and succeed; a second copy of a running job's message does not run it twice."""

from __future__ import annotations

import json
import os
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import httpx
import redis
from kombu.transport.redis import Channel

from amprep.queue import TASK_OF_KIND, make_celery
from amprep.serve import free_port, start_redis, wait_http
from amprep.settings import Settings
from amprep.store import UNSTARTED
from tests.conftest import corpus
from tests.service.conftest import _spawn, _stop, submit, wait_status

PART = "cq_cube_cylinder_colors.step"
SLOW = "nist_ctc02_ap242.stp"


@contextmanager
def api_without_worker(tmp: Path) -> Iterator[tuple[str, dict[str, str], redis.Redis]]:
    """Redis and an API that sends lost tasks again 2 s after they were sent; no worker yet."""
    redis_proc, redis_url = start_redis(tmp)
    env = dict(os.environ, AMPREP_REDIS_URL=redis_url, AMPREP_DATA_DIR=str(tmp), PYTHONUNBUFFERED="1",
               AMPREP_REQUEUE_AFTER_SECONDS="2")
    env.pop("AMPREP_API_KEYS", None)
    port = free_port()
    api = _spawn([sys.executable, "-m", "uvicorn", "app.main:app", "--port", str(port)], env, tmp / "api.log")
    try:
        assert wait_http(f"http://127.0.0.1:{port}/healthz", 60), (tmp / "api.log").read_text()[-2000:]
        yield f"http://127.0.0.1:{port}", env, redis.Redis.from_url(redis_url, decode_responses=True)
    finally:
        _stop(api)
        redis_proc.terminate()
        redis_proc.wait(10)


def _worker(env: dict[str, str], log: Path, processes: int = 1):  # type: ignore[no-untyped-def]
    return _spawn([sys.executable, "-m", "celery", "-A", "workers.celery_app", "worker", "-Q", "quick,heavy", "-c",
                   str(processes), "-n", f"lost{processes}@%h", "--without-gossip", "--without-mingle", "-O", "fair"],
                  env, log)


def _take(r: redis.Redis, job_id: str) -> str:
    """Remove the job's message from its queue (as a worker's BRPOP does); the raw message."""
    for raw in r.lrange("quick", 0, -1):
        if json.loads(raw)["headers"]["id"] == job_id:
            assert r.lrem("quick", 1, raw) == 1
            return raw  # type: ignore[no-any-return]
    raise AssertionError(f"no message for {job_id} in the queue")


def test_lost_and_dropped_tasks_are_sent_again(tmp_path: Path):
    with api_without_worker(tmp_path) as (url, env, r), httpx.Client(base_url=url, timeout=60) as c:
        lost = submit(c, corpus(PART), params='{"reuse": false}').json()["id"]
        dropped = submit(c, corpus(PART), params='{"reuse": false, "tolerance": 0.05}').json()["id"]
        waiting = submit(c, corpus(PART), params='{"reuse": false, "tolerance": 0.02}').json()["id"]
        _take(r, lost)
        raw = _take(r, dropped)
        # kombu's QoS.append: the message under a delivery tag, reserved a minute ago by a worker that is gone
        r.hset(Channel.unacked_key, "tag-of-a-gone-worker", json.dumps([json.loads(raw), "", "quick"]))
        r.zadd(Channel.unacked_index_key, {"tag-of-a-gone-worker": time.time() - 60})
        deadline = time.monotonic() + 60
        while r.llen("quick") < 3:  # the two lost ones are back; the waiting one was never sent twice
            assert time.monotonic() < deadline, (tmp_path / "api.log").read_text()[-2000:]
            time.sleep(0.2)
        assert sorted(json.loads(m)["headers"]["id"] for m in r.lrange("quick", 0, -1)) == sorted([lost, dropped,
                                                                                                     waiting])
        assert r.hlen(Channel.unacked_key) == 0  # the dropped reservation is gone with it
        worker = _worker(env, tmp_path / "worker.log")
        try:
            done = [wait_status(c, j, ("succeeded", "failed"), timeout=180) for j in (lost, dropped, waiting)]
        finally:
            _stop(worker)
        assert r.zcard(UNSTARTED) == 0  # every job left the watch when it started
        assert "amprep_tasks_sent_again_total 2.0" in c.get("/metrics").text
    assert [d["status"] for d in done] == ["succeeded"] * 3
    assert [d["attempts"] for d in done] == [1, 1, 1]
    api_log = (tmp_path / "api.log").read_text()
    assert {lost, dropped} <= {json.loads(line).get("job_id") for line in api_log.splitlines()
                               if "sent again" in line}


def test_a_second_copy_of_a_running_jobs_task_does_not_run_it_again(tmp_path: Path):
    with api_without_worker(tmp_path) as (url, env, r), httpx.Client(base_url=url, timeout=60) as c:
        worker = _worker(env, tmp_path / "worker.log", processes=2)
        try:
            job = submit(c, corpus(SLOW), params='{"tolerance": 0.01, "reuse": false}').json()
            running = wait_status(c, job["id"], ("running",), timeout=180)
            celery = make_celery(Settings(redis_url=env["AMPREP_REDIS_URL"]), "test")
            celery.send_task(TASK_OF_KIND["convert"], args=[job["id"]], task_id=job["id"])  # a publish retried, say
            deadline = time.monotonic() + 120
            while "another copy of a running job's task" not in (tmp_path / "worker.log").read_text():
                assert time.monotonic() < deadline, (tmp_path / "worker.log").read_text()[-3000:]
                time.sleep(0.2)
            done = wait_status(c, job["id"], ("succeeded", "failed"), timeout=300)
        finally:
            _stop(worker)
    assert done["status"] == "succeeded" and done["attempts"] == 1 and done["worker"] == running["worker"]
