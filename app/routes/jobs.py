"""/v1/jobs: create (upload), read, list, cancel/delete, artifacts and server-sent events."""

from __future__ import annotations

import json
import os
import tempfile
import zipfile
from pathlib import Path
from typing import Annotated, Any

from fastapi import APIRouter, File, Form, Header, Query, Request, UploadFile
from fastapi.responses import FileResponse, JSONResponse, Response
from pydantic import ValidationError
from sse_starlette.sse import EventSourceResponse
from starlette.background import BackgroundTask
from starlette.concurrency import run_in_threadpool

from amprep import callbacks
from amprep.errors import AmprepError, ErrorCode
from amprep.jobs.params import check
from amprep.queue import CALLBACK_TASK, TASK_OF_KIND
from amprep.store import TERMINAL, Job, fingerprint, new_job_id, now

from ..deps import CeleryDep, OwnerDep, StoreDep
from ..events import job_updates, owner_updates, wait_for_end
from ..models import PARAMS_MODEL, JobList, JobPublic, Kind, Problem, Status
from ..problems import ApiError, problem
from ..uploads import require_cad, require_stl, sniff, store_upload

router = APIRouter(prefix="/v1", tags=["jobs"])

PROBLEMS: dict[int | str, dict[str, Any]] = {
    s: {"model": Problem, "content": {"application/problem+json": {}}, "description": d}
    for s, d in [(400, "A body that is not well-formed (e.g. broken multipart)"),
                 (401, "Missing or invalid API key"), (404, "No such job (or not yours)"),
                 (422, "Invalid request or input: see `code`"),
                 (503, "Redis or the queue is unreachable (code unavailable): retry after Retry-After seconds")]
}
JOB_EXAMPLE = JobPublic.model_config["json_schema_extra"]["examples"][0]  # type: ignore[index]


#: mesh media types a client may ask for in Accept to get an ended job's mesh itself
MESH_TYPES = ("model/stl", "model/3mf")


def _job_response(job: Job, request: Request, status_code: int | None = None) -> Response:
    """The job JSON (200 when it has ended, else 202); or its mesh when asked with Accept: model/stl or model/3mf."""
    accept = request.headers.get("accept", "")
    wanted = [m for m in MESH_TYPES if m in accept]
    if wanted and job.status in TERMINAL:
        if job.status != "succeeded":
            err = job.error or {"code": ErrorCode.CANCELLED.value, "message": "the job was cancelled"}
            return problem(422, err["code"], err["message"], request.url.path, job_id=job.id)
        art = next((a for m in wanted for a in job.artifacts if a["media_type"] == m), None)
        if art is None:
            return problem(406, ErrorCode.NOT_ACCEPTABLE.value, f"this job has no {' or '.join(wanted)} artifact "
                           "(ask a convert job for the format its params chose)", request.url.path, job_id=job.id)
        return FileResponse(request.app.state.store.artifact_path(job.id, art["name"]), media_type=art["media_type"],
                            filename=art["name"], headers={"X-Amprep-Job": job.id})
    code = status_code or (200 if job.status in TERMINAL else 202)
    return JSONResponse(job.public(), status_code=code, headers={"Location": f"/v1/jobs/{job.id}"})


def _own(store: Any, job_id: str, owner: str) -> Job:
    job = store.get(job_id)
    if job is None or job.owner != owner:
        raise ApiError(404, ErrorCode.NOT_FOUND, f"no job {job_id}")
    return job


def _params(kind: str, raw: str) -> dict[str, Any]:
    try:
        data = json.loads(raw or "{}")
    except json.JSONDecodeError as exc:
        raise ApiError(422, ErrorCode.INVALID_REQUEST, f"params: not JSON ({exc.msg})") from None
    except RecursionError:
        raise ApiError(422, ErrorCode.INVALID_REQUEST, "params: nested too deeply") from None
    if not isinstance(data, dict):
        raise ApiError(422, ErrorCode.INVALID_REQUEST, "params: must be a JSON object")
    try:
        values = PARAMS_MODEL[kind].model_validate(data).model_dump(mode="json")
        check(kind, values, service=True)  # what a schema cannot say (a zero build direction), as the CLI checks it
        return values
    except AmprepError as exc:
        raise ApiError(422, ErrorCode.INVALID_REQUEST, f"params.{exc.message}") from None
    except ValidationError as exc:
        errors = [{"loc": ["params", *e["loc"]], "msg": e["msg"], "type": e["type"]} for e in exc.errors()]
        first = errors[0]
        raise ApiError(422, ErrorCode.INVALID_REQUEST, f"{'.'.join(map(str, first['loc']))}: {first['msg']}",
                       errors=errors) from None


