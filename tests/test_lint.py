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


def test_layout_keeps_folders_modules_and_functions_small():
    """The layout's limits (docs/architecture.md): no package folder over 15 modules, no module over 500 lines, no
    function over 80 lines; errors.py sits above the geometry library, which is split into its wings."""
    import ast

    too_big = []
    for pkg in ("amprep", "app", "workers"):
        for folder in [ROOT / pkg, *(p for p in (ROOT / pkg).rglob("*") if p.is_dir() and p.name != "__pycache__")]:
            modules = [m for m in folder.glob("*.py") if m.name != "__init__.py"]
            if len(modules) > 15:
                too_big.append(f"{folder.relative_to(ROOT)}: {len(modules)} modules")
        for path in (ROOT / pkg).rglob("*.py"):
            text = path.read_text(encoding="utf-8")
            if text.count("\n") > 500:
                too_big.append(f"{path.relative_to(ROOT)}: {text.count(chr(10))} lines")
            for node in ast.walk(ast.parse(text)):
                if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and node.end_lineno - node.lineno >= 80:
                    too_big.append(f"{path.relative_to(ROOT)}: {node.name}() {node.end_lineno - node.lineno + 1} lines")
    assert not too_big, too_big
    assert (ROOT / "amprep" / "errors.py").exists() and not (ROOT / "amprep" / "geometry" / "errors.py").exists()
    wings = {p.name for p in (ROOT / "amprep" / "geometry").iterdir() if (p / "__init__.py").exists()}
    assert wings == {"core", "cad", "meshing", "measure", "refine", "placement", "io", "parallel"}
    assert not list((ROOT / "amprep" / "geometry").glob("*.py")) or \
        [p.name for p in (ROOT / "amprep" / "geometry").glob("*.py")] == ["__init__.py"]
