"""RFC 9457 problem+json: one exception type, one mapping of every error the API can answer with."""

from __future__ import annotations

import logging
from http import HTTPStatus
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from redis.exceptions import RedisError
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import Match, Route

from amprep.errors import AmprepError, ErrorCode

MEDIA_TYPE = "application/problem+json"
log = logging.getLogger("amprep.api")


class ApiError(Exception):
    """An answer other than success: HTTP status, stable code, one-line detail, optional extensions."""

    def __init__(self, status: int, code: ErrorCode | str, detail: str, **extra: Any) -> None:
        super().__init__(detail)
        self.status, self.code, self.detail, self.extra = status, str(code), detail, extra


def problem(status: int, code: str, detail: str, instance: str | None = None,
            headers: dict[str, str] | None = None, **extra: Any) -> JSONResponse:
    """An RFC 9457 problem+json response (`headers`: more headers, e.g. a 405's Allow)."""
    body = {"type": "about:blank", "title": HTTPStatus(status).phrase, "status": status, "detail": detail,
            "code": code, "instance": instance} | {k: v for k, v in extra.items() if v is not None}
    headers = dict(headers or {}) | ({"WWW-Authenticate": "Bearer"} if status == 401 else {})
    return JSONResponse(body, status_code=status, media_type=MEDIA_TYPE, headers=headers or None)


_CODE_OF_STATUS = {404: ErrorCode.NOT_FOUND, 405: ErrorCode.INVALID_REQUEST, 413: ErrorCode.UPLOAD_TOO_LARGE,
                   401: ErrorCode.UNAUTHORIZED, 406: ErrorCode.NOT_ACCEPTABLE}


#: seconds a client is asked to wait before retrying a 503
RETRY_AFTER = 5


def allowed_methods(request: Request) -> str:
    """The Allow header of a 405: every method of every route whose path matches (Starlette names only the first
    route's, and GET and POST /v1/jobs are two routes)."""
    methods: set[str] = set()
    for route in request.app.router.routes:
        if isinstance(route, Route) and route.methods and route.matches(request.scope)[0] != Match.NONE:
            methods |= route.methods
    return ", ".join(sorted(methods))


def install(app: FastAPI) -> None:
    """Map ApiError, AmprepError, validation errors, HTTP errors and anything unexpected to problem+json."""

    @app.exception_handler(ApiError)
    async def _api(request: Request, exc: ApiError) -> JSONResponse:
        headers = {"Retry-After": str(RETRY_AFTER)} if exc.status == 503 else None
        return problem(exc.status, exc.code, exc.detail, request.url.path, headers=headers, **exc.extra)

    @app.exception_handler(AmprepError)
    async def _amprep(request: Request, exc: AmprepError) -> JSONResponse:
        return problem(422, exc.code.value, exc.message, request.url.path)

    @app.exception_handler(RequestValidationError)
    async def _validation(request: Request, exc: RequestValidationError) -> JSONResponse:
        errors = [{"loc": list(e.get("loc", ())), "msg": e.get("msg", ""), "type": e.get("type", "")} for e in exc.errors()]
        first = errors[0] if errors else {"loc": [], "msg": "invalid request"}
        where = ".".join(str(x) for x in first["loc"] if x not in ("body",))
        return problem(422, ErrorCode.INVALID_REQUEST.value, f"{where}: {first['msg']}" if where else first["msg"],
                       request.url.path, errors=errors)

    @app.exception_handler(StarletteHTTPException)
    async def _http(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        code = _CODE_OF_STATUS.get(exc.status_code, ErrorCode.INVALID_REQUEST)
        headers = dict(exc.headers or {})
        if exc.status_code == 405:
            headers["Allow"] = allowed_methods(request)
        return problem(exc.status_code, code.value, str(exc.detail), request.url.path, headers=headers)

    @app.exception_handler(RedisError)
    async def _redis(request: Request, exc: RedisError) -> JSONResponse:
        log.warning("redis unavailable on %s: %s", request.url.path, type(exc).__name__)
        return problem(503, ErrorCode.UNAVAILABLE.value, f"the job store is unreachable ({type(exc).__name__}): "
                       "retry later", request.url.path, headers={"Retry-After": str(RETRY_AFTER)})

    @app.exception_handler(Exception)
    async def _unexpected(request: Request, exc: Exception) -> JSONResponse:
        log.exception("unexpected error on %s", request.url.path)
        return problem(500, ErrorCode.INTERNAL_ERROR.value, "unexpected server error (logged)", request.url.path)
