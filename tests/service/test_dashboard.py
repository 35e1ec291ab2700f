"""The dashboard in a real browser (Debian's Chromium driven by Playwright) against the real service: upload through
the page, the live list, the 3D view's pixels, error colouring, a defect highlighted, downloads that are the job's
artifacts, the API docs — and not one request to another host."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numpy as np
import pytest

from amprep.geometry.io.stl import read_stl, write_stl
from tests.conftest import corpus, filleted_box

from .browser import (
    ARGS,
    chromium_path,
    drawn_fraction,
    guard_host,
    have_browser,
    near_colour,
    pixels,
    saturated_fraction,
)
from .conftest import KEY_A, Service, submit, wait_status

ROOT = Path(__file__).resolve().parents[2]
SHOTS = Path(os.environ.get("AMPREP_TEST_ARTIFACTS", ROOT / "test-artifacts")) / "dashboard"
HIGHLIGHT = (0xFF, 0xD4, 0x00)
LONG = 180_000  # ms: a busy 2-core machine runs the worker, the API and the browser at once


@pytest.fixture(scope="module")
def browser():
    have_browser()
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=chromium_path(), args=ARGS)
        yield b
        b.close()


@pytest.fixture
def page(browser, service: Service):
    """A fresh page on the service whose requests to any other host fail the test."""
    SHOTS.mkdir(parents=True, exist_ok=True)
    context = browser.new_context(viewport={"width": 1280, "height": 860}, accept_downloads=True)
    pg = context.new_page()
    outside: list[str] = []
    errors: list[str] = []
    guard_host(pg, service.url, outside)
    pg.on("pageerror", lambda e: errors.append(str(e)))
    pg.set_default_timeout(LONG)
    yield pg
    context.close()
    assert not outside, f"the page asked another host: {outside[:5]}"
    assert not errors, f"script errors: {errors[:5]}"


def analyzed(service: Service, stl: Path) -> dict:  # type: ignore[type-arg]
    """The succeeded analyze job of an STL (no bounding-box cusp method: faster)."""
    with service.client() as c:
        job = submit(c, stl, "analyze", '{"bounding_box": false}').json()
        job = wait_status(c, job["id"], ("succeeded", "failed"), 180)
    assert job["status"] == "succeeded", job
    return job


def view_pixels(pg, selector: str = "#view-main") -> np.ndarray:  # type: ignore[no-untyped-def]
    return pixels(pg.locator(f"{selector} canvas").screenshot())


def wait_drawn(pg, selector: str = "#view-main") -> np.ndarray:  # type: ignore[no-untyped-def]
    """The view's pixels once its first frame is drawn (the page marks data-ready on the first frame)."""
    pg.wait_for_selector(f"{selector}[data-ready=true]")
    return view_pixels(pg, selector)


def test_upload_watch_view_colour_download(page, service: Service) -> None:
    """Upload a STEP through the page as an analyze job, see it reach succeeded in the live list, open it: the
    canvas shows the part; colouring by chordal error changes the pixels; mesh.stl downloads byte for byte."""
    step = corpus("voron_vhb_din_mount.step")
    page.goto(service.url + "/")
    page.select_option("#kind", "analyze")
    page.set_input_files("#file", str(step))
    page.click("#submit")
    row = page.locator("#jobs tbody tr", has_text=step.name).first
    row.wait_for()
    page.evaluate("""() => { window.shifts = 0; new PerformanceObserver((list) => { for (const e of list.getEntries())
        if (!e.hadRecentInput) window.shifts += e.value; }).observe({ type: 'layout-shift' }); }""")
    row.locator(".badge.succeeded").wait_for()  # no reload: the row changes by server-sent events
    assert page.evaluate("() => window.shifts") == 0, "the list moved while the job's row updated"
    page.screenshot(path=str(SHOTS / "jobs.png"))
    job_id = row.get_attribute("data-job")
    row.locator("td.name a").click()
    page.wait_for_url(f"**/jobs/{job_id}")
    plain = wait_drawn(page)
    assert drawn_fraction(plain) > 0.03, "the canvas shows no part"
    assert saturated_fraction(plain) < 0.01, "the plain view is grey"
    page.select_option("#colour", "chordal_error")
    page.wait_for_selector("#view-main[data-colour=chordal_error]")
    page.wait_for_function("() => window.amprep.viewers.at(-1).frames > 1")
    page.wait_for_timeout(300)
    coloured = view_pixels(page)
    assert saturated_fraction(coloured) > 0.02, "colouring by chordal error left the part grey"
    assert (np.abs(coloured.astype(int) - plain.astype(int)).max(axis=2) > 24).mean() > 0.02
    assert page.locator("#legend").is_visible() and "mm" in page.locator("#legend").inner_text()
    page.screenshot(path=str(SHOTS / "job.png"))
    with page.expect_download() as dl:
        page.click("button[data-artifact='mesh.stl']")
    got = Path(dl.value.path()).read_bytes()
    art = next(a for a in service.client().get(f"/v1/jobs/{job_id}").json()["artifacts"] if a["name"] == "mesh.stl")
    assert hashlib.sha256(got).hexdigest() == art["sha256"]
    with page.expect_download() as dl:
        page.click("#zip")
    import zipfile

    with zipfile.ZipFile(dl.value.path()) as zf:
        assert hashlib.sha256(zf.read("mesh.stl")).hexdigest() == art["sha256"]
        assert {"report.json", "chordal_error.f32", "face_id.i32"} <= set(zf.namelist())


