"""`amprep submit`, the command-line client, against the running service."""

from __future__ import annotations

import json
import subprocess
import sys

from amprep.geometry.core.checks import check_mesh
from amprep.geometry.io.stl import read_stl
from tests.conftest import corpus
from tests.service.conftest import KEY_A


def _submit(*args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "amprep", "submit", *args], capture_output=True, text=True,
                          timeout=300, env=env)


def test_submit_waits_and_writes_the_stl(service, tmp_path):
    out = tmp_path / "part.stl"
    r = _submit(str(corpus("voron_vhb_din_mount.step")), "--kind", "convert", "--server", service.url,
                "-p", "tolerance=0.04", "-p", "reuse=false", "-o", str(out), "--json")
    assert r.returncode == 0, r.stderr
    job = json.loads(r.stdout)
    assert job["status"] == "succeeded" and job["params"]["tolerance"] == 0.04
    assert check_mesh(read_stl(out)).closed


def test_submit_analyze_report_and_failed_job_exit_status(service, tmp_path):
    out = tmp_path / "report.json"
    r = _submit(str(corpus("voron_vhb_din_mount.step")), "--kind", "analyze", "--server", service.url, "-o", str(out))
    assert r.returncode == 0 and json.loads(out.read_text())["schema"] == "amprep.report/1"
    r = _submit(str(corpus("featuretype_inch.stl")), "--kind", "refine", "--server", service.url, "--wait")
    assert r.returncode == 2 and "[invalid_parameter]" in r.stderr


def test_submit_errors_are_one_line_with_a_code(service, tmp_path):
    notes = tmp_path / "notes.txt"
    notes.write_text("hello\n" * 100)
    r = _submit(str(notes), "--kind", "convert", "--server", service.url)
    assert r.returncode == 2 and r.stderr.strip().startswith("amprep: error [unsupported_format]")
    assert len(r.stderr.strip().splitlines()) == 1
    r = _submit(str(corpus("voron_vhb_din_mount.step")), "--kind", "convert", "--server", "http://127.0.0.1:9")
    assert r.returncode == 2 and "[unavailable]" in r.stderr


def test_submit_with_an_api_key(service, keyed_api, tmp_path):
    step = str(corpus("voron_vhb_din_mount.step"))
    r = _submit(step, "--kind", "convert", "--server", keyed_api)
    assert r.returncode == 2 and "[unauthorized]" in r.stderr
    r = _submit(step, "--kind", "convert", "--server", keyed_api, "--api-key", KEY_A, "--wait")
    assert r.returncode == 0 and "succeeded" in r.stdout
