"""Time limits, process recycling, retention and structured logs, on a second stack (its own Redis database)."""

from __future__ import annotations

import json
import time

import httpx
import pytest

from tests.conftest import corpus
from tests.service.conftest import _spawn, _stop, submit, wait_status


@pytest.fixture(scope="module")
def strict(service):
    """API + worker on Redis database 1 with a 4 s soft / 12 s hard limit (the small part the other tests run takes
    ~0.3 s: over 10× margin on a loaded machine), 2 jobs per process, 3 s retention."""
    env = {"AMPREP_REDIS_URL": service.env["AMPREP_REDIS_URL"].rsplit("/", 1)[0] + "/1",
           "AMPREP_DATA_DIR": str(service.data / "strict"), "AMPREP_MAX_TRIANGLES": "20000000",
           "AMPREP_SOFT_TIME_LIMIT_QUICK": "4", "AMPREP_HARD_TIME_LIMIT_QUICK": "12",
           "AMPREP_MAX_JOBS_PER_PROCESS": "2", "AMPREP_RETENTION_SECONDS": "3"}
    import sys

    worker = _spawn([sys.executable, "-m", "celery", "-A", "workers.celery_app", "worker", "-Q", "quick,callbacks",
                     "-c", "1", "-n", "strict@%h", "--without-gossip", "--without-mingle"],
                    dict(service.env, **env), service.logs / "strict-worker.log")
    url, api = service.start_api(**env)
    client = httpx.Client(base_url=url, timeout=120)
    deadline = time.monotonic() + 60
    while client.get("/readyz").status_code != 200:
        assert time.monotonic() < deadline
        time.sleep(0.3)
    yield client
    client.close()
    _stop(api)
    _stop(worker)


def test_time_limit_fails_the_job_with_its_code(strict):
    # CTC-02 at 0.001 mm (1.3 M triangles) takes ~12 s in a warm worker on this machine: 3× the soft limit, and a
    # loaded machine only makes it longer
    job = submit(strict, corpus("nist_ctc02_ap242.stp"), params='{"tolerance": 0.001, "reuse": false}').json()
    done = wait_status(strict, job["id"], ("succeeded", "failed"), timeout=120)
    assert done["status"] == "failed" and done["error"]["code"] == "time_limit"
    # the worker is alive and takes the next job
    assert submit(strict, corpus("voron_vhb_din_mount.step"), params='{"reuse": false}', wait=60).json()["status"] == "succeeded"


def test_a_fresh_process_after_n_jobs(strict):
    pids = []
    for _ in range(4):
        job = submit(strict, corpus("voron_vhb_din_mount.step"), params='{"reuse": false}', wait=60).json()
        assert job["status"] == "succeeded"
        pids.append(job["worker"])
    assert len(set(pids)) >= 2  # at most 2 jobs per process
    assert all(pids.count(p) <= 2 for p in pids)


def test_retention_deletes_records_and_files(strict, service):
    old = submit(strict, corpus("voron_vhb_din_mount.step"), params='{"reuse": false}', wait=60).json()
    folder = service.data / "strict" / "jobs" / old["id"]
    assert folder.exists()
    time.sleep(4.5)
    submit(strict, corpus("voron_vhb_din_mount.step"), params='{"reuse": false}', wait=60)  # the worker sweeps
    assert strict.get(f"/v1/jobs/{old['id']}").status_code == 404
    deadline = time.monotonic() + 10
    while folder.exists():
        assert time.monotonic() < deadline, "files of an expired job were kept"
        time.sleep(0.2)


def test_logs_are_json_lines_with_the_job_id(strict, service):
    job = submit(strict, corpus("voron_vhb_din_mount.step"), params='{"reuse": false}', wait=60).json()
    time.sleep(0.5)
    worker_lines = [json.loads(line) for line in (service.logs / "strict-worker.log").read_text().splitlines()
                    if line.startswith("{")]
    mine = [r for r in worker_lines if r.get("job_id") == job["id"]]
    assert {"started", "succeeded"} <= {r["msg"] for r in mine}
    assert any("received" in r["msg"] for r in mine)  # Celery's own lines carry it too
    api_logs = [p for p in service.logs.glob("api-*.log")]
    api_lines = [json.loads(line) for p in api_logs for line in p.read_text().splitlines() if line.startswith("{")]
    assert any(r.get("job_id") == job["id"] and r.get("method") == "POST" for r in api_lines)
