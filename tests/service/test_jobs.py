"""Jobs over real HTTP: create (wait, STL body), read, list, artifacts, errors as problem+json."""

from __future__ import annotations

import hashlib
import json
import time

import numpy as np
import pytest

from amprep.geometry.core.checks import check_mesh
from amprep.geometry.io.stl import read_stl
from tests.conftest import corpus
from tests.service.conftest import submit, wait_status

PART = "voron_vhb_din_mount.step"


def test_one_curl_line_returns_the_stl(service, tmp_path):
    with service.client() as c:
        r = submit(c, corpus(PART), wait=120, headers={"Accept": "model/stl"})
    assert r.status_code == 200 and r.headers["content-type"] == "model/stl"
    out = tmp_path / "part.stl"
    out.write_bytes(r.content)
    mesh = read_stl(out)
    checks = check_mesh(mesh)
    assert checks.closed and checks.triangles > 500 and checks.volume > 0
    assert r.content[:6] == b"amprep"  # provenance in the header


def test_job_record_artifacts_and_provenance(service):
    with service.client() as c:
        r = submit(c, corpus(PART), params=json.dumps({"tolerance": 0.05, "reuse": False}))
        assert r.status_code == 202, r.text
        job = r.json()
        assert job["status"] in ("queued", "running") and r.headers["location"] == f"/v1/jobs/{job['id']}"
        job = wait_status(c, job["id"], ("succeeded", "failed"))
        assert job["status"] == "succeeded", job["error"]
        assert job["progress"] == 1.0 and job["stage"] == "done"
        assert job["params"]["tolerance"] == 0.05 and job["params"]["angular"] == 0.5  # all params, defaults filled
        prov = job["provenance"]
        assert {"amprep", "occt", "cadquery"} <= set(prov) and prov["params"]["tolerance"] == 0.05
        assert prov["mesh_params"]["tolerance"] == 0.05
        assert job["created_at"] <= job["started_at"] <= job["finished_at"]
        assert job["result"]["meshing"]["max_chordal_error"] <= 0.05
        names = {a["name"]: a for a in job["artifacts"]}
        assert set(names) == {"part.stl", "summary.json"}
        for a in job["artifacts"]:
            body = c.get(a["url"])
            assert body.status_code == 200 and body.headers["content-type"].startswith(a["media_type"])
            assert len(body.content) == a["size"] and hashlib.sha256(body.content).hexdigest() == a["sha256"]
        assert c.get(f"/v1/jobs/{job['id']}/artifacts/nothing.stl").json()["code"] == "not_found"
        assert c.get(f"/v1/jobs/{job['id']}/artifacts/..%2F..%2Finput%2Fmodel.step").status_code == 404


def test_3mf_and_ascii_outputs(service):
    with service.client() as c:
        job = submit(c, corpus(PART), params='{"format": "3mf"}', wait=120).json()
        assert job["status"] == "succeeded" and job["artifacts"][0]["media_type"] == "model/3mf"
        assert c.get(job["artifacts"][0]["url"]).content[:2] == b"PK"
        job = submit(c, corpus(PART), params='{"ascii": true}', wait=120).json()
        assert c.get(job["artifacts"][0]["url"]).content.startswith(b"solid")


def test_analyze_job_writes_a_report(service):
    with service.client() as c:
        job = submit(c, corpus(PART), kind="analyze", params='{"layer": 0.1}', wait=120).json()
        assert job["status"] == "succeeded", job["error"]
        report = c.get(job["artifacts"][0]["url"]).json()
        names = {a["name"]: a for a in job["artifacts"]}
        assert {"report.json", "mesh.stl", "chordal_error.f32", "cusp_height.f32", "cusp_per_slice.png",
                "chordal_per_face.png", "regularity.png"} <= set(names)
        assert names["chordal_error.f32"]["size"] == 4 * report["mesh"]["triangles"]
        assert names["regularity.png"]["media_type"] == "image/png"
    assert report["schema"] == "amprep.report/1" and report["mesh"]["watertight"] is True
    assert report["issues"] == [] and report["cusp_height"]["layer"] == 0.1 and report["faces"]
    assert job["result"]["chordal_error"]["max"] == report["chordal_error"]["max"]


