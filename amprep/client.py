"""`amprep submit`: the HTTP client. Upload, follow the job's events, download its main artifact."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import httpx

from amprep.errors import AmprepError, ErrorCode
from amprep.jobs.params import KINDS

MAIN_ARTIFACT = {k.name: k.artifacts for k in KINDS.values()}


def _raise_problem(r: httpx.Response) -> None:
    if r.status_code >= 400:
        try:
            body = r.json()
            code, detail = body.get("code", "invalid_request"), body.get("detail", r.text)
        except ValueError:
            code, detail = "unavailable", r.text[:200]
        raise AmprepError(ErrorCode(code) if code in ErrorCode._value2member_map_ else ErrorCode.INVALID_REQUEST,
                          f"server answered {r.status_code}: {detail}")


class Client:
    """A thin client of the REST API (one httpx.Client; Bearer key when given)."""

    def __init__(self, server: str, api_key: str | None = None, timeout: float = 60.0) -> None:
        headers = {"Authorization": f"Bearer {api_key}"} if api_key else {}
        self.http = httpx.Client(base_url=server.rstrip("/"), headers=headers, timeout=timeout)

    def submit(self, path: Path, kind: str, params: dict[str, Any], stl: Path | None = None,
               idempotency_key: str | None = None) -> dict[str, Any]:
        files: dict[str, Any] = {"file": (path.name, path.open("rb"))}
        if stl is not None:
            files["stl"] = (stl.name, stl.open("rb"))
        headers = {"Idempotency-Key": idempotency_key} if idempotency_key else {}
        try:
            r = self.http.post("/v1/jobs", data={"kind": kind, "params": json.dumps(params)}, files=files,
                               headers=headers, timeout=None)
        except httpx.HTTPError as exc:
            raise AmprepError(ErrorCode.UNAVAILABLE, f"cannot reach {self.http.base_url}: {exc}") from None
        finally:
            for _, fh in files.values():
                fh.close()
        _raise_problem(r)
        return r.json()

    def follow(self, job_id: str, on_update: Callable[[dict[str, Any]], None] | None = None) -> dict[str, Any]:
        """Read the job's server-sent events until it ends; the final job."""
        job: dict[str, Any] = {}
        with self.http.stream("GET", f"/v1/jobs/{job_id}/events", timeout=httpx.Timeout(60, read=None)) as r:
            _raise_problem(r)
            for line in r.iter_lines():
                if line.startswith("data:"):
                    job = json.loads(line[5:].strip())
                    if on_update:
                        on_update(job)
        return job or self.get(job_id)

    def get(self, job_id: str) -> dict[str, Any]:
        r = self.http.get(f"/v1/jobs/{job_id}")
        _raise_problem(r)
        return r.json()

    def download(self, job: dict[str, Any], name: str, out: Path) -> int:
        with self.http.stream("GET", f"/v1/jobs/{job['id']}/artifacts/{name}") as r:
            _raise_problem(r)
            size = 0
            with out.open("wb") as fh:
                for chunk in r.iter_bytes():
                    fh.write(chunk)
                    size += len(chunk)
        return size


def main_artifact(job: dict[str, Any]) -> str | None:
    names = {a["name"] for a in job.get("artifacts", [])}
    return next((n for n in MAIN_ARTIFACT.get(job["kind"], ()) if n in names), None)
