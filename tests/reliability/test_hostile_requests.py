"""What a careless or hostile client sends is a 4xx with a stable code, never a 500 or a job that runs on something
else than was asked: each probe that once got through is kept here, against the real service."""

from __future__ import annotations

import base64
import socket
import struct
from urllib.parse import urlsplit

import httpx
import pytest

from app.auth import KeyGuard
from tests.conftest import corpus
from tests.service.conftest import KEY_A, submit, wait_status

PART = "voron_vhb_din_mount.step"


@pytest.mark.parametrize("params", ['{"min_size": Infinity}', '{"build_dir": [NaN, 0, 1]}', '{"tolerance": 1e-300}',
                                    '{"tolerance": -Infinity}', "[" * 100_000 + "]" * 100_000,
                                    '{"build_dir": [0, 0, 0]}', '{"faces": [1.5]}'])
def test_bad_params_are_422_and_no_job_is_stored(service, params):
    with service.client() as c:
        before = len(c.get("/v1/jobs", params={"limit": 200}).json()["jobs"])
        r = submit(c, corpus(PART), params=params)
        assert r.status_code == 422 and r.json()["code"] == "invalid_request", r.text
        assert len(c.get("/v1/jobs", params={"limit": 200}).json()["jobs"]) == before


@pytest.mark.parametrize("cursor", [base64.urlsafe_b64encode(b"nan").decode(), base64.urlsafe_b64encode(b"inf").decode(),
                                    "%%%", base64.urlsafe_b64encode(b"1e999").decode()])
def test_a_cursor_the_server_never_gave_is_422(service, cursor):
    with service.client() as c:
        r = c.get("/v1/jobs", params={"cursor": cursor})
        assert r.status_code == 422 and r.json()["code"] == "invalid_request"


def test_an_extra_form_field_is_refused_not_ignored(service):
    """`-F tolerance=0.05` would have run at the default tolerance."""
    with service.client() as c:
        r = c.post("/v1/jobs", data={"kind": "convert", "tolerance": "0.05"},
                   files={"file": (PART, corpus(PART).read_bytes())})
        assert r.status_code == 422 and "tolerance" in r.json()["detail"]


def test_an_stl_of_points_is_a_clear_error(service, tmp_path):
    """Every vertex at the origin, as the user's STL of an analyze job: stl_mismatch, not internal_error."""
    zero = tmp_path / "zero.stl"
    zero.write_bytes(b"\0" * 80 + struct.pack("<I", 4) + struct.pack("<12fH", *[0.0] * 12, 0) * 4)
    with service.client() as c:
        r = submit(c, corpus(PART), kind="analyze", params='{"reuse": false}', wait=120, stl=zero)
        job = wait_status(c, r.json()["id"], ("succeeded", "failed"), 300)
        assert job["status"] == "failed" and job["error"]["code"] == "stl_mismatch", job["error"]
        r = submit(c, zero, kind="analyze", params='{"reuse": false}', wait=120)  # alone: a report, nothing crossed
        job = wait_status(c, r.json()["id"], ("succeeded", "failed"), 300)
        assert job["status"] == "succeeded", job["error"]


def test_the_same_idempotency_key_with_other_bytes_is_a_conflict(service, tmp_path):
    """Same key, same file name and size, different bytes: 409, not the first job."""
    a, b = tmp_path / "a" / "part.stl", tmp_path / "b" / "part.stl"
    for p, z in ((a, 0.0), (b, 1.0)):
        p.parent.mkdir()
        tri = struct.pack("<12fH", 0, 0, 1, 0, 0, z, 1, 0, z, 0, 1, z, 0)
        p.write_bytes(b"\0" * 80 + struct.pack("<I", 1) + tri)
    assert a.stat().st_size == b.stat().st_size
    with service.client() as c:
        first = submit(c, a, headers={"Idempotency-Key": "same-key-bytes"})
        assert first.status_code in (200, 202)
        again = submit(c, a, headers={"Idempotency-Key": "same-key-bytes"})
        assert again.json()["id"] == first.json()["id"]
        other = submit(c, b, headers={"Idempotency-Key": "same-key-bytes"})
        assert other.status_code == 409 and other.json()["code"] == "conflict"


