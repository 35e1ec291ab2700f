"""What can be checked of the Docker files without a Docker engine (none runs on the CI machine).

The compose file parses and has the shape the README promises; every command it and the Dockerfile name exists
in this package and accepts its arguments; every path the Dockerfile copies exists.
"""

from __future__ import annotations

import re
import shlex
import subprocess
import sys
from pathlib import Path

import yaml

from amprep.cli import build_parser

ROOT = Path(__file__).resolve().parents[2]


def _compose() -> dict:
    return yaml.safe_load((ROOT / "docker-compose.yml").read_text())


def test_compose_shape():
    c = _compose()
    services = c["services"]
    assert {"redis", "api", "worker"} <= set(services)
    redis = services["redis"]
    assert "--appendonly" in redis["command"] and redis["command"][redis["command"].index("--appendonly") + 1] == "yes"
    assert "healthcheck" in redis
    assert all(s.get("restart") == "unless-stopped" for s in services.values())  # a dead worker comes back
    images = {services[n]["image"] for n in services if n != "redis"}
    assert len(images) == 1  # one image: API and workers differ only by command
    for name in ("api", "worker", "worker-heavy"):
        s = services[name]
        assert s["build"]["dockerfile"] == "docker/Dockerfile"
        assert "artifacts:/data" in s["volumes"]
        assert s["environment"]["AMPREP_REDIS_URL"].startswith("redis://redis:")
        assert s["depends_on"]["redis"]["condition"] == "service_healthy"
    worker = services["worker"]
    assert "container_name" not in worker and "ports" not in worker  # --scale worker=4 needs both absent
    assert "AMPREP_API_KEYS" in services["api"]["environment"]


def test_every_command_exists_and_parses():
    c = _compose()
    for name in ("api", "worker", "worker-heavy"):
        cmd = c["services"][name]["command"]
        if cmd[0] == "amprep":
            build_parser().parse_args(cmd[1:])
        else:
            assert cmd[:4] == ["celery", "-A", "workers.celery_app", "worker"], cmd
            queues = cmd[cmd.index("-Q") + 1].split(",")
            from workers.celery_app import app

            assert set(queues) <= {q.name for q in app.conf.task_queues}
            r = subprocess.run([sys.executable, "-m", "celery", "-A", "workers.celery_app", "worker", "--help"],
                               capture_output=True, text=True, timeout=120, cwd=ROOT)
            assert r.returncode == 0 and "--queues" in r.stdout
    dockerfile = (ROOT / "docker" / "Dockerfile").read_text()
    cmd = shlex.split(re.search(r'^CMD \[(.*)\]$', dockerfile, re.M).group(1).replace(",", " "))
    assert cmd[0] == "amprep"
    build_parser().parse_args(cmd[1:])
    for src in re.findall(r"^COPY (.+) \S+$", dockerfile, re.M):
        for path in src.split():
            assert (ROOT / path).exists(), path
    for run in re.findall(r"^RUN amprep (.+)$", dockerfile, re.M):
        build_parser().parse_args(shlex.split(run))


def test_the_image_warms_numbas_cache_as_the_user_that_runs_it():
    """`amprep warm` runs after USER amprep, into NUMBA_CACHE_DIR, a directory made and given to that user before
    (numba ignores a cache directory it cannot write: root's compiled kernels would be compiled again)."""
    dockerfile = (ROOT / "docker" / "Dockerfile").read_text()
    cache = re.search(r"NUMBA_CACHE_DIR=(\S+)", dockerfile).group(1)
    made = re.search(r"mkdir -p [^&]*" + re.escape(cache), dockerfile)
    owned = re.search(r"chown -R amprep:amprep [^&\n]*" + re.escape(str(Path(cache).parent)), dockerfile)
    assert made and owned
    assert dockerfile.index("USER amprep") < dockerfile.index("RUN amprep warm") < dockerfile.index("CMD")


def test_api_image_command_needs_keys_on_a_public_address(tmp_path):
    """The image's API binds 0.0.0.0: without AMPREP_API_KEYS it refuses to start, and says why."""
    import os

    env = {k: v for k, v in os.environ.items() if not k.startswith("AMPREP_")}
    env["AMPREP_REDIS_URL"] = "redis://127.0.0.1:9/0"
    r = subprocess.run([sys.executable, "-m", "amprep", "serve", "--host", "0.0.0.0", "--no-workers",
                        "--data", str(tmp_path)], capture_output=True, text=True, timeout=60, env=env)
    assert r.returncode == 2 and "AMPREP_API_KEYS" in r.stderr
