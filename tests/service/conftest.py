"""The real system: a Redis server, a Celery worker subprocess and the API over HTTP (uvicorn subprocesses)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import httpx
import pytest

from amprep.serve import free_port, start_redis, wait_http
from amprep.settings import hash_key
from amprep.store import JobStore

ROOT = Path(__file__).resolve().parents[2]
SECRET = "test-callback-secret"
KEY_A, KEY_B = "amp_test_key_alpha", "amp_test_key_beta"


def _spawn(cmd: list[str], env: dict[str, str], log: Path) -> subprocess.Popen:
    fh = log.open("ab")
    return subprocess.Popen(cmd, env=env, cwd=ROOT, stdout=fh, stderr=subprocess.STDOUT, start_new_session=True)


def _stop(proc: subprocess.Popen, grace: float = 10.0) -> None:
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(grace)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


@dataclass
class Service:
    url: str
    env: dict[str, str]
    store: JobStore
    data: Path
    logs: Path
    worker: subprocess.Popen

    def client(self, key: str | None = None) -> httpx.Client:
        headers = {"Authorization": f"Bearer {key}"} if key else {}
        return httpx.Client(base_url=self.url, headers=headers, timeout=120)

    def start_api(self, **env: str) -> tuple[str, subprocess.Popen]:
        """Another API process on the same Redis and data (e.g. with API keys or a small upload limit)."""
        port = free_port()
        proc = _spawn([sys.executable, "-m", "uvicorn", "app.main:app", "--port", str(port)],
                      dict(self.env, **env), self.logs / f"api-{port}.log")
        url = f"http://127.0.0.1:{port}"
        assert wait_http(url + "/healthz", 60), "extra API did not start"
        return url, proc


@contextmanager
def running_service(data: Path, logs: Path, **extra: str) -> Iterator[Service]:
    """A Redis server, a job worker (one process for both queues), a callback worker and an API on them, with the
    environment `extra` added; all stopped after."""
    redis_proc, redis_url = start_redis(data)
    env = dict(os.environ, AMPREP_REDIS_URL=redis_url, AMPREP_DATA_DIR=str(data), AMPREP_CALLBACK_SECRET=SECRET,
               AMPREP_MAX_JOBS_PER_PROCESS="50", PYTHONUNBUFFERED="1",
               AMPREP_CALLBACK_ALLOW="127.0.0.1")  # the tests' callback receivers listen on loopback
    env.pop("AMPREP_API_KEYS", None)
    env.update(extra)
    # One process per queue: a test can tell which process runs its job and kill it.
    worker = _spawn([sys.executable, "-m", "celery", "-A", "workers.celery_app", "worker", "-Q", "quick,heavy",
                     "-c", "1", "-n", "test@%h", "--without-gossip", "--without-mingle", "-O", "fair"],
                    env, logs / "worker.log")
    callbacks = _spawn([sys.executable, "-m", "celery", "-A", "workers.celery_app", "worker", "-Q", "callbacks",
                        "-P", "threads", "-c", "4", "-n", "cb@%h", "--without-gossip", "--without-mingle"],
                       env, logs / "callbacks.log")
    port = free_port()
    api = _spawn([sys.executable, "-m", "uvicorn", "app.main:app", "--port", str(port)], env, logs / "api.log")
    url = f"http://127.0.0.1:{port}"
    try:
        assert wait_http(url + "/healthz", 60), (logs / "api.log").read_text()[-2000:]
        deadline = time.monotonic() + 60
        while httpx.get(url + "/readyz").status_code != 200:
            assert time.monotonic() < deadline, (logs / "worker.log").read_text()[-3000:]
            time.sleep(0.3)
        yield Service(url, env, JobStore(redis_url, data), data, logs, worker)
    finally:
        for p in (api, worker, callbacks):
            _stop(p)
        redis_proc.terminate()
        redis_proc.wait(10)


#: the shared service's cap on any job's output (a torus at 0.0001 mm is estimated over it)
MAX_TRIANGLES = 1_000_000


@pytest.fixture(scope="session")
def service(tmp_path_factory: pytest.TempPathFactory):
    with running_service(tmp_path_factory.mktemp("amprep-data"), tmp_path_factory.mktemp("logs"),
                         AMPREP_MAX_TRIANGLES=str(MAX_TRIANGLES)) as svc:
        yield svc


@pytest.fixture(scope="session")
def keyed_api(service: Service):
    """An API process with two API keys configured (same Redis and workers)."""
    url, proc = service.start_api(AMPREP_API_KEYS=f"{hash_key(KEY_A)},{hash_key(KEY_B)}")
    yield url
    _stop(proc)


def wait_status(client: httpx.Client, job_id: str, statuses: tuple[str, ...], timeout: float = 120) -> dict:
    deadline = time.monotonic() + timeout
    while True:
        job = client.get(f"/v1/jobs/{job_id}").json()
        if job["status"] in statuses:
            return job
        assert time.monotonic() < deadline, f"job {job_id} stuck in {job['status']}"
        time.sleep(0.05)


def submit(client: httpx.Client, path: Path, kind: str = "convert", params: str = "{}", wait: float = 0,
           headers: dict | None = None, **files: Path) -> httpx.Response:
    parts = {"file": (path.name, path.read_bytes())} | {k: (v.name, v.read_bytes()) for k, v in files.items()}
    return client.post("/v1/jobs", params={"wait": wait} if wait else None, data={"kind": kind, "params": params},
                       files=parts, headers=headers or {})