def test_analyze_an_open_stl_lists_its_defects(service):
    with service.client() as c:
        job = submit(c, corpus("voron_rear_skirt_nonmanifold.stl"), kind="analyze", wait=120).json()
        report = c.get(job["artifacts"][0]["url"]).json()
    codes = {i["code"]: i for i in report["issues"]}
    assert report["mesh"]["watertight"] is False
    assert "nonmanifold_edges" in codes or "boundary_edges" in codes
    assert all(i["count"] > 0 and i["severity"] in ("error", "warning", "info") for i in report["issues"])


def test_refine_job_returns_the_users_stl_refined_in_its_own_frame(service, tmp_path):
    """The thesis's setting over HTTP: STEP + the author's STL (rotated into print orientation) → refined STL in
    the STL's frame, closed, with the report and the error-vs-size plot; on the heavy queue."""
    stl = corpus("voron_vhb_din_mount.stl")
    with service.client() as c:
        job = submit(c, corpus(PART), kind="refine", params='{"method": "sma", "max_chordal": 0.001}', wait=240,
                     stl=stl).json()
        assert job["status"] == "succeeded", job["error"]
        names = {a["name"]: a for a in job["artifacts"]}
        assert {"refined.stl", "report.json", "chordal_error.f32", "error_vs_size.png"} <= set(names)
        out = tmp_path / "refined.stl"
        out.write_bytes(c.get(names["refined.stl"]["url"]).content)
        report = c.get(names["report.json"]["url"]).json()
        assert submit(c, corpus(PART), kind="refine", params='{"method": "magic"}').json()["code"] == "invalid_request"
        assert submit(c, corpus(PART), kind="refine", params='{"ratios": "3:4"}').json()["code"] == "invalid_request"
    refined, original = read_stl(out), read_stl(stl)
    assert check_mesh(refined).closed and refined.n_triangles > original.n_triangles
    assert np.allclose(refined.bbox()[0], original.bbox()[0], atol=0.02)  # the user's frame, not the CAD's
    assert np.allclose(refined.bbox()[1], original.bbox()[1], atol=0.02)
    assert report["refined_faces"] and all(f["chordal_error_after"]["mean"] < f["chordal_error_before"]["mean"]
                                           for f in report["refined_faces"])
    assert job["result"]["mesh"]["watertight"] is True and report["alignment"]["axis_permutation"]


def test_refine_job_failure_has_a_code(service):
    """A refine job that fails in the worker ends with the library's code; an input that does not fit the method
    is refused at submit."""
    with service.client() as c:
        # 6 levels of butterfly: 3,476 × 4⁶ = 14 M triangles, over the default 10 M
        job = submit(c, corpus("featuretype_inch.stl"), kind="refine", params='{"method": "butterfly", "levels": 6}',
                     wait=120).json()
        assert job["status"] == "failed" and job["error"]["code"] == "output_too_large"
        r = submit(c, corpus("featuretype_inch.stl"), kind="refine")  # sma needs the CAD
        assert r.status_code == 422 and r.json()["code"] == "invalid_parameter" and "CAD" in r.json()["detail"]


@pytest.mark.parametrize(("kind", "params", "code"), [
    ("convert", '{"tolerance": 0.1, "bogus": 1}', "invalid_request"),
    ("convert", '{"tolerance": -1}', "invalid_request"),
    ("convert", "not json", "invalid_request"),
    ("convert", "[1, 2]", "invalid_request"),
    ("analyze", '{"build_dir": [0, 0, 0]}', "invalid_request"),
    ("explode", "{}", "invalid_request"),
])
def test_invalid_params_are_422_problems(service, kind, params, code):
    with service.client() as c:
        r = submit(c, corpus(PART), kind=kind, params=params)
    assert r.status_code == 422 and r.headers["content-type"] == "application/problem+json"
    body = r.json()
    assert body["code"] == code and body["status"] == 422 and body["detail"]


def test_bad_files_are_422_with_the_library_codes(service, tmp_path):
    empty, text = tmp_path / "empty.step", tmp_path / "notes.step"
    empty.write_bytes(b"")
    text.write_bytes(b"just some notes, not CAD\n" * 20)
    with service.client() as c:
        assert submit(c, empty).json()["code"] == "empty_model"
        assert submit(c, text).json()["code"] == "unsupported_format"
        assert submit(c, corpus(PART), stl=text).json()["code"] == "unsupported_format"
        r = submit(c, corpus("voron_vhb_din_mount.stl"), stl=corpus("voron_vhb_din_mount.stl"))
        assert r.status_code == 422 and r.json()["code"] == "invalid_request"
        assert c.post("/v1/jobs", data={"kind": "convert"}).json()["code"] == "invalid_request"  # no file
        assert c.get("/v1/jobs/doesnotexist").json()["code"] == "not_found"
        assert c.get("/v1/jobs/../../etc/passwd").status_code == 404