#: the multipart fields of POST /v1/jobs; any other is refused, never ignored
FORM_FIELDS = frozenset({"file", "stl", "kind", "params"})


async def _no_other_fields(request: Request) -> None:
    """invalid_request for a form field the API does not take (a param sent as `-F tolerance=0.05` would otherwise
    be silently ignored and the job run at the default)."""
    extra = sorted(set((await request.form()).keys()) - FORM_FIELDS)
    if extra:
        raise ApiError(422, ErrorCode.INVALID_REQUEST, f"unknown form field '{extra[0]}': the fields are file, stl, "
                       "kind and params (job parameters go in the params JSON, e.g. -F 'params={\"tolerance\": 0.05}')")


async def _callback_allowed(url: str, allow: list[str]) -> None:
    """callback_refused (422) for a callback_url that resolves to an address callbacks must not reach."""
    try:
        await run_in_threadpool(callbacks.resolve, url, callbacks.networks(allow))
    except AmprepError as exc:
        raise ApiError(422, exc.code, exc.message) from None


@router.post(
    "/jobs", operation_id="create_job", status_code=202, summary="Submit a file for convert, analyze or refine",
    responses={200: {"model": JobPublic, "description": "The job ended within ?wait (or an idempotent repeat of "
                     "an ended job); with Accept: model/stl, the STL itself",
                     "content": {"model/stl": {}, "application/json": {"example": JOB_EXAMPLE}}},
               202: {"model": JobPublic, "description": "Queued (or still running when ?wait ran out)"},
               409: PROBLEMS[422] | {"description": "Idempotency-Key reused with a different request"},
               413: PROBLEMS[422] | {"description": "Upload over the size limit (code upload_too_large)"},
               **PROBLEMS})
async def create_job(
    request: Request, store: StoreDep, celery: CeleryDep, owner: OwnerDep,
    file: Annotated[UploadFile, File(description="STEP, IGES, BREP, ACIS (SAT, SAB, DXF) or STL (recognised from its bytes)")],
    kind: Annotated[Kind, Form(description="convert | analyze | refine")],
    params: Annotated[str, Form(description="JSON object of the kind's params (unknown keys are an error): "
                                "ConvertParams, AnalyzeParams or RefineParams",
                                examples=['{"tolerance": 0.05}'])] = "{}",
    # typed without None so the schema says "a file, or absent" (a null part is not a file)
    stl: Annotated[UploadFile, File(description="An STL made elsewhere, scored/refined against `file`")] = None,  # type: ignore[assignment]
    wait: Annotated[float, Query(ge=0, le=3600, description="Hold the request up to this many seconds for the end")] = 0,
    idempotency_key: Annotated[str | None, Header(alias="Idempotency-Key", max_length=255,
                                                  description="The same key returns the same job")] = None,
) -> Response:
    await _no_other_fields(request)
    p = _params(kind, params)
    if p.get("callback_url"):
        await _callback_allowed(p["callback_url"], request.app.state.settings.callback_allow)
    info = {"file": await sniff(file, "file")}
    if stl is not None:
        info["stl"] = await sniff(stl, "stl")
        require_stl(info["stl"])
        require_cad(info["file"])
    if kind == "refine":
        _refine_input(p["method"], info)
    job_id = new_job_id()
    earlier = store.claim_idempotency(owner, idempotency_key, job_id) if idempotency_key else None
    job_dir = store.job_dir(job_id) / "input"
    info["file"] = await store_upload(file, info["file"], job_dir, "model")
    if stl is not None:
        info["stl"] = await store_upload(stl, info["stl"], job_dir, "user")
    info["fingerprint"] = fingerprint(kind, info["file"]["sha256"], info.get("stl", {}).get("sha256", ""), p)
    if idempotency_key:  # the same key: the same bytes and params, or a conflict
        info["request"] = fingerprint(kind, f"{info['file']['sha256']}:{info['file']['name']}",
                                      info.get("stl", {}).get("sha256", ""), p)
        if earlier and (old := store.get(earlier)) is not None:
            store.discard_files(job_id)
            if old.input.get("request") != info["request"]:
                raise ApiError(409, ErrorCode.CONFLICT, "Idempotency-Key already used for a different request")
            request.state.job_id = old.id
            if old.status == "queued" and not store.was_sent(old.id):  # the broker was down when it was made
                _send(celery, store, old, keyed=True)
            return await _respond(request, store, old, wait, owner)
        if earlier and not store.rebind_idempotency(owner, idempotency_key, earlier, job_id):
            # the key named a job whose record was never written (Redis went away): this request takes it over
            store.discard_files(job_id)
            raise ApiError(409, ErrorCode.CONFLICT, "a request with this Idempotency-Key is in progress: retry")
    job = Job(id=job_id, kind=kind, owner=owner, params=p, input=info, idempotency_key=idempotency_key)
    request.state.job_id = job_id
    earlier_result = store.reusable(info["fingerprint"], owner) if p["reuse"] else None
    if earlier_result is not None:
        store.copy_artifacts(earlier_result, job_id)
        t = now()
        job.status, job.progress, job.stage = "succeeded", 1.0, "reused"
        job.artifacts, job.result, job.provenance = earlier_result.artifacts, earlier_result.result, earlier_result.provenance
        job.reused_from, job.created_at, job.started_at, job.finished_at = earlier_result.id, t, t, t
        store.create(job)
        if p.get("callback_url"):
            celery.send_task(CALLBACK_TASK, args=[job_id])
        return _job_response(job, request)
    store.create(job)
    _send(celery, store, job, keyed=bool(idempotency_key))
    return await _respond(request, store, job, wait, owner)


