"""Style and architecture checks run with the suite: ruff (no print in the library) and the import contract."""

import os
import shutil
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONUTF8": "1", "PYTHONIOENCODING": "utf-8"}  # CI may run with no UTF-8 locale


def _run(cmd: list[str]) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, cwd=ROOT, capture_output=True, encoding="utf-8", errors="replace", env=ENV)


def test_ruff_clean():
    r = _run([shutil.which("ruff") or "ruff", "check", "."])
    assert r.returncode == 0, r.stdout + r.stderr


def test_geometry_library_imports_no_web_or_queue_framework():
    r = _run([shutil.which("lint-imports") or "lint-imports"])
    assert r.returncode == 0 and "broken" in r.stdout and "0 broken" in r.stdout, r.stdout + r.stderr
