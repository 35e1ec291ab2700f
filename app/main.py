"""create_app(): the FastAPI app (uvicorn app.main:app)."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from contextlib import asynccontextmanager

import redis.asyncio as aioredis
from celery import Celery
from fastapi import FastAPI
from prometheus_client import CollectorRegistry
from starlette.types import ASGIApp, Receive, Scope, Send

from amprep import __version__
from amprep.queue import make_celery, requeue_lost
from amprep.settings import Settings, get_settings
from amprep.store import JobStore

from . import problems
from .auth import KeyGuard
from .limits import UploadLimit
from .metrics import StoreCollector
from .routes import health, jobs, kinds, pages

log = logging.getLogger("amprep.api")

DESCRIPTION = """CAD (STEP, IGES, BREP, ACIS SAT/SAB/DXF) or STL in; closed STL or 3MF within a chord tolerance, and error reports, out.

Submit with `POST /v1/jobs` (multipart), follow with `GET /v1/jobs/{id}` or its server-sent `events`, download
`artifacts`. Errors are RFC 9457 problem details with a stable `code`. One line converts a file:

    curl -fsS -F file=@part.step -F kind=convert -H 'Accept: model/stl' 'http://127.0.0.1:8000/v1/jobs?wait=600' -o part.stl
"""


class AccessLog:
    """One JSON log line per request with method, path, status, duration and the job id it touched."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        t0, status = time.perf_counter(), [500]

        async def _send(msg: dict) -> None:  # type: ignore[type-arg]
            if msg["type"] == "http.response.start":
                status[0] = msg["status"]
            await send(msg)

        try:
            await self.app(scope, receive, _send)
        finally:
            log.info("%s %s %d", scope["method"], scope["path"], status[0], extra={
                "method": scope["method"], "path": scope["path"], "code": status[0],
                "duration_ms": round((time.perf_counter() - t0) * 1000, 1),
                "job_id": scope.get("state", {}).get("job_id")})


def _openapi(app: FastAPI) -> dict:  # type: ignore[type-arg]
    """The generated schema plus the per-kind params models (the `params` form field is a JSON string)."""
    from fastapi.openapi.utils import get_openapi

    from .models import PARAMS_MODEL

    if app.openapi_schema is None:
        spec = get_openapi(title=app.title, version=app.version, description=app.description, routes=app.routes,
                           tags=app.openapi_tags)
        schemas = spec.setdefault("components", {}).setdefault("schemas", {})
        for model in PARAMS_MODEL.values():
            schema = model.model_json_schema(ref_template="#/components/schemas/{model}")
            schemas.update(schema.pop("$defs", {}))
            schemas[model.__name__] = schema
        spec["x-params-by-kind"] = {k: f"#/components/schemas/{m.__name__}" for k, m in PARAMS_MODEL.items()}
        app.openapi_schema = spec
    return app.openapi_schema


async def _watch_lost(store: JobStore, celery: Celery, after: float) -> None:
    """Every after/4 seconds (1 to 15), send again the tasks the broker lost (queue.requeue_lost)."""
    while True:
        await asyncio.sleep(min(15.0, max(1.0, after / 4)))
        try:
            for job_id in await asyncio.to_thread(requeue_lost, store, celery, after):
                log.warning("sent again: its task was in no queue and held by no worker", extra={"job_id": job_id})
        except Exception as exc:  # Redis away (a restart): the next round tries again
            log.warning("the lost-task watch could not run: %s", type(exc).__name__)


def create_app(settings: Settings | None = None) -> FastAPI:
    """The API on the given settings (default: from the AMPREP_* environment)."""
    s = settings or get_settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI):  # type: ignore[no-untyped-def]
        app.state.settings = s
        app.state.store = JobStore(s.redis_url, s.data_dir, s.retention_seconds)
        app.state.aredis = aioredis.Redis.from_url(s.redis_url, decode_responses=True)
        app.state.celery = make_celery(s, "amprep-api")
        app.state.key_hashes = frozenset(s.api_keys)
        app.state.ping_cache = (-1e9, [])
        app.state.registry = CollectorRegistry()
        app.state.registry.register(StoreCollector(app.state.store))
        s.artifacts_dir.mkdir(parents=True, exist_ok=True)
        watch = asyncio.create_task(_watch_lost(app.state.store, app.state.celery, s.requeue_after_seconds))
        yield
        watch.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await watch
        await app.state.aredis.aclose()

    app = FastAPI(title="amprep", version=__version__, description=DESCRIPTION, lifespan=lifespan, docs_url=None,
                  redoc_url=None,
                  openapi_tags=[{"name": "jobs", "description": "Convert, analyze and refine jobs"},
                                {"name": "health", "description": "Liveness, readiness and metrics"}])
    problems.install(app)
    app.openapi = lambda: _openapi(app)  # type: ignore[method-assign]
    app.include_router(health.router)
    app.include_router(jobs.router)
    app.include_router(kinds.router)
    app.include_router(pages.router)
    app.mount("/static", pages.static_files(), name="static")
    app.add_middleware(UploadLimit, limit=s.max_upload_bytes)
    app.add_middleware(KeyGuard, keys=frozenset(s.api_keys), allow_insecure=s.allow_insecure_bind)
    app.add_middleware(AccessLog)
    return app


def __getattr__(name: str) -> FastAPI:
    """`uvicorn app.main:app` builds the app on first access (settings are read then, not at import)."""
    if name == "app":
        from amprep.logs import setup_logging

        setup_logging()
        return create_app()
    raise AttributeError(name)