def test_pick_shows_face(page, service: Service) -> None:
    """Clicking the middle of the part shows a triangle of a CAD face with its surface type and errors."""
    with service.client() as c:
        job = c.post("/v1/jobs", params={"wait": 120}, data={"kind": "analyze", "params": '{"bounding_box": false}'},
                     files={"file": ("din.step", corpus("voron_vhb_din_mount.step").read_bytes())}).json()
    page.goto(f"{service.url}/jobs/{job['id']}")
    wait_drawn(page)
    page.wait_for_selector("#colour:not([disabled])")
    box = page.locator("#view-main canvas").bounding_box()
    page.mouse.click(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
    page.wait_for_selector("#pick[data-triangle]")
    text = page.locator("#pick").inner_text()
    assert "CAD face" in text and any(t in text for t in ("plane", "cylinder", "cone")), text
    assert "chordal error" in text
    shaded = view_pixels(page)
    assert near_colour(shaded, HIGHLIGHT) > 0, "the picked triangle is not marked"
    page.focus("#view-main canvas")
    page.keyboard.press("w")  # the view's keys: w toggles wireframe, f fits
    page.wait_for_function("() => document.querySelector('#wireframe').checked")
    page.wait_for_timeout(300)
    wire = view_pixels(page)
    assert drawn_fraction(wire) < drawn_fraction(shaded), "wireframe drew as much as the shaded part"
    page.keyboard.press("w")
    page.wait_for_function("() => !document.querySelector('#wireframe').checked")


def test_open_stl_defect_highlighted(page, service: Service, tmp_path: Path) -> None:
    """An STL with holes: its boundary loops are listed; selecting one draws it in the highlight colour."""
    mesh = read_stl(corpus("voron_vhb_din_mount.stl"))
    keep = np.ones(mesh.n_triangles, bool)
    keep[[5, 400, 900]] = False
    holed = tmp_path / "holed.stl"
    write_stl(type(mesh).from_arrays(mesh.vertices, mesh.triangles[keep]), holed)
    job = analyzed(service, holed)
    page.goto(f"{service.url}/jobs/{job['id']}")
    wait_drawn(page)
    items = page.locator("#defects button")
    items.first.wait_for()
    assert items.count() >= 3 and all("Boundary loop" in items.nth(i).inner_text() for i in range(3))
    before = near_colour(view_pixels(page), HIGHLIGHT)
    items.nth(1).click()
    page.wait_for_selector("#view-main[data-selected='1']")
    page.wait_for_timeout(300)
    after = near_colour(view_pixels(page), HIGHLIGHT)
    assert items.nth(1).get_attribute("aria-pressed") == "true"
    assert after > before + 20, (before, after)
    page.screenshot(path=str(SHOTS / "defect.png"))


def test_refine_before_after(page, service: Service) -> None:
    """A refine job's page shows the mesh before and after side by side, both drawn."""
    with service.client() as c:
        job = c.post("/v1/jobs", params={"wait": 170}, data={"kind": "refine", "params": '{"method": "butterfly"}'},
                     files={"file": ("din.stl", corpus("voron_vhb_din_mount.stl").read_bytes())}).json()
    assert job["status"] == "succeeded", job
    page.goto(f"{service.url}/jobs/{job['id']}")
    after = wait_drawn(page)
    before = view_pixels(page, "#view-before")
    assert drawn_fraction(before) > 0.03 and drawn_fraction(after) > 0.03
    assert int(page.locator("#view-before").get_attribute("data-triangles")) * 4 == int(
        page.locator("#view-main").get_attribute("data-triangles"))


def test_convert_summary_on_the_job_page(page, service: Service, touching_step: Path) -> None:
    """A convert job's page shows its summary.json: the mesh checks (closed by index, not once joined by position for
    two boxes of one STEP face to face), the meshing's tolerance and worst chordal error, and the notes."""
    with service.client() as c:
        job = submit(c, touching_step, "convert", '{"tolerance": 0.05}', wait=170).json()
        assert job["status"] == "succeeded", job
        art = next(a for a in job["artifacts"] if a["name"] == "summary.json")
        summary = c.get(art["url"]).json()
    page.goto(f"{service.url}/jobs/{job['id']}")
    page.locator("#report h3", has_text="Meshing").wait_for()

    def cell(name: str) -> str:
        return page.locator("#report tr", has=page.locator("th", has_text=name)).first.locator("td").inner_text()

    assert cell("watertight") == "true" and cell("closed once joined by position") == "false"
    assert summary["mesh"]["closed_by_position"] is False and summary["mesh"]["watertight"] is True
    assert float(cell("tolerance (mm)")) == 0.05
    assert float(cell("max chordal error (mm)")) <= 0.05 and cell("within tolerance") == "true"
    mean = page.locator("#report tr", has=page.locator("th", has_text="angle regularity")).first.locator("td").first
    assert float(mean.inner_text()) == pytest.approx(summary["regularity"]["angle"]["mean"], abs=5e-4)
    notes = page.locator("#report li").all_inner_texts()
    assert any("float32 position" in n for n in notes) and notes == summary["notes"]


def test_brep_gap_on_the_job_page(page, service: Service, tmp_path: Path) -> None:
    """A part whose round misses its planes by 30 µm, converted at 10 µm: the page says it is not within tolerance,
    by how much its faces miss their edges, and why (the note)."""
    from OCP.BRepTools import BRepTools

    path = tmp_path / "gapped.brep"
    BRepTools.Write_s(filleted_box(0.03), str(path))
    with service.client() as c:
        job = submit(c, path, "convert", '{"tolerance": 0.01}', wait=170).json()
        assert job["status"] == "succeeded", job
    page.goto(f"{service.url}/jobs/{job['id']}")
    page.locator("#report h3", has_text="Meshing").wait_for()
    row = page.locator("#report tr", has=page.locator("th", has_text="faces miss their shared edges")).first
    assert float(row.locator("td").inner_text()) == pytest.approx(0.015, rel=0.2)
    moved = page.locator("#report tr", has=page.locator("th", has_text="edge nodes moved to join their faces")).first
    assert float(moved.locator("td").inner_text()) == pytest.approx(0.03, rel=0.2)  # the round's nodes, to the planes
    within = page.locator("#report tr", has=page.locator("th", has_text="within tolerance")).first
    assert within.locator("td").inner_text() == "false"
    assert any("miss their shared edges" in n for n in page.locator("#report li").all_inner_texts())


def test_form_from_definitions(page, service: Service) -> None:
    """The form's fields are the kind's parameters with their defaults and bounds; a value out of bounds is refused
    in the page, before any upload."""
    kinds = {k["name"]: k for k in service.client().get("/v1/kinds").json()}
    page.goto(service.url + "/")
    page.select_option("#kind", "convert")
    for p in kinds["convert"]["params"]:
        field = page.locator(f"#p-convert-{p['name']}")
        assert field.count() == 1, p["name"]
        if p["type"] in ("float", "int") and p["default"] is not None:
            assert float(field.get_attribute("placeholder")) == p["default"]
    page.click("#submit-form summary")
    page.fill("#p-convert-tolerance", "1000")
    page.set_input_files("#file", str(corpus("voron_vhb_din_mount.stl")))
    n = len(service.client().get("/v1/jobs").json()["jobs"])
    page.click("#submit")
    assert "≤ 100" in page.locator("#p-convert-tolerance-error").inner_text()
    assert "tolerance" in page.locator("#submit-message").inner_text()
    assert len(service.client().get("/v1/jobs").json()["jobs"]) == n


def test_cancel_filter_and_delete_from_list(page, service: Service) -> None:
    """Cancel a running and a queued job from their rows, filter the list by status and kind, delete an ended job:
    each row changes or goes without a reload."""
    with service.client() as c:
        busy = submit(c, corpus("nist_ctc02_ap242.stp"), params='{"tolerance": 0.01, "reuse": false}').json()
        queued = submit(c, corpus("voron_vhb_din_mount.step"), params='{"reuse": false, "tolerance": 0.09}').json()
        wait_status(c, busy["id"], ("running",))
    page.goto(service.url + "/")
    for job in (queued, busy):
        row = page.locator(f"#jobs tr[data-job='{job['id']}']")
        row.get_by_role("button", name="Cancel").click()
        row.locator(".badge.cancelled").wait_for()
        assert "cancelled" in row.locator(".stage").inner_text()
    page.select_option("#filter-status", "cancelled")
    page.locator(f"#jobs tr[data-job='{busy['id']}']").wait_for()
    statuses = page.locator("#jobs tbody tr").evaluate_all("rs => rs.map(r => r.dataset.status)")
    assert statuses and all(s == "cancelled" for s in statuses), statuses
    page.select_option("#filter-kind", "analyze")
    page.locator(f"#jobs tr[data-job='{busy['id']}']").wait_for(state="detached")
    page.select_option("#filter-kind", "")
    page.select_option("#filter-status", "")
    row = page.locator(f"#jobs tr[data-job='{busy['id']}']")
    row.get_by_role("button", name="Delete").click()
    row.wait_for(state="detached")
    assert service.client().get(f"/v1/jobs/{busy['id']}").status_code == 404


#: counts, in the page, the job lists whose JSON was read (load() renders in the same microtask checkpoint)
COUNT_LISTS = """
window.__lists = 0;
const fetched = window.fetch;
window.fetch = async (...a) => {
  const r = await fetched(...a);
  if (String(a[0]).includes('/v1/jobs?')) {
    const read = r.json.bind(r);
    r.json = async () => { const v = await read(); window.__lists += 1; return v; };
  }
  return r;
};
"""


def test_a_list_sent_before_a_delete_does_not_bring_the_row_back(page, service: Service) -> None:
    """A job list that left the server before a delete and arrives after it (held here by the browser's router) must
    not show the deleted job again: the delete is final on the page as on the server."""
    with service.client() as c:
        job = submit(c, corpus("voron_vhb_din_mount.step"), params='{"reuse": false}').json()
        assert c.delete(f"/v1/jobs/{job['id']}").json()["status"] == "cancelled"
    page.add_init_script(COUNT_LISTS)
    page.goto(service.url + "/")
    row = page.locator(f"#jobs tr[data-job='{job['id']}']")
    row.get_by_role("button", name="Delete").wait_for()
    held: list = []  # type: ignore[type-arg]
    page.route("**/v1/jobs?*", lambda r: held.append((r, r.fetch())))
    page.select_option("#filter-status", "cancelled")  # a list is asked for, sent and held
    for _ in range(LONG // 100):
        if held:
            break
        page.wait_for_timeout(100)
    assert len(held) == 1, "the page did not ask for the list"
    assert job["id"] in held[0][1].text()
    row.get_by_role("button", name="Delete").click()
    row.wait_for(state="detached")
    assert service.client().get(f"/v1/jobs/{job['id']}").status_code == 404
    page.unroute("**/v1/jobs?*")
    seen = page.evaluate("window.__lists")
    held[0][0].fulfill(response=held[0][1])
    page.wait_for_function("n => window.__lists > n", arg=seen)
    assert row.count() == 0, "the deleted job came back with a list sent before its delete"


def test_api_docs_served_locally(page, service: Service) -> None:
    """/docs and /redoc draw the API from this server's own files."""
    page.goto(service.url + "/docs")
    page.wait_for_selector(".opblock")
    assert page.locator(".opblock").count() >= 8
    page.goto(service.url + "/redoc")
    page.locator("h2", has_text="Submit a file for convert").first.wait_for()


def test_api_key_in_session(browser, service: Service, keyed_api: str) -> None:
    """On a keyed server the page asks for the key, keeps it for the session and lists that key's jobs only."""
    import httpx

    with httpx.Client(base_url=keyed_api, headers={"Authorization": f"Bearer {KEY_A}"}, timeout=120) as c:
        mine = submit(c, corpus("voron_vhb_din_mount.stl"), "convert").json()
    context = browser.new_context()
    pg = context.new_page()
    outside: list[str] = []
    guard_host(pg, keyed_api, outside)
    pg.set_default_timeout(LONG)
    pg.goto(keyed_api + "/")
    pg.wait_for_selector("#api-key")
    pg.fill("#api-key", KEY_A)
    pg.click(".keybar button")
    pg.locator(f"#jobs tr[data-job='{mine['id']}']").wait_for()
    assert pg.evaluate("() => sessionStorage.getItem('amprep.apiKey')") == KEY_A
    pg.goto(f"{keyed_api}/jobs/{mine['id']}")
    pg.wait_for_selector("#view-main[data-ready=true]")
    context.close()
    assert not outside


def test_owner_events_stream(service: Service, keyed_api: str) -> None:
    """GET /v1/events carries every change of the caller's jobs (and their deletion), and none of another key's."""
    import json
    import threading

    import httpx

    from .conftest import KEY_B

    seen: list[tuple[str, dict]] = []
    opened = threading.Event()

    def listen() -> None:
        with httpx.Client(base_url=keyed_api, headers={"Authorization": f"Bearer {KEY_A}"}, timeout=None) as c:
            with c.stream("GET", "/v1/events") as r:
                assert r.status_code == 200 and r.headers["content-type"].startswith("text/event-stream")
                opened.set()
                event = None
                for line in r.iter_lines():
                    if line.startswith("event:"):
                        event = line[6:].strip()
                    elif line.startswith("data:"):
                        seen.append((event or "", json.loads(line[5:])))
                        if event == "deleted":
                            return

    t = threading.Thread(target=listen, daemon=True)
    t.start()
    assert opened.wait(60)
    with httpx.Client(base_url=keyed_api, timeout=120) as c:
        other = submit(c, corpus("voron_vhb_din_mount.stl"), "convert", headers={"Authorization": f"Bearer {KEY_B}"},
                       wait=60).json()
        c.headers["Authorization"] = f"Bearer {KEY_A}"
        mine = submit(c, corpus("voron_vhb_din_mount.stl"), "convert", '{"tolerance": 0.07}', wait=60).json()
        assert mine["status"] == "succeeded"
        assert c.delete(f"/v1/jobs/{mine['id']}").status_code == 204
    t.join(60)
    assert not t.is_alive(), seen
    ids = {d["id"] for _, d in seen}
    assert ids == {mine["id"]}, "another key's job was streamed" if other["id"] in ids else seen
    statuses = [d["status"] for e, d in seen if e == "job"]
    assert statuses[0] == "queued" and "succeeded" in statuses and seen[-1][0] == "deleted"
    assert httpx.get(keyed_api + "/v1/events", timeout=30).status_code == 401


def test_moving_copy_while_turning(page, service: Service, tmp_path: Path) -> None:
    """A mesh too slow to turn in full is drawn from a lighter copy while it moves (forced here with a frame budget
    of 1 µs): the copy is built, shows the part, carries each source triangle's colour, and the full mesh is back
    once the view settles."""
    from bench.dashboard import torus

    stl = tmp_path / "torus.stl"
    write_stl(torus(200, 60), stl)  # 24,000 triangles
    job = analyzed(service, stl)
    page.goto(f"{service.url}/jobs/{job['id']}?frame_ms=0.001")
    wait_drawn(page)
    page.wait_for_function("() => window.amprep.viewers.at(-1).lod")
    n = page.evaluate("() => window.amprep.viewers.at(-1).lodOrig.length")
    assert 1000 < n < 12_000, n
    page.select_option("#colour", "cusp_height")
    page.wait_for_selector("#view-main[data-colour=cusp_height]")
    same = page.evaluate("""() => { const v = window.amprep.viewers.at(-1);
        const full = v.mesh.geometry.getAttribute('color').array, lod = v.lod.geometry.getAttribute('color').array;
        let ok = 0; for (let j = 0; j < v.lodOrig.length; j += 97) { const t = v.lodOrig[j];
          ok += [0, 1, 2, 3, 4, 5, 6, 7, 8].every((k) => lod[9 * j + k] === full[9 * t + k]) ? 1 : 0; }
        return [ok, Math.ceil(v.lodOrig.length / 97)]; }""")
    assert same[0] == same[1] and same[1] > 10
    page.evaluate("() => { const v = window.amprep.viewers.at(-1); v.spinning = true; v.moving = true; v.draw(); }")
    assert page.evaluate("() => { const v = window.amprep.viewers.at(-1); return v.lod.visible && !v.mesh.visible; }")
    assert drawn_fraction(view_pixels(page)) > 0.03, "the moving copy shows nothing"
    page.evaluate("() => { const v = window.amprep.viewers.at(-1); v.spinning = false; v.moved(); }")
    page.wait_for_function("() => { const v = window.amprep.viewers.at(-1); return v.mesh.visible && !v.lod.visible; }")


CONTRAST = """() => {
  const rgb = (s) => (s.match(/[\\d.]+/g) || []).map(Number);
  const lum = ([r, g, b]) => { const f = (c) => { c /= 255; return c <= 0.03928 ? c / 12.92 : ((c + 0.055) / 1.055) ** 2.4; };
    return 0.2126 * f(r) + 0.7152 * f(g) + 0.0722 * f(b); };
  const bg = (e) => { for (; e; e = e.parentElement) { const c = rgb(getComputedStyle(e).backgroundColor);
    if (c.length === 3 || c[3] > 0.5) return c.slice(0, 3); } return [255, 255, 255]; };
  const bad = [];
  const walker = document.createTreeWalker(document.body, NodeFilter.SHOW_TEXT);
  for (let n = walker.nextNode(); n; n = walker.nextNode()) {
    const e = n.parentElement;
    if (!n.textContent.trim() || !e || !e.getClientRects().length) continue;
    const st = getComputedStyle(e);
    if (st.visibility === 'hidden' || e.closest('.sr-only,[hidden],canvas')) continue;
    const a = lum(rgb(st.color).slice(0, 3)), b = lum(bg(e));
    const ratio = (Math.max(a, b) + 0.05) / (Math.min(a, b) + 0.05);
    const large = parseFloat(st.fontSize) >= 24 || (parseFloat(st.fontSize) >= 18.66 && Number(st.fontWeight) >= 700);
    if (ratio < (large ? 3 : 4.5)) bad.push(`${n.textContent.trim().slice(0, 30)}: ${ratio.toFixed(2)}`);
  }
  return bad;
}"""


@pytest.mark.parametrize("viewport", [(1280, 800), (768, 1024)], ids=["laptop", "tablet"])
def test_readable_and_keyboard_reachable(browser, service: Service, viewport: tuple[int, int]) -> None:
    """Both pages fit a laptop and a tablet (no sideways scrolling of the page), all visible text passes WCAG AA
    contrast, and the form is reachable by Tab alone."""
    with service.client() as c:
        job = submit(c, corpus("voron_vhb_din_mount.step"), "analyze", '{"bounding_box": false}', wait=120).json()
    context = browser.new_context(viewport={"width": viewport[0], "height": viewport[1]})
    pg = context.new_page()
    outside: list[str] = []
    guard_host(pg, service.url, outside)
    pg.set_default_timeout(LONG)
    for url in (service.url + "/", f"{service.url}/jobs/{job['id']}"):
        pg.goto(url)
        pg.wait_for_selector("#jobs tbody tr" if url.endswith("/") else "#view-main[data-ready=true]")
        assert pg.evaluate("() => document.documentElement.scrollWidth <= window.innerWidth + 1"), url
        assert pg.evaluate(CONTRAST) == [], url
    pg.goto(service.url + "/")
    pg.wait_for_selector("#jobs tbody tr")
    reached = set()
    for _ in range(40):
        pg.keyboard.press("Tab")
        reached.add(pg.evaluate("() => document.activeElement.id || document.activeElement.tagName"))
    assert {"file", "kind", "submit", "filter-status", "filter-kind"} <= reached, reached
    context.close()
    assert not outside
