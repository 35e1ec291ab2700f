"""The dashboard's built files: current with their sources (frontend/build.py records their hashes), shipped inside
the Python package (a wheel holds them), and the pages reference only this server's own files."""

from __future__ import annotations

import importlib.util
import json
import re
import subprocess
import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
STATIC = ROOT / "app" / "static"


def _build_module():  # type: ignore[no-untyped-def]
    spec = importlib.util.spec_from_file_location("frontend_build", ROOT / "frontend" / "build.py")
    mod = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    spec.loader.exec_module(mod)  # type: ignore[union-attr]
    return mod


def test_bundles_are_built_from_the_current_sources():
    recorded = json.loads((STATIC / "dist" / "BUILD.json").read_text(encoding="utf-8"))
    assert recorded["sources"] == _build_module().source_hashes(), "frontend/src changed: run `python frontend/build.py`"
    for entry in _build_module().ENTRIES:
        assert (STATIC / "dist" / entry).stat().st_size > 1000


def test_pages_load_only_local_files():
    for page in ("index.html", "job.html"):
        html = (STATIC / page).read_text(encoding="utf-8")
        refs = re.findall(r'(?:src|href)="([^"]+)"', html)
        assert refs and all(r.startswith("/") and not r.startswith("//") for r in refs), refs
        for r in refs:
            if r.startswith("/static/"):
                assert (STATIC / r.removeprefix("/static/")).is_file(), r


def test_wheel_ships_the_dashboard(tmp_path: Path):
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w",
                    str(tmp_path), str(ROOT)], check=True, capture_output=True)
    wheel = next(tmp_path.glob("amprep-*.whl"))
    names = set(zipfile.ZipFile(wheel).namelist())
    for f in ("index.html", "job.html", "style.css", "dist/dashboard.js", "dist/job.js", "vendor/swagger-ui-bundle.js",
              "vendor/swagger-ui.css", "vendor/redoc.standalone.js"):
        assert f"app/static/{f}" in names, f
