"""The dashboard's 3D view in headless Chromium with software WebGL (SwiftShader) on this machine: time to the first
drawn frame of a job's page and frames per second while the part turns, at 100k and 1 M triangles.

    python bench/dashboard.py [--write]      # → docs/bench_dashboard.md

A service runs on a private Redis (bench/load.py's stack). The 100k part is an analyze job (the page also fetches its
report, the per-triangle fields and the plots); the 1 M part a convert job of an STL (passthrough). Both STLs are
tori tessellated on a regular (u, v) grid. "first frame" is from the page starting to load to the end of the first
frame that shows the mesh; "turning" draws frame after frame for 6 s, each one finished (a 1-pixel readPixels)
before the next, so the rate is what the renderer delivers, not what it queues.
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import tempfile
from pathlib import Path

import httpx
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from amprep.geometry.core.mesh import Mesh  # noqa: E402
from amprep.geometry.io.stl import write_stl  # noqa: E402
from tests.service.browser import ARGS, chromium_path  # noqa: E402


def _load_module():  # type: ignore[no-untyped-def]
    spec = importlib.util.spec_from_file_location("bench_load", ROOT / "bench" / "load.py")
    mod = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    sys.modules["bench_load"] = mod
    spec.loader.exec_module(mod)  # type: ignore[union-attr]
    return mod


def torus(n_u: int, n_v: int, R: float = 40.0, r: float = 12.0) -> Mesh:
    """A closed torus of 2·n_u·n_v triangles on a regular (u, v) grid."""
    u, v = np.meshgrid(np.arange(n_u) * 2 * np.pi / n_u, np.arange(n_v) * 2 * np.pi / n_v, indexing="ij")
    pts = np.stack([(R + r * np.cos(v)) * np.cos(u), (R + r * np.cos(v)) * np.sin(u), r * np.sin(v)], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(n_u), np.arange(n_v), indexing="ij")
    a, b = i * n_v + j, ((i + 1) % n_u) * n_v + j
    c, d = ((i + 1) % n_u) * n_v + (j + 1) % n_v, i * n_v + (j + 1) % n_v
    tris = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return Mesh.from_arrays(pts, tris)


def job(url: str, path: Path, kind: str) -> str:
    with httpx.Client(base_url=url, timeout=900) as c:
        params = '{"bounding_box": false}' if kind == "analyze" else "{}"
        j = c.post("/v1/jobs", params={"wait": 850}, data={"kind": kind, "params": params},
                   files={"file": (path.name, path.read_bytes())}).json()
    if j["status"] != "succeeded":
        raise RuntimeError(j)
    return j["id"]


def measure(browser, url: str, job_id: str, seconds: float) -> dict:  # type: ignore[no-untyped-def, type-arg]
    page = browser.new_page(viewport={"width": 1280, "height": 860})
    page.set_default_timeout(600_000)
    page.goto(f"{url}/jobs/{job_id}")
    page.wait_for_selector("#view-main[data-ready=true]")
    first = page.evaluate("() => window.amprep.firstFrameAt")
    page.wait_for_function("() => window.amprep.viewers.at(-1).fullMs !== undefined")
    if page.evaluate("() => window.amprep.viewers.at(-1).fullMs > 30"):
        page.wait_for_function("() => window.amprep.viewers.at(-1).lod")
    moving = page.evaluate("() => window.amprep.viewers.at(-1).lod ? window.amprep.viewers.at(-1).lodOrig.length : 0")
    full = page.evaluate(f"() => window.amprep.viewers.at(-1).spin({seconds}, true)")
    fps = page.evaluate(f"() => window.amprep.viewers.at(-1).spin({seconds})")
    size = page.evaluate("() => { const c = document.querySelector('#view-main canvas'); return [c.width, c.height]; }")
    renderer = page.evaluate("""() => { const gl = document.createElement('canvas').getContext('webgl2');
        const d = gl.getExtension('WEBGL_debug_renderer_info'); return d ? gl.getParameter(d.UNMASKED_RENDERER_WEBGL) : ''; }""")
    page.close()
    return {"first_ms": first, "fps": fps, "full_fps": full, "moving": moving, "canvas": size, "renderer": renderer}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=6.0)
    ap.add_argument("--write", action="store_true")
    args = ap.parse_args()
    from playwright.sync_api import sync_playwright

    load = _load_module()
    cases = [("2k, convert", torus(50, 20), "convert"), ("100k, analyze", torus(250, 200), "analyze"),
             ("1 M, convert", torus(1000, 500), "convert")]
    rows = []
    with (tempfile.TemporaryDirectory(prefix="amprep-dash-") as tmp, load.stack(1, AMPREP_MAX_TRIANGLES="2000000") as s,
          sync_playwright() as p):
        browser = p.chromium.launch(executable_path=chromium_path(), args=ARGS)
        for name, mesh, kind in cases:
            path = Path(tmp) / f"torus_{mesh.n_triangles}.stl"
            write_stl(mesh, path)
            jid = job(s.url, path, kind)
            m = measure(browser, s.url, jid, args.seconds)
            rows.append((name, mesh.n_triangles, path.stat().st_size, m))
            print(name, m, flush=True)
        browser.close()
    renderer = rows[0][3]["renderer"]
    lines = ["| part | triangles | STL | canvas (px) | first frame (ms after the page starts loading) | "
             "turning, full mesh (frames/s) | moving copy (triangles) | turning as a drag draws it (frames/s) |",
             "|---|---:|---:|---|---:|---:|---:|---:|"]
    for name, n, size, m in rows:
        copy = f"{m['moving']:,}" if m["moving"] else "none"
        lines.append(f"| {name} | {n:,} | {size / 1e6:.1f} MB | {m['canvas'][0]}×{m['canvas'][1]} | "
                     f"{m['first_ms']:,.0f} | {m['full_fps']:.1f} | {copy} | {m['fps']:.1f} |")
    text = "\n".join(lines) + f"\n\nRenderer: {renderer}; Chromium headless, 2 cores shared with the service.\n"
    print(text)
    if args.write:
        head = ("# Dashboard: the 3D view's speed\n\n`python bench/dashboard.py --write` on this 2-core machine, "
                "headless Chromium from Debian's packages with software WebGL. \"Turning, full mesh\" draws every "
                "triangle in every frame; \"as a drag draws it\" uses the moving copy the page builds when a full "
                "frame takes over 30 ms (dashboard.md, \"A million triangles\"). Each frame is finished before "
                "the next; 60 frames/s is the display's cap.\n\n")
        (ROOT / "docs" / "bench_dashboard.md").write_text(head + text)


if __name__ == "__main__":
    main()
