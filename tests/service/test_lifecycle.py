"""Cancel, server-sent events, signed callbacks, killed workers, API keys and the upload limit, for real."""

from __future__ import annotations

import hashlib
import hmac
import json
import os
import signal
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import httpx
import pytest

from amprep.serve import free_port
from tests.conftest import corpus
from tests.service.conftest import KEY_A, KEY_B, SECRET, submit, wait_status

SLOW = "nist_ctc02_ap242.stp"  # seconds of work at 0.01 mm: long enough to act on mid-job
SLOW_PARAMS = '{"tolerance": 0.01, "reuse": false}'
PART = "voron_vhb_din_mount.step"


def _worker_pid(job: dict) -> int:
    return int(job["worker"].rsplit(":", 1)[1])


def test_cancel_a_running_job_stops_the_worker(service):
    """The worker is free again sooner than the job would have taken: measured against the same job run to its end
    on the same machine (server timestamps, so a loaded machine slows both alike), not against a fixed time."""
    long = '{"tolerance": 0.005, "reuse": false}'
    with service.client() as c:
        whole = submit(c, corpus(SLOW), params=long, wait=300).json()
        assert whole["status"] == "succeeded"
        full = _seconds(whole["finished_at"]) - _seconds(whole["started_at"])
        job = submit(c, corpus(SLOW), params=long).json()
        wait_status(c, job["id"], ("running",))
        r = c.delete(f"/v1/jobs/{job['id']}")
        assert r.status_code == 200 and r.json()["status"] == "cancelled"
        assert r.json()["error"]["code"] == "cancelled"
        nxt = submit(c, corpus(PART), params='{"reuse": false}', wait=300).json()
        assert nxt["status"] == "succeeded" and nxt["worker"] == whole["worker"]
        cancelled = c.get(f"/v1/jobs/{job['id']}").json()
        assert cancelled["status"] == "cancelled"  # never overwritten
        freed = _seconds(nxt["started_at"]) - _seconds(cancelled["started_at"])
    assert freed < 0.75 * full, (freed, full)


def _seconds(stamp: str) -> float:
    from datetime import datetime

    return datetime.fromisoformat(stamp.replace("Z", "+00:00")).timestamp()


def test_cancel_a_queued_job(service):
    with service.client() as c:
        busy = submit(c, corpus(SLOW), params=SLOW_PARAMS).json()
        queued = submit(c, corpus(PART), params='{"reuse": false}').json()
        assert c.get(f"/v1/jobs/{queued['id']}").json()["status"] == "queued"
        assert c.delete(f"/v1/jobs/{queued['id']}").json()["status"] == "cancelled"
        c.delete(f"/v1/jobs/{busy['id']}")
        time.sleep(2)
        job = c.get(f"/v1/jobs/{queued['id']}").json()
        assert job["status"] == "cancelled" and job["started_at"] is None and job["attempts"] == 0


def test_events_stream_until_the_job_ends(service):
    with service.client() as c:
        job = submit(c, corpus("featuretype_inch_ap214.step"), params='{"tolerance": 0.01, "reuse": false}').json()
        seen = []
        with c.stream("GET", f"/v1/jobs/{job['id']}/events") as r:
            assert r.headers["content-type"].startswith("text/event-stream")
            event = None
            for line in r.iter_lines():
                if line.startswith("event:"):
                    event = line[6:].strip()
                elif line.startswith("data:"):
                    assert event == "job"
                    seen.append(json.loads(line[5:]))
    assert seen[-1]["status"] == "succeeded" and seen[-1]["progress"] == 1.0
    progress = [j["progress"] for j in seen if j["status"] == "running"]
    assert progress == sorted(progress)
    assert len({(j["status"], j["stage"], j["progress"]) for j in seen}) == len(seen)  # changes only


class _Receiver(BaseHTTPRequestHandler):
    calls: list = []
    fail_first = 0

    def do_POST(self) -> None:  # noqa: N802
        body = self.rfile.read(int(self.headers["Content-Length"]))
        type(self).calls.append((dict(self.headers), body, time.monotonic()))
        ok = len(type(self).calls) > type(self).fail_first
        self.send_response(200 if ok else 503)
        self.end_headers()

    def log_message(self, *args) -> None:
        pass


@pytest.fixture
def receiver():
    _Receiver.calls, _Receiver.fail_first = [], 0
    port = free_port()
    server = ThreadingHTTPServer(("127.0.0.1", port), _Receiver)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    yield f"http://127.0.0.1:{port}/hook", _Receiver
    server.shutdown()


def _wait_calls(rec, n: int, timeout: float = 30) -> None:
    deadline = time.monotonic() + timeout
    while len(rec.calls) < n:
        assert time.monotonic() < deadline, f"{len(rec.calls)} callback(s) of {n}"
        time.sleep(0.05)


def test_callback_is_signed_and_carries_the_final_job(service, receiver):
    url, rec = receiver
    with service.client() as c:
        job = submit(c, corpus(PART), params=json.dumps({"callback_url": url, "reuse": False}), wait=60).json()
    _wait_calls(rec, 1)
    headers, body, _ = rec.calls[0]
    expected = "sha256=" + hmac.new(SECRET.encode(), body, hashlib.sha256).hexdigest()
    assert headers["X-Amprep-Signature"] == expected
    sent = json.loads(body)
    assert sent["id"] == job["id"] and sent["status"] == "succeeded" and sent["artifacts"]