def _refine_input(method: str, info: dict[str, Any]) -> None:
    """A refine job's input fits its method: butterfly an STL alone, the others a CAD file (422 otherwise)."""
    stl_alone = info["file"]["format"] == "stl" and "stl" not in info
    if method == "butterfly" and not stl_alone:
        raise ApiError(422, ErrorCode.INVALID_PARAMETER, "butterfly refines an STL alone (no CAD): upload the STL as "
                       "`file`; for a CAD model use sma, vta or adaptive")
    if method != "butterfly" and info["file"]["format"] == "stl":
        raise ApiError(422, ErrorCode.INVALID_PARAMETER, f"{method} refines the faces of a CAD model: upload the STEP, "
                       "IGES or BREP as `file` (and an STL as `stl`), or use method butterfly for an STL alone")


def _send(celery: Any, store: Any, job: Job, keyed: bool) -> None:
    """Queue the job's task and mark it sent. When the broker is down: a keyed job stays queued (a retry with its
    Idempotency-Key sends it), any other fails with unavailable (its client submits again); a 503 either way."""
    try:
        celery.send_task(TASK_OF_KIND[job.kind], args=[job.id], task_id=job.id)
    except Exception as exc:  # the broker is down: the job cannot run yet
        if not keyed:
            store.transition(job.id, ("queued",), status="failed", finished_at=now(),
                             error={"code": ErrorCode.UNAVAILABLE.value, "message": "the queue is unreachable"})
        raise ApiError(503, ErrorCode.UNAVAILABLE, f"the queue is unreachable: {type(exc).__name__}") from None
    store.mark_sent(job.id)


async def _respond(request: Request, store: Any, job: Job, wait: float, owner: str) -> Response:
    if wait > 0 and job.status not in TERMINAL:
        job = await wait_for_end(request.app.state.aredis, store, job.id, wait, owner) or job
    return _job_response(job, request)


@router.get("/jobs/{job_id}", operation_id="get_job", response_model=JobPublic, summary="A job's status and results",
            responses={200: {"content": {"model/stl": {}}, "description": "The job; with Accept: model/stl and a "
                             "finished convert job, its STL"}, **PROBLEMS})
async def get_job(job_id: str, request: Request, store: StoreDep, owner: OwnerDep) -> Response:
    request.state.job_id = job_id
    return _job_response(_own(store, job_id, owner), request, status_code=200)


#: a cursor is the created_at (Unix seconds, Python's shortest exact repr) of the previous page's last job: any
#: string of this form is a valid cursor, and none is non-finite
CURSOR = r"^[0-9]{1,12}(\.[0-9]{1,20})?$"


@router.get("/jobs", operation_id="list_jobs", response_model=JobList, summary="Your jobs, newest first",
            responses=PROBLEMS)
async def list_jobs(store: StoreDep, owner: OwnerDep, status: Status | None = None, kind: Kind | None = None,
                    cursor: Annotated[str | None, Query(description="next_cursor of the previous page",
                                                        pattern=CURSOR, max_length=40)] = None,
                    limit: Annotated[int, Query(ge=1, le=200)] = 50) -> JobList:
    jobs, nxt = store.list(owner, status, kind, float(cursor) if cursor else None, limit)
    next_cursor = repr(float(nxt)) if nxt is not None else None
    return JobList(jobs=[JobPublic.model_validate(j.public()) for j in jobs], next_cursor=next_cursor)


@router.delete("/jobs/{job_id}", operation_id="delete_job", summary="Cancel a queued or running job, or delete "
               "a finished one and its files",
               responses={200: {"model": JobPublic, "description": "Cancelled (the worker stops at its next step)"},
                          204: {"description": "Deleted"}, **PROBLEMS})