def test_accept_model_3mf_gets_the_3mf(service):
    with service.client() as c:
        r = submit(c, corpus(PART), params='{"format": "3mf", "reuse": false}', wait=300,
                   headers={"Accept": "model/3mf"})
        assert r.status_code == 200 and r.headers["content-type"] == "model/3mf" and r.content[:2] == b"PK"
        r = submit(c, corpus(PART), params='{"reuse": false}', wait=300, headers={"Accept": "model/3mf"})
        assert r.status_code == 406 and r.json()["code"] == "not_acceptable"


def test_an_anonymous_upload_is_refused_before_its_body_is_read(keyed_api):
    """Headers announcing 150 MB, then 64 KB of it: the 401 comes back while the rest has not been sent."""
    u = urlsplit(keyed_api)
    with socket.create_connection((u.hostname, u.port), timeout=30) as s:
        s.sendall(b"POST /v1/jobs HTTP/1.1\r\nHost: x\r\nContent-Type: multipart/form-data; boundary=b\r\n"
                  b"Content-Length: 150000000\r\n\r\n" + b"x" * 65536)
        status = s.recv(4096).split(b"\r\n", 1)[0]
    assert b" 401 " in status
    with httpx.Client(base_url=keyed_api, timeout=30) as c:
        assert c.get("/healthz").status_code == 200 and c.get("/openapi.json").status_code == 200
        assert c.get("/v1/jobs").status_code == 401
        assert c.get("/v1/jobs", headers={"Authorization": f"Bearer {KEY_A}"}).status_code == 200


def test_without_keys_only_the_own_machine_is_served():
    """However the app was started (uvicorn --host 0.0.0.0 too): a server without keys answers a non-loopback client
    with 401, a loopback one as usual, and the health checks to anyone (the ASGI guard called as the server would)."""
    import asyncio

    async def app(scope, receive, send):  # type: ignore[no-untyped-def]
        await send({"type": "http.response.start", "status": 200, "headers": []})
        await send({"type": "http.response.body", "body": b"ok"})

    def status(client: tuple[str, int], path: str = "/v1/jobs", keys: frozenset[str] = frozenset(),
               insecure: bool = False) -> int:
        sent: list[dict] = []

        async def receive() -> dict:
            return {"type": "http.request", "body": b"", "more_body": False}

        async def send(msg: dict) -> None:
            sent.append(msg)

        scope = {"type": "http", "method": "GET", "path": path, "headers": [], "client": client}
        asyncio.run(KeyGuard(app, keys, insecure)(scope, receive, send))
        return sent[0]["status"]

    assert status(("192.0.2.7", 5000)) == 401 and status(("203.0.113.9", 1), "/healthz") == 200
    assert status(("127.0.0.1", 5000)) == 200 and status(("::1", 5000)) == 200
    assert status(("192.0.2.7", 5000), insecure=True) == 200


@pytest.mark.parametrize("tail", ["../../../../../../etc/passwd", "..%2F..%2F..%2F..%2Fetc%2Fpasswd",
                                  "..%2Finput%2Fmodel.step", "%2e%2e/%2e%2e/summary.json", "part.stl%00.png"])
def test_artifact_paths_do_not_leave_the_job(service, tail):
    """Sent as raw bytes (httpx and browsers normalise `..` away before sending): every such name is a 404."""
    import http.client

    with service.client() as c:
        job = submit(c, corpus(PART), wait=120).json()
    u = urlsplit(service.url)
    conn = http.client.HTTPConnection(u.hostname, u.port, timeout=30)
    conn.request("GET", f"/v1/jobs/{job['id']}/artifacts/{tail}")
    r = conn.getresponse()
    body = r.read()
    conn.close()
    assert r.status == 404 and b"root:" not in body and b"ISO-10303" not in body
