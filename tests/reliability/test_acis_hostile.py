"""Hostile ACIS: truncated data, dangling and cyclic references, counts the data cannot hold, nesting with no
end, non-finite numbers and binary garbage are unreadable_cad, read in bounded work (every chain walked at most
once, every count checked against the bytes present before anything is allocated); over HTTP such a file fails its
job and the worker takes the next one."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.cad.read import read_cad
from tests.conftest import corpus
from tests.service.conftest import submit, wait_status

SOLID = "sat/oda_3dsolids_A5_cyl_v700.sat"
SHEET_SPLINE = "sat/acad_2004_Surface_LOFTED_v20800.sat"


def _text(name: str = SOLID) -> str:
    return corpus(name).read_text()


def _records(text: str) -> list[str]:
    return text.split("\n")


def _first(text: str, kind: str) -> str:
    return re.search(rf"(?m)^{kind} .*#$", text).group(0)


def _set_field(record: str, k: int, value: str) -> str:
    parts = record.split(" ")
    parts[k] = value
    return " ".join(parts)


def _hostile() -> dict[str, bytes]:
    solid, spline = _text(), _text(SHEET_SPLINE)
    face, loop, lump = _first(solid, "face"), _first(solid, "loop"), _first(solid, "lump")
    n_face = solid.split("\n")[3:].index(face)  # record number of the first face
    n_loop = solid.split("\n")[3:].index(loop)
    sab = corpus("sat/acad_example_2013_3DSOLID_acis_binary.sab").read_bytes()
    return {
        "truncated": solid[: len(solid) // 2].encode(),
        "dangling": solid.replace(face, _set_field(face, 5, "$999999")).encode(),  # fields: name, attrib, history,
        "face cycle": solid.replace(face, _set_field(face, 4, f"${n_face}")).encode(),  # pattern, next, …
        "loop cycle": solid.replace(loop, _set_field(loop, 4, f"${n_loop}")).encode(),
        "lump cycle": solid.replace(lump, _set_field(lump, 4, "$2")).encode(),
        "huge knot count": spline.replace("open open none none 2 2", "open open none none 2000000000 2", 1).encode(),
        "endless nesting": spline.replace("{ exactsur", "{ exactsur " + "{ " * 200_000, 1).encode(),
        "non-finite": solid.replace(_first(solid, "point"), "point $-1 -1 $-1 1e999 0 0 #").encode(),
        "wrong kind": solid.replace(face, _set_field(face, 5, "$0")).encode(),  # a body where the loop should be
        "binary truncated": sab[: len(sab) // 3],
        "binary garbage": sab[:200] + bytes(range(256)) * 40,
        "header only": b"700 0 1 0\n@4 test @4 ACIS @0 \n1 1e-06 1e-10\n",
    }


NAMES = ["truncated", "dangling", "face cycle", "loop cycle", "lump cycle", "huge knot count", "endless nesting",
         "non-finite", "wrong kind", "binary truncated", "binary garbage", "header only"]


def test_the_names_cover_every_hostile_file():
    assert sorted(NAMES) == sorted(_hostile())


@pytest.mark.parametrize("name", NAMES)
def test_hostile_acis_is_unreadable_cad(tmp_path: Path, name):
    data = _hostile()[name]
    path = tmp_path / ("f.sab" if data.startswith(b"ACIS") else "f.sat")
    path.write_bytes(data)
    with pytest.raises(AmprepError) as err:
        read_cad(path)
    assert err.value.code in (ErrorCode.UNREADABLE_CAD, ErrorCode.EMPTY_MODEL), err.value
    if name != "header only":
        assert err.value.code == ErrorCode.UNREADABLE_CAD, err.value


def test_hostile_acis_over_http_fails_its_job_and_the_worker_goes_on(service, tmp_path: Path):
    bad = tmp_path / "cycle.sat"
    bad.write_bytes(_hostile()["face cycle"])
    with service.client() as c:
        job = wait_status(c, submit(c, bad, params='{"reuse": false}').json()["id"], ("succeeded", "failed"), 300)
        assert job["status"] == "failed" and job["error"]["code"] == "unreadable_cad", job
        assert "loops back" in job["error"]["message"]
        ok = submit(c, corpus(SOLID), params='{"reuse": false, "tolerance": 0.01}').json()
        ok = wait_status(c, ok["id"], ("succeeded", "failed"), 300)
        assert ok["status"] == "succeeded" and ok["worker"] == job["worker"] and job["attempts"] == 1
        assert ok["input"]["file"]["format"] == "sat", ok["input"]
        dxf = submit(c, corpus("sat/libredwg_example_2013.dxf"), params='{"tolerance": 0.05}', wait=300).json()
        assert dxf["status"] == "succeeded" and dxf["input"]["file"]["format"] == "dxf", dxf
