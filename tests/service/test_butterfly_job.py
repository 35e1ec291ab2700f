"""STL-only refinement over HTTP: a refine job with only an STL uploaded and method butterfly."""

from __future__ import annotations

from amprep.geometry.io.stl import read_stl
from tests.conftest import corpus
from tests.service.conftest import submit


def test_an_stl_alone_is_refined_by_butterfly(service, tmp_path):
    src = corpus("voron_hotend_mount_dragon.stl")
    with service.client() as c:
        job = submit(c, src, kind="refine", params='{"method": "butterfly", "levels": 1, "compare": false}',
                     wait=240).json()
        assert job["status"] == "succeeded", job.get("error")
        assert job["result"]["method"] == "butterfly" and job["result"]["mesh"]["watertight"]
        out = tmp_path / "refined.stl"
        out.write_bytes(c.get(f"/v1/jobs/{job['id']}/artifacts/refined.stl").content)
        assert read_stl(out).n_triangles == 4 * read_stl(src).n_triangles
        # the other methods need the CAD, butterfly refuses it: 422 at submit, nothing stored
        r = submit(c, src, kind="refine", params='{"method": "sma"}')
        assert r.status_code == 422 and r.json()["code"] == "invalid_parameter"
        r = submit(c, corpus("voron_hotend_mount_dragon.step"), kind="refine", params='{"method": "butterfly"}')
        assert r.status_code == 422 and "STL alone" in r.json()["detail"]


def test_an_stl_remeshed_to_an_edge_length_over_http(service):
    with service.client() as c:
        job = submit(c, corpus("voron_vhb_din_mount.stl"), kind="refine",
                     params='{"method": "butterfly", "max_edge": 2.0}', wait=240).json()
        assert job["status"] == "succeeded", job.get("error")
        b = job["result"]["butterfly"]
        assert b["max_edge"] == 2.0 and b["longest_edge"] <= 2.0 and b["limit_depth"] >= 1
        assert job["result"]["mesh"]["watertight"]
        r = submit(c, corpus("voron_vhb_din_mount.stl"), kind="refine", params='{"method": "butterfly", "max_edge": 0}')
        assert r.status_code == 422
