"""Costs bounded before they are paid, through the real service: a tiny file whose mesh would be huge is refused
with output_too_large before meshing (the server's AMPREP_MAX_TRIANGLES lowers a job's own max_triangles), a small
file of thousands of placed copies of one solid is meshed once and placed, and a job past its memory limit ends with
memory_limit while its worker lives on."""

from __future__ import annotations

import json
from pathlib import Path

from OCP.BRepTools import BRepTools

from tests.conftest import corpus
from tests.geometry.test_instances import _boxes
from tests.service.conftest import MAX_TRIANGLES, running_service, submit, wait_status


def _torus_step(path: Path) -> Path:
    import cadquery as cq

    cq.exporters.export(cq.Workplane().add(cq.Solid.makeTorus(20, 5)), str(path))
    return path


def test_a_small_file_that_would_mesh_huge_is_refused_before_meshing(service, tmp_path):
    step = _torus_step(tmp_path / "torus.step")
    assert step.stat().st_size < 20_000
    with service.client() as c:
        # 10,000,000 by default, lowered to the server's cap: ~2.7 M triangles expected at 0.0001 mm
        job = submit(c, step, params=json.dumps({"tolerance": 1e-4, "reuse": False})).json()
        job = wait_status(c, job["id"], ("succeeded", "failed"), 300)
        assert job["status"] == "failed" and job["error"]["code"] == "output_too_large", job.get("error")
        assert f"{MAX_TRIANGLES:,}" in job["error"]["message"]
        # a job's own lower limit applies too
        job = submit(c, step, params=json.dumps({"tolerance": 0.01, "max_triangles": 1000, "reuse": False})).json()
        job = wait_status(c, job["id"], ("succeeded", "failed"), 300)
        assert job["status"] == "failed" and job["error"]["code"] == "output_too_large"


def test_thousands_of_placed_boxes_are_one_box_meshed_and_placed(service, tmp_path):
    brep = tmp_path / "boxes.brep"
    BRepTools.Write_s(_boxes(14), str(brep))  # 16,384 boxes in 5 KB
    with service.client() as c:
        job = submit(c, brep, params='{"reuse": false}').json()
        job = wait_status(c, job["id"], ("succeeded", "failed"), 600)
        assert job["status"] == "succeeded", job.get("error")
        mesh = job["result"]["mesh"]
        assert mesh["watertight"] and mesh["triangles"] == 12 * 16384 and mesh["shells"] == 16384
        assert abs(mesh["volume"] - 16384) < 1e-6


def test_a_job_past_its_memory_limit_fails_with_memory_limit_and_the_worker_lives_on(tmp_path):
    data, logs = tmp_path / "data", tmp_path / "logs"
    data.mkdir()
    logs.mkdir()
    with running_service(data, logs, AMPREP_MEMORY_LIMIT_MB="150") as svc, svc.client() as c:
        big = submit(c, corpus("nist_ctc02_ap242.stp"), params='{"tolerance": 0.005}').json()
        big = wait_status(c, big["id"], ("succeeded", "failed"), 600)
        assert big["status"] == "failed" and big["error"]["code"] == "memory_limit", big.get("error")
        assert big["attempts"] == 1
        small = submit(c, corpus("cq_cube_cylinder_colors.step")).json()
        small = wait_status(c, small["id"], ("succeeded", "failed"), 300)
        assert small["status"] == "succeeded", small.get("error")
        assert small["worker"] == big["worker"]
