"""Load: many small convert jobs from concurrent clients on a 2-process worker, with the Redis server restarted
mid-load; none lost or duplicated, every result closed. Prints submit latency (p50/p99), 503s and jobs/s.

    python bench/load.py [--jobs 1000] [--clients 20] [--workers 2] [--restart-at 0.4] [--down 3] [--write]

The stack is started here (Redis persisting with its append-only file, `celery … worker -Q quick -c WORKERS`, one
uvicorn), not by `amprep serve`, so that Redis can be stopped and started again on its port. Each client submits
its share with its own Idempotency-Key per job and retries a 503 after its Retry-After. With --write the table
goes to docs/bench_load.md. tests/reliability/test_load.py runs a smaller load through run_load.
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import httpx

ROOT = Path(__file__).resolve().parents[1]
CORPUS = Path(os.environ.get("AMPREP_CORPUS", ROOT.parent / "shared" / "corpus"))
sys.path.insert(0, str(ROOT))

from amprep.serve import free_port, start_redis, wait_http  # noqa: E402


def pct(values: list[float], q: float) -> float:
    s = sorted(values)
    return s[min(len(s) - 1, max(0, round(q / 100 * (len(s) - 1))))] if s else float("nan")


@dataclass
class Stack:
    """A Redis server (restartable on its port), a job worker and an API."""

    data: Path
    url: str
    redis: subprocess.Popen  # type: ignore[type-arg]
    redis_port: int
    procs: list[subprocess.Popen] = field(default_factory=list)  # type: ignore[type-arg]

    def restart_redis(self, down: float) -> None:
        """Stop Redis (SIGTERM: it writes its append-only file), stay down `down` seconds, start it on its port."""
        self.redis.send_signal(signal.SIGTERM)
        self.redis.wait(30)
        time.sleep(down)
        self.redis, _ = start_redis(self.data, port=self.redis_port)


def _spawn(cmd: list[str], env: dict[str, str], log: Path) -> subprocess.Popen:  # type: ignore[type-arg]
    return subprocess.Popen(cmd, env=env, cwd=ROOT, stdout=log.open("ab"), stderr=subprocess.STDOUT,
                            start_new_session=True)


@contextmanager
def stack(workers: int = 2, **env_extra: str) -> Iterator[Stack]:
    data = Path(tempfile.mkdtemp(prefix="amprep-load-"))
    redis_proc, redis_url = start_redis(data)
    port = int(redis_url.rsplit(":", 1)[1].split("/")[0])
    env = dict(os.environ, AMPREP_REDIS_URL=redis_url, AMPREP_DATA_DIR=str(data), PYTHONUNBUFFERED="1",
               AMPREP_MAX_JOBS_PER_PROCESS="1000", **env_extra)
    env.pop("AMPREP_API_KEYS", None)
    api_port = free_port()
    s = Stack(data, f"http://127.0.0.1:{api_port}", redis_proc, port)
    s.procs.append(_spawn([sys.executable, "-m", "celery", "-A", "workers.celery_app", "worker", "-Q", "quick",
                           "-c", str(workers), "-n", "load@%h", "--without-gossip", "--without-mingle", "-O", "fair"],
                          env, data / "worker.log"))
    s.procs.append(_spawn([sys.executable, "-m", "uvicorn", "app.main:app", "--port", str(api_port)], env,
                          data / "api.log"))
    try:
        if not wait_http(s.url + "/healthz", 60):
            raise RuntimeError((data / "api.log").read_text()[-2000:])
        deadline = time.monotonic() + 90
        while httpx.get(s.url + "/readyz").status_code != 200:
            if time.monotonic() > deadline:
                raise RuntimeError((data / "worker.log").read_text()[-3000:])
            time.sleep(0.3)
        yield s
    finally:
        for p in s.procs:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGTERM)
        for p in s.procs:
            try:
                p.wait(20)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
        s.redis.terminate()
        s.redis.wait(10)
        shutil.rmtree(data, ignore_errors=True)  # the Redis dump, the jobs' files and the logs (read inside the block)


@dataclass
class LoadResult:
    jobs: int
    clients: int
    submit_seconds: list[float]  # every submit attempt that was answered (202/200/503)
    unavailable: int  # 503 answers (retried)
    ids: dict[str, str]  # Idempotency-Key → job id
    ended: dict[str, dict]  # type: ignore[type-arg]  # job id → its final record
    listed: int  # jobs the list endpoint returns
    seconds: float  # first submit to last job ended

    @property
    def succeeded(self) -> int:
        return sum(j["status"] == "succeeded" for j in self.ended.values())

    @property
    def closed(self) -> int:
        return sum(bool(j.get("result", {}).get("mesh", {}).get("watertight")) for j in self.ended.values())


def _submit(c: httpx.Client, part: Path, key: str, times: list[float], lock: threading.Lock,
            unavailable: list[int]) -> str:
    data = part.read_bytes()
    for _ in range(200):
        t0 = time.monotonic()
        try:
            r = c.post("/v1/jobs", data={"kind": "convert", "params": '{"reuse": false}'},
                       files={"file": (part.name, data)}, headers={"Idempotency-Key": key})
        except httpx.TransportError:
            time.sleep(1.0)
            continue
        with lock:
            times.append(time.monotonic() - t0)
        if r.status_code in (200, 202):
            return str(r.json()["id"])
        if r.status_code == 503:
            with lock:
                unavailable[0] += 1
            time.sleep(float(r.headers.get("Retry-After", "1")))
            continue
        raise RuntimeError(f"submit answered {r.status_code}: {r.text[:300]}")
    raise RuntimeError("submit never accepted")


def _ended(c: httpx.Client, job_id: str, deadline: float, s: Stack) -> dict:  # type: ignore[type-arg]
    """The job's record once it has ended; TimeoutError past `deadline`, RuntimeError at once when a process of the
    stack has exited (a dead worker leaves its jobs unended until the broker's visibility timeout)."""
    last = None
    while True:
        dead = [p for p in s.procs if p.poll() is not None]
        if dead:
            log = (s.data / "worker.log").read_text(errors="replace")[-3000:]
            raise RuntimeError(f"{len(dead)} process(es) of the stack exited (codes {[p.returncode for p in dead]}); "
                               f"the worker's log ends:\n{log}")
        try:
            r = c.get(f"/v1/jobs/{job_id}")
            last = r.json() if r.status_code in (200, 202) else last
            if r.status_code == 200 and r.json()["status"] in ("succeeded", "failed", "cancelled"):
                return r.json()  # type: ignore[no-any-return]
        except httpx.TransportError:
            pass
        if time.monotonic() > deadline:
            seen = {k: last.get(k) for k in ("status", "stage", "attempts", "worker", "started_at")} if last else None
            raise TimeoutError(f"job {job_id} did not end; last seen {seen}")
        time.sleep(0.2)


def run_load(s: Stack, part: Path, jobs: int, clients: int, restart_at: float | None = None, down: float = 3.0,
             timeout: float = 3600) -> LoadResult:
    """Submit `jobs` converts of `part` from `clients` threads (keys load-<client>-<i>), restarting Redis once
    restart_at × jobs have been accepted; wait for every job; list them."""
    times: list[float] = []
    unavailable = [0]
    lock = threading.Lock()
    accepted = [0]
    restarted = threading.Event()
    ids: dict[str, str] = {}

    def client(n: int) -> None:
        with httpx.Client(base_url=s.url, timeout=120) as c:
            for i in range(n, jobs, clients):
                key = f"load-{n}-{i}"
                job_id = _submit(c, part, key, times, lock, unavailable)
                with lock:
                    ids[key] = job_id
                    accepted[0] += 1
                    go = restart_at is not None and not restarted.is_set() and accepted[0] >= restart_at * jobs
                    if go:
                        restarted.set()
                if go:
                    threading.Thread(target=s.restart_redis, args=(down,), daemon=True).start()

    t0 = time.monotonic()
    with ThreadPoolExecutor(clients) as pool:
        list(pool.map(client, range(clients)))
    deadline = time.monotonic() + timeout
    with httpx.Client(base_url=s.url, timeout=120) as c:
        ended = {job_id: _ended(c, job_id, deadline, s) for job_id in ids.values()}
        seconds = time.monotonic() - t0
        listed, cursor = 0, None
        while True:
            page = c.get("/v1/jobs", params={"limit": 200} | ({"cursor": cursor} if cursor else {})).json()
            listed += len(page["jobs"])
            cursor = page["next_cursor"]
            if cursor is None:
                break
    return LoadResult(jobs, clients, times, unavailable[0], ids, ended, listed, seconds)


def table(r: LoadResult, restarted: bool, workers: int) -> str:
    ms = [1000 * t for t in r.submit_seconds]
    rows = [
        ("jobs submitted / clients / worker processes", f"{r.jobs} / {r.clients} / {workers}"),
        ("Redis restarted mid-load", "yes" if restarted else "no"),
        ("distinct jobs (by key) / listed by the API", f"{len(set(r.ids.values()))} / {r.listed}"),
        ("succeeded / closed results", f"{r.succeeded} / {r.closed}"),
        ("503 answers while Redis was down (retried)", str(r.unavailable)),
        ("submit latency p50 / p99 (ms)", f"{pct(ms, 50):.0f} / {pct(ms, 99):.0f}"),
        ("throughput (jobs/s, first submit to last job ended)", f"{r.jobs / r.seconds:.1f}"),
    ]
    return "| measure | value |\n|---|---|\n" + "".join(f"| {a} | {b} |\n" for a, b in rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=1000)
    ap.add_argument("--clients", type=int, default=20)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--restart-at", type=float, default=0.4)
    ap.add_argument("--down", type=float, default=3.0)
    ap.add_argument("--part", default="cq_cube_cylinder_colors.step")
    ap.add_argument("--write", action="store_true")
    args = ap.parse_args()
    with stack(args.workers) as s:
        r = run_load(s, CORPUS / args.part, args.jobs, args.clients, args.restart_at if args.restart_at > 0 else None,
                     args.down)
    text = table(r, args.restart_at > 0, args.workers)
    print(text)
    if args.write:
        head = (f"# Load: {args.jobs} small convert jobs ({args.part}) from {args.clients} clients\n\n"
                f"`python bench/load.py --jobs {args.jobs} --clients {args.clients} --workers {args.workers} "
                f"--restart-at {args.restart_at} --down {args.down} --write`, on this 2-core machine. The p99 submit "
                "latency includes the submits held while Redis was down (the broker publish retrying); a 503 is "
                "retried after its Retry-After.\n\n")
        (ROOT / "docs" / "bench_load.md").write_text(head + text)


if __name__ == "__main__":
    main()
