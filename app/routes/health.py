"""/healthz (the process answers), /readyz (Redis answers and a worker is alive), /metrics (Prometheus)."""

from __future__ import annotations

import time

from fastapi import APIRouter, Request
from fastapi.responses import JSONResponse, PlainTextResponse
from prometheus_client import CONTENT_TYPE_LATEST, generate_latest
from starlette.concurrency import run_in_threadpool

from amprep.errors import ErrorCode

from ..deps import OwnerDep
from ..problems import problem

router = APIRouter(tags=["health"])


@router.get("/healthz", operation_id="healthz", summary="The API process is up",
            responses={200: {"content": {"application/json": {"example": {"status": "ok"}}}}})
async def healthz() -> JSONResponse:
    return JSONResponse({"status": "ok"})


def _workers_alive(request: Request) -> list[str]:
    """Names of workers answering a ping within a second (cached 2 s)."""
    state = request.app.state
    t = time.monotonic()
    if t - state.ping_cache[0] > 2.0:
        replies = state.celery.control.ping(timeout=1.0) or []
        state.ping_cache = (t, sorted(name for r in replies for name in r))
    return state.ping_cache[1]


@router.get("/readyz", operation_id="readyz", summary="Redis answers and at least one worker is alive",
            responses={200: {"content": {"application/json": {"example": {"status": "ready", "workers": ["w@h"]}}}},
                       503: {"content": {"application/problem+json": {}}, "description": "Not ready (code unavailable)"}})
async def readyz(request: Request) -> JSONResponse:
    try:
        await request.app.state.aredis.ping()
    except Exception as exc:
        return problem(503, ErrorCode.UNAVAILABLE.value, f"Redis does not answer: {type(exc).__name__}", "/readyz")
    workers = await run_in_threadpool(_workers_alive, request)
    if not workers:
        return problem(503, ErrorCode.UNAVAILABLE.value, "no worker answers", "/readyz")
    return JSONResponse({"status": "ready", "workers": workers})


@router.get("/metrics", operation_id="metrics", summary="Prometheus metrics (needs a key when keys are configured)",
            response_class=PlainTextResponse,
            responses={200: {"content": {"text/plain": {}}}})
async def metrics(request: Request, _owner: OwnerDep) -> PlainTextResponse:
    body = await run_in_threadpool(generate_latest, request.app.state.registry)
    return PlainTextResponse(body.decode(), media_type=CONTENT_TYPE_LATEST)
