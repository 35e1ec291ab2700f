"""Build the dashboard's front end into app/static (committed, so `pip install` + `amprep serve` needs no Node):

    cd frontend && python build.py        # npm ci, esbuild bundles, vendored API-docs files, BUILD.json

- dist/dashboard.js, dist/job.js, dist/lod.js (a worker of job.js): src/*.js bundled with three.js by esbuild
  (minified ES modules).
- vendor/: swagger-ui-bundle.js, swagger-ui.css (for /docs) and redoc.standalone.js (for /redoc), copied from
  node_modules at the versions package-lock.json pins; Redoc's one request to its CDN (a logo) is replaced by an
  empty inline image.
- dist/BUILD.json: sha256 of every source file and of package-lock.json; tests/dashboard/test_build.py fails when
  a source changed after the last build.
"""

from __future__ import annotations

import hashlib
import json
import shutil
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
STATIC = HERE.parent / "app" / "static"
ENTRIES = ("dashboard.js", "job.js", "lod.js")  # lod.js: the job page's worker
#: run-time requests to other hosts inside vendored files, replaced so the pages load nothing from elsewhere
OFFLINE = {"redoc.standalone.js": [("https://cdn.redoc.ly/redoc/logo-mini.svg",  # the sidebar's "by Redocly" logo
                                   "data:image/svg+xml,%3Csvg xmlns='http://www.w3.org/2000/svg'/%3E")]}
VENDOR = {"swagger-ui-dist/swagger-ui-bundle.js": "swagger-ui-bundle.js",
          "swagger-ui-dist/swagger-ui.css": "swagger-ui.css",
          "redoc/bundles/redoc.standalone.js": "redoc.standalone.js"}


def source_hashes() -> dict[str, str]:
    """sha256 of each file the build reads: src/*.js, package.json and package-lock.json."""
    files = sorted(HERE.glob("src/*.js")) + [HERE / "package.json", HERE / "package-lock.json"]
    return {f.relative_to(HERE).as_posix(): hashlib.sha256(f.read_bytes()).hexdigest() for f in files}


def main() -> int:
    subprocess.run(["npm", "ci", "--no-audit", "--no-fund"], cwd=HERE, check=True)
    dist, vendor = STATIC / "dist", STATIC / "vendor"
    shutil.rmtree(dist, ignore_errors=True)
    dist.mkdir(parents=True)
    vendor.mkdir(parents=True, exist_ok=True)
    esbuild = HERE / "node_modules" / ".bin" / "esbuild"
    subprocess.run([str(esbuild), *(f"src/{e}" for e in ENTRIES), "--bundle", "--minify", "--format=esm",
                    "--target=es2020", "--legal-comments=linked", f"--outdir={dist}"], cwd=HERE, check=True)
    for src, name in VENDOR.items():
        text = (HERE / "node_modules" / src).read_text(encoding="utf-8")
        for old, new in OFFLINE.get(name, []):
            if old not in text:
                raise SystemExit(f"{src} no longer holds {old}: check it for other hosts")
            text = text.replace(old, new)
        (vendor / name).write_text(text, encoding="utf-8")
    for package in ("three", "swagger-ui-dist", "redoc"):
        licence = HERE / "node_modules" / package / "LICENSE"
        shutil.copyfile(licence, vendor / f"LICENSE.{package}")
    lock = json.loads((HERE / "package-lock.json").read_text())
    versions = {k.removeprefix("node_modules/"): v["version"] for k, v in lock["packages"].items()
                if k.count("node_modules/") == 1 and k.removeprefix("node_modules/") in ("three", "swagger-ui-dist",
                                                                                        "redoc", "esbuild")}
    (dist / "BUILD.json").write_text(json.dumps({"sources": source_hashes(), "versions": versions}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
