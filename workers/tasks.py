"""One thin task per job kind: load the job, run the geometry, store artifacts, update the record."""

from __future__ import annotations

import hashlib
import hmac
import json
import logging
import os
import socket
import time
from typing import Any

import httpx
from celery import Task
from celery.exceptions import SoftTimeLimitExceeded, TimeLimitExceeded

from amprep import callbacks
from amprep.errors import AmprepError, ErrorCode, out_of_memory
from amprep.geometry.core.progress import checking
from amprep.jobs.common import provenance
from amprep.jobs.params import KINDS, JobKind
from amprep.jobs.runner import run
from amprep.logs import job_id_var
from amprep.memory import memory_budget
from amprep.queue import CALLBACK_TASK
from amprep.settings import get_settings
from amprep.store import JobStore, now

from .celery_app import app

log = logging.getLogger("amprep.worker")
_store: JobStore | None = None


def store() -> JobStore:
    global _store
    if _store is None:
        s = get_settings()
        _store = JobStore(s.redis_url, s.data_dir, s.retention_seconds, patience=60.0)  # ride out a Redis restart
    return _store


class JobTask(Task):
    """Marks the job failed when the pool ends a task from outside it (hard time limit)."""

    def on_failure(self, exc, task_id, args, kwargs, einfo):  # type: ignore[no-untyped-def]
        job_id = args[0] if args else kwargs.get("job_id")
        if job_id:
            code = ErrorCode.TIME_LIMIT if isinstance(exc, TimeLimitExceeded) else ErrorCode.INTERNAL_ERROR
            _finish(job_id, "failed", error={"code": code.value, "message": f"the job was stopped: {exc}"})


def _finish(job_id: str, status: str, **fields: Any) -> None:
    job = store().transition(job_id, ("queued", "running"), status=status, finished_at=now(), **fields)
    if job is not None and job.params.get("callback_url"):
        app.send_task(CALLBACK_TASK, args=[job_id])


class _Reporter:
    """progress(stage, fraction) for the library: throttled writes to the job record; raises on cancel."""

    def __init__(self, job_id: str) -> None:
        self.job_id, self.last, self.last_check = job_id, 0.0, 0.0

    def check(self) -> None:
        """The library's checkpoint between blocks of one long computation: raises when the job was cancelled
        (asks Redis at most every 0.5 s)."""
        t = time.monotonic()
        if t - max(self.last, self.last_check) < 0.5:
            return
        self.last_check = t
        job = store().get(self.job_id)
        if job is None or job.status == "cancelled":
            raise AmprepError(ErrorCode.CANCELLED, "the job was cancelled")

    def __call__(self, stage: str, fraction: float) -> None:
        t = time.monotonic()
        if t - self.last < 0.2:
            return
        self.last = t
        if store().set_progress(self.job_id, stage, fraction) is None:
            raise AmprepError(ErrorCode.CANCELLED, "the job was cancelled")


