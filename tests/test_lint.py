"""Style and architecture checks run with the suite: ruff (no print in the library) and the import contract."""

import shutil
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_ruff_clean():
    r = subprocess.run([shutil.which("ruff") or "ruff", "check", "."], cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr


def test_geometry_library_imports_no_web_or_queue_framework():
    r = subprocess.run([shutil.which("lint-imports") or "lint-imports"], cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 0 and "broken" in r.stdout and "0 broken" in r.stdout, r.stdout + r.stderr