def test_callback_retries_with_backoff(service, receiver):
    url, rec = receiver
    rec.fail_first = 2
    with service.client() as c:
        submit(c, corpus(PART), params=json.dumps({"callback_url": url, "reuse": False}), wait=60)
    _wait_calls(rec, 3, timeout=60)
    gaps = [b[2] - a[2] for a, b in zip(rec.calls, rec.calls[1:])]
    assert gaps[1] > gaps[0] * 1.5  # exponential backoff: 1 s, then 2 s


def test_callback_on_cancel_and_never_blocking_jobs(service, receiver):
    url, rec = receiver
    with service.client() as c:
        job = submit(c, corpus(SLOW), params=json.dumps({"callback_url": url, "tolerance": 0.01, "reuse": False})).json()
        wait_status(c, job["id"], ("running",))
        c.delete(f"/v1/jobs/{job['id']}")
    _wait_calls(rec, 1)
    assert json.loads(rec.calls[0][1])["status"] == "cancelled"


def test_worker_killed_mid_job_the_job_still_finishes(service):
    with service.client() as c:
        job = submit(c, corpus(SLOW), params=SLOW_PARAMS).json()
        running = wait_status(c, job["id"], ("running",))
        time.sleep(0.5)
        os.kill(_worker_pid(running), signal.SIGKILL)
        done = wait_status(c, job["id"], ("succeeded", "failed"), timeout=180)
    assert done["status"] == "succeeded" and done["attempts"] == 2
    assert done["worker"] != running["worker"]  # a fresh process ran it


def test_input_that_kills_its_worker_twice_fails_with_worker_crashed(service):
    with service.client() as c:
        job = submit(c, corpus(SLOW), params=SLOW_PARAMS).json()
        killed = set()
        for _ in range(2):
            deadline = time.monotonic() + 60
            while True:
                j = c.get(f"/v1/jobs/{job['id']}").json()
                if j["status"] == "running" and j["worker"] not in killed:
                    break
                assert time.monotonic() < deadline
                time.sleep(0.05)
            killed.add(j["worker"])
            os.kill(_worker_pid(j), signal.SIGKILL)
        done = wait_status(c, job["id"], ("succeeded", "failed"), timeout=60)
        assert done["status"] == "failed" and done["error"]["code"] == "worker_crashed"
        assert submit(c, corpus(PART), params='{"reuse": false}', wait=60).json()["status"] == "succeeded"


def test_api_keys_isolate_owners(service, keyed_api):
    a = httpx.Client(base_url=keyed_api, headers={"Authorization": f"Bearer {KEY_A}"}, timeout=60)
    b = httpx.Client(base_url=keyed_api, headers={"Authorization": f"Bearer {KEY_B}"}, timeout=60)
    anon = httpx.Client(base_url=keyed_api, timeout=60)
    with a, b, anon:
        assert anon.get("/healthz").status_code == 200 and anon.get("/readyz").status_code == 200
        assert anon.get("/metrics").status_code == 401 and a.get("/metrics").status_code == 200
        r = anon.get("/v1/jobs")
        assert r.status_code == 401 and r.json()["code"] == "unauthorized" and r.headers["www-authenticate"] == "Bearer"
        bad = httpx.get(keyed_api + "/v1/jobs", headers={"Authorization": "Bearer wrong"})
        assert bad.status_code == 401
        assert submit(anon, corpus(PART)).status_code == 401
        job = submit(a, corpus(PART), wait=60).json()
        assert a.get(f"/v1/jobs/{job['id']}").status_code == 200
        for path in (f"/v1/jobs/{job['id']}", f"/v1/jobs/{job['id']}/artifacts/part.stl", f"/v1/jobs/{job['id']}/events"):
            r = b.get(path)
            assert r.status_code == 404 and r.json()["code"] == "not_found", path
        assert b.delete(f"/v1/jobs/{job['id']}").status_code == 404
        assert job["id"] not in [j["id"] for j in b.get("/v1/jobs").json()["jobs"]]
        assert job["id"] in [j["id"] for j in a.get("/v1/jobs").json()["jobs"]]
        # B submitting the same bytes gets its own job, never A's result.
        jb = submit(b, corpus(PART), wait=60).json()
        assert jb["reused_from"] is None or b.get(f"/v1/jobs/{jb['reused_from']}").status_code == 200
    keys = service.store.redis.keys("*")
    assert not any(KEY_A in k or KEY_B in k for k in keys)  # keys are never stored, only their digests


def test_upload_limit_is_413_while_streaming(service):
    url, proc = service.start_api(AMPREP_MAX_UPLOAD_BYTES="1000000")
    try:
        with httpx.Client(base_url=url, timeout=60) as c:
            r = submit(c, corpus(SLOW))  # 3.4 MB
            assert r.status_code == 413 and r.json()["code"] == "upload_too_large"

            def chunks():  # no Content-Length: the limit must hold on the stream itself
                boundary = b"--xyz\r\n"
                yield boundary + b'Content-Disposition: form-data; name="kind"\r\n\r\nconvert\r\n'
                yield boundary + b'Content-Disposition: form-data; name="file"; filename="big.stl"\r\n\r\n'
                for _ in range(150):  # 1.2 MB
                    yield b"solid x\n" + b" " * 8192
                yield b"\r\n--xyz--\r\n"

            r = c.post("/v1/jobs", content=chunks(), headers={"Content-Type": "multipart/form-data; boundary=xyz"})
            assert r.status_code == 413 and r.json()["code"] == "upload_too_large"
            assert submit(c, corpus(PART)).status_code == 202  # 310 kB: under the limit
    finally:
        proc.terminate()
        proc.wait(10)