def run_job(job_id: str, redelivered: bool = False) -> None:
    """The body of every kind's task. A job starts once: from queued, or again from running only on a message the
    broker gave back because the process running it died (`redelivered`); any other copy of its message (sent
    twice: a lost task sent again, a publish retried) ends at once."""
    st, settings = store(), get_settings()
    job_id_var.set(job_id)
    job = st.get(job_id)
    if job is None or job.status not in ("queued", "running"):
        return  # deleted or cancelled while queued, or a copy of an ended job's message
    if job.status == "running" and not redelivered:
        log.info("another copy of a running job's task: dropped")
        return
    job = st.transition(job_id, (job.status,), attempt=True, status="running", started_at=now(), stage="starting",
                        progress=0.0, worker=f"{socket.gethostname()}:{os.getpid()}",
                        provenance=provenance() | {"params": job.params})
    if job is None:
        return  # another copy started it first
    if job.attempts > settings.max_crashes:
        log.error("worker process died %d times on this job", settings.max_crashes)
        _finish(job_id, "failed", error={"code": ErrorCode.WORKER_CRASHED.value, "message":
                f"the worker process running this job died {settings.max_crashes} times; the input may crash OCCT"})
        return
    log.info("started", extra={"kind": job.kind})
    src = st.input_path(job_id, job.input["file"]["stored_as"])
    stl = st.input_path(job_id, job.input["stl"]["stored_as"]) if job.input.get("stl") else None
    params = job.params | {"max_triangles": min(job.params.get("max_triangles", settings.max_triangles),
                                                settings.max_triangles)}
    try:
        reporter = _Reporter(job_id)
        with memory_budget(settings.memory_limit_mb), checking(reporter.check):
            result, paths = run(job.kind, src, params, st.job_dir(job_id) / "out", reporter, stl)
        artifacts = [st.add_artifact(job_id, p) for p in paths]
    except AmprepError as exc:
        if exc.code == ErrorCode.CANCELLED:
            log.info("cancelled")
            return
        log.info("failed", extra={"code": exc.code.value})
        _finish(job_id, "failed", error={"code": exc.code.value, "message": exc.message})
        return
    except SoftTimeLimitExceeded:
        _finish(job_id, "failed", error={"code": ErrorCode.TIME_LIMIT.value, "message": "the job ran over its time limit"})
        return
    except Exception as exc:  # a bug of ours: the job fails with a code, the worker goes on
        if out_of_memory(exc):
            _finish(job_id, "failed", error={"code": ErrorCode.MEMORY_LIMIT.value, "message": "the job ran out of "
                    f"memory: it may add {settings.memory_limit_mb} MiB to its worker (AMPREP_MEMORY_LIMIT_MB)"})
            return
        log.exception("unexpected error")
        _finish(job_id, "failed", error={"code": ErrorCode.INTERNAL_ERROR.value, "message": f"{type(exc).__name__}: {exc}"})
        return
    made_by = job.provenance | ({"mesh_params": result["provenance"]["params"]}
                                if "params" in result.get("provenance", {}) else {})
    fp = job.input.get("fingerprint")
    if fp:  # before the job shows as succeeded: a client told so may resubmit at once (reusable checks the status)
        st.remember_result(fp, job_id)
    _finish(job_id, "succeeded", progress=1.0, stage="done", artifacts=artifacts, result=result, provenance=made_by)
    st.sweep()
    log.info("succeeded")


def _job_task(kind: JobKind) -> Task:
    """The kind's task: its name from jobs.params, its body run_job."""

    def job(self: Task, job_id: str) -> None:
        run_job(job_id, redelivered=bool((self.request.delivery_info or {}).get("redelivered")))

    job.__name__ = job.__qualname__ = kind.name
    return app.task(name=kind.task, base=JobTask, bind=True)(job)


TASKS = {name: _job_task(kind) for name, kind in KINDS.items()}


def signature(secret: str, body: bytes) -> str:
    """`sha256=<hex HMAC-SHA256 of the body>`: the X-Amprep-Signature header of a callback."""
    return "sha256=" + hmac.new(secret.encode(), body, hashlib.sha256).hexdigest()


@app.task(name=CALLBACK_TASK, bind=True, acks_late=True, max_retries=None)
def callback(self: Task, job_id: str) -> None:
    """POST the final job JSON to params.callback_url, at an address checked as it connects (amprep.callbacks: never
    loopback, private or link-local unless AMPREP_CALLBACK_ALLOW says), no redirect followed; retried with
    exponential backoff on failure."""
    settings = get_settings()
    job = store().get(job_id)
    if job is None or not job.params.get("callback_url"):
        return
    job_id_var.set(job_id)
    body = json.dumps(job.public(), sort_keys=True).encode()
    headers = {"Content-Type": "application/json", "X-Amprep-Job": job_id,
               "X-Amprep-Signature": signature(settings.callback_secret, body)}
    try:
        r = callbacks.post(job.params["callback_url"], body, headers, callbacks.networks(settings.callback_allow))
        r.raise_for_status()
        log.info("callback delivered", extra={"code": r.status_code})
    except AmprepError as exc:  # the host now resolves to an address callbacks must not reach: never sent
        log.error("callback refused: %s", exc.message)
        return
    except httpx.HTTPError as exc:
        if self.request.retries >= settings.callback_retries:
            log.error("callback given up after %d tries: %s", self.request.retries + 1, exc)
            return
        log.warning("callback failed (%s), retrying", exc)
        raise self.retry(countdown=min(2 ** self.request.retries, 300)) from None