def test_unreadable_cad_fails_in_the_worker_with_its_code(service, tmp_path):
    bad = tmp_path / "broken.step"
    bad.write_bytes(b"ISO-10303-21;\nHEADER;\nthis is not a step file at all\n" + b"x" * 5000)
    with service.client() as c:
        job = submit(c, bad, wait=60).json()
        assert job["status"] == "failed" and job["error"]["code"] in ("unreadable_cad", "empty_model")
        r = submit(c, bad, wait=60, headers={"Accept": "model/stl"})
        assert r.status_code == 422 and r.json()["code"] == job["error"]["code"] and r.json()["job_id"]


def test_stl_passthrough_and_stl_part(service):
    with service.client() as c:
        job = submit(c, corpus("voron_vhb_din_mount.stl"), wait=60).json()
        assert job["status"] == "succeeded" and job["input"]["file"]["format"] == "stl"
        job = submit(c, corpus(PART), kind="analyze", wait=60, stl=corpus("voron_vhb_din_mount.stl")).json()
        assert job["status"] == "succeeded" and job["input"]["stl"]["format"] == "stl"


def test_list_filters_and_cursor_pagination(service):
    with service.client() as c:
        ids = [submit(c, corpus(PART), kind="analyze", wait=60).json()["id"] for _ in range(3)]
        seen, cursor = [], None
        while True:
            page = c.get("/v1/jobs", params={"limit": 2, "kind": "analyze"} | ({"cursor": cursor} if cursor else {}))
            assert page.status_code == 200
            body = page.json()
            seen += [j["id"] for j in body["jobs"]]
            assert all(j["kind"] == "analyze" for j in body["jobs"])
            cursor = body["next_cursor"]
            if cursor is None:
                break
        assert len(seen) == len(set(seen)) and set(ids) <= set(seen)
        assert seen == sorted(seen, reverse=True)  # newest first (ids are time-ordered)
        failed = c.get("/v1/jobs", params={"status": "failed"}).json()["jobs"]
        assert all(j["status"] == "failed" for j in failed)
        assert c.get("/v1/jobs", params={"cursor": "garbage!"}).json()["code"] == "invalid_request"
        assert c.get("/v1/jobs", params={"status": "sleeping"}).status_code == 422


def test_delete_a_finished_job_removes_it_and_its_files(service):
    with service.client() as c:
        job = submit(c, corpus(PART), wait=60, params='{"reuse": false}').json()
        folder = service.data / "jobs" / job["id"]
        assert folder.exists()
        assert c.delete(f"/v1/jobs/{job['id']}").status_code == 204
        assert c.get(f"/v1/jobs/{job['id']}").status_code == 404
        assert not folder.exists()
        assert c.delete(f"/v1/jobs/{job['id']}").status_code == 404


def test_a_task_marked_sent_after_its_job_went_leaves_no_record(service):
    """The API marks a job's task sent after queueing it; a job deleted in between (its id is on the event stream
    at once) must stay deleted, not come back as a record without fields."""
    with service.client() as c:
        job = submit(c, corpus(PART), params='{"reuse": false}').json()
        c.delete(f"/v1/jobs/{job['id']}")
        if c.get(f"/v1/jobs/{job['id']}").status_code == 200:
            assert c.delete(f"/v1/jobs/{job['id']}").status_code == 204
        service.store.mark_sent(job["id"])
        assert not service.store.redis.exists(service.store.key(job["id"]))
        assert c.get(f"/v1/jobs/{job['id']}").status_code == 404
        assert job["id"] not in [j["id"] for j in c.get("/v1/jobs", params={"limit": 200}).json()["jobs"]]