async def delete_job(job_id: str, request: Request, store: StoreDep, celery: CeleryDep, owner: OwnerDep) -> Response:
    request.state.job_id = job_id
    job = _own(store, job_id, owner)
    if job.status not in TERMINAL:
        cancelled = store.transition(job_id, ("queued", "running"), status="cancelled", finished_at=now(),
                                     stage="cancelled", error={"code": ErrorCode.CANCELLED.value,
                                                               "message": "cancelled by the client"})
        if cancelled is not None:
            if cancelled.params.get("callback_url"):
                celery.send_task(CALLBACK_TASK, args=[job_id])
            return JSONResponse(cancelled.public())
        job = _own(store, job_id, owner)  # it ended meanwhile: delete it below
    store.delete(job)
    return Response(status_code=204)


@router.get("/jobs/{job_id}/artifacts/{name}", operation_id="get_artifact", summary="Download an artifact",
            response_class=FileResponse,
            responses={200: {"content": {"model/stl": {}, "model/3mf": {}, "application/json": {}, "image/png": {}},
                             "description": "The file"}, **PROBLEMS})
async def get_artifact(job_id: str, name: str, request: Request, store: StoreDep, owner: OwnerDep) -> Response:
    request.state.job_id = job_id
    job = _own(store, job_id, owner)
    art = next((a for a in job.artifacts if a["name"] == name), None)
    if art is None:
        raise ApiError(404, ErrorCode.NOT_FOUND, f"job {job_id} has no artifact '{name}'")
    return FileResponse(store.artifact_path(job_id, name), media_type=art["media_type"], filename=name,
                        headers={"X-Amprep-Sha256": art["sha256"]})


@router.get("/jobs/{job_id}/events", operation_id="job_events", summary="Server-sent events: the job on every change",
            response_class=EventSourceResponse,
            responses={200: {"content": {"text/event-stream": {}}, "description": "`event: job` with the job JSON "
                             "on every change; the stream ends when the job does"}, **PROBLEMS})
async def job_events(job_id: str, request: Request, store: StoreDep, owner: OwnerDep) -> EventSourceResponse:
    request.state.job_id = job_id
    _own(store, job_id, owner)
    aredis = request.app.state.aredis

    async def stream():  # type: ignore[no-untyped-def]
        last = None
        async for job in job_updates(aredis, store, job_id, None, owner):
            key = (job.status, job.progress, job.stage)
            if key != last:
                last = key
                yield {"event": "job", "id": f"{job.status}:{job.progress}", "data": json.dumps(job.public())}

    return EventSourceResponse(stream(), ping=10)


def _zip(job: Job, store: Any) -> Path:
    """A temporary zip of the job's artifacts (deflated, level 1: meshes compress by half at little cost)."""
    store.tmp.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(prefix=f"{job.id}-", suffix=".zip", dir=store.tmp)
    os.close(fd)
    with zipfile.ZipFile(name, "w", zipfile.ZIP_DEFLATED, compresslevel=1) as zf:
        for a in job.artifacts:
            zf.write(store.artifact_path(job.id, a["name"]), arcname=a["name"])
    return Path(name)


@router.get("/jobs/{job_id}/archive", operation_id="get_archive", summary="Every artifact of a job in one zip",
            response_class=FileResponse,
            responses={200: {"content": {"application/zip": {}}, "description": "A zip of the job's artifacts"},
                       **PROBLEMS})
async def get_archive(job_id: str, request: Request, store: StoreDep, owner: OwnerDep) -> Response:
    request.state.job_id = job_id
    job = _own(store, job_id, owner)
    if not job.artifacts:
        raise ApiError(404, ErrorCode.NOT_FOUND, f"job {job_id} has no artifacts ({job.status})")
    path = await run_in_threadpool(_zip, job, store)
    return FileResponse(path, media_type="application/zip", filename=f"amprep-{job.kind}-{job.id}.zip",
                        background=BackgroundTask(path.unlink, missing_ok=True))


@router.get("/events", operation_id="owner_events", summary="Server-sent events: every change of any of your jobs",
            response_class=EventSourceResponse,
            responses={200: {"content": {"text/event-stream": {}}, "description": "`event: job` with the job JSON on "
                             "every change of one of your jobs, `event: deleted` with `{id}` when one is deleted; "
                             "the stream does not end"}, 401: PROBLEMS[401], 503: PROBLEMS[503]})
async def owner_events(request: Request, owner: OwnerDep) -> EventSourceResponse:
    aredis = request.app.state.aredis

    async def stream():  # type: ignore[no-untyped-def]
        async for change in owner_updates(aredis, owner):
            if change.get("deleted"):
                yield {"event": "deleted", "data": json.dumps({"id": change["id"]})}
            elif change:
                yield {"event": "job", "data": json.dumps(change)}

    return EventSourceResponse(stream(), ping=10)