def test_the_sweep_removes_left_over_files_and_nothing_else(service):
    """A job directory with no record (its job deleted while a worker still wrote there, or a crash before the record
    was made) and a temporary archive, both unchanged for over ORPHAN_GRACE, are removed by the worker's sweep; a
    directory that has a record, and fresh left-overs (an upload in progress), are kept."""
    import os

    from amprep.store import ORPHAN_GRACE, P

    st = service.store
    with service.client() as c:
        kept = submit(c, corpus(PART), wait=60, params='{"reuse": false}').json()
    old = time.time() - 2 * ORPHAN_GRACE
    orphan, fresh, tmp = st.job_dir("0rphan0000000001"), st.job_dir("0rphan0000000002"), st.tmp
    for d in (orphan / "out", fresh / "input", tmp):
        d.mkdir(parents=True, exist_ok=True)
    (orphan / "out" / "mesh.stl").write_bytes(b"x" * 84)
    (tmp / "broken.zip").write_bytes(b"PK")
    for path in (orphan, tmp / "broken.zip", st.job_dir(kept["id"])):
        os.utime(path, (old, old))
    st.redis.delete(f"{P}orphan-lock", f"{P}sweep-lock")
    # the worker sweeps after each job it finishes, with the same function: on a busy machine its sweep after `kept`
    # can start after the locks are gone and take the left-overs (and the lock) first, so the end state is asserted,
    # not this call's count
    st.sweep()
    assert not orphan.exists() and not (tmp / "broken.zip").exists()
    assert fresh.exists() and st.job_dir(kept["id"]).exists()
    with service.client() as c:
        assert c.get(kept["artifacts"][0]["url"]).status_code == 200
    st.discard_files("0rphan0000000002")


def test_identical_input_reuses_the_result_and_says_so(service):
    with service.client() as c:
        first = submit(c, corpus("featuretype_inch_ap214.step"), params='{"tolerance": 0.07}', wait=120).json()
        again = submit(c, corpus("featuretype_inch_ap214.step"), params='{"tolerance": 0.07}', wait=120).json()
        assert again["id"] != first["id"] and again["reused_from"] == first["id"] and again["status"] == "succeeded"
        assert [a["sha256"] for a in again["artifacts"]] == [a["sha256"] for a in first["artifacts"]]
        assert c.get(again["artifacts"][0]["url"]).status_code == 200
        fresh = submit(c, corpus("featuretype_inch_ap214.step"), params='{"tolerance": 0.07, "reuse": false}',
                       wait=120).json()
        assert fresh["reused_from"] is None and fresh["attempts"] == 1
        other = submit(c, corpus("featuretype_inch_ap214.step"), params='{"tolerance": 0.08}', wait=120).json()
        assert other["reused_from"] is None


def test_idempotency_key_returns_the_same_job(service):
    with service.client() as c:
        h = {"Idempotency-Key": "order-4711"}
        a = submit(c, corpus(PART), params='{"reuse": false}', headers=h).json()
        b = submit(c, corpus(PART), params='{"reuse": false}', headers=h).json()
        assert a["id"] == b["id"] and b["idempotency_key"] == "order-4711"
        r = submit(c, corpus(PART), params='{"reuse": false, "tolerance": 0.2}', headers=h)
        assert r.status_code == 409 and r.json()["code"] == "conflict"
        n = len([j for j in c.get("/v1/jobs", params={"limit": 200}).json()["jobs"] if j["id"] == a["id"]])
        assert n == 1


def test_health_ready_and_metrics(service):
    with service.client() as c:
        assert c.get("/healthz").json() == {"status": "ok"}
        ready = c.get("/readyz").json()
        assert ready["status"] == "ready" and any(w.startswith("test@") for w in ready["workers"])
        submit(c, corpus(PART), wait=60)
        text = c.get("/metrics").text
    assert 'amprep_jobs_total{kind="convert",status="succeeded"}' in text
    assert 'amprep_job_duration_seconds_count{kind="convert"}' in text
    assert 'amprep_queue_depth{queue="quick"}' in text


def test_stl_body_mesh_matches_the_job_result(service, tmp_path):
    with service.client() as c:
        r = submit(c, corpus("featuretype_inch_ap214.step"), params='{"tolerance": 0.05}', wait=120,
                   headers={"Accept": "model/stl"})
        job = c.get(f"/v1/jobs/{r.headers['x-amprep-job']}").json()
    n = int(np.frombuffer(r.content[80:84], "<u4")[0])
    assert n == job["result"]["mesh"]["triangles"] and len(r.content) == 84 + 50 * n
