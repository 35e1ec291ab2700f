"""RFC 9457 problem+json: one exception type, one mapping of every error the API can answer with."""

from __future__ import annotations

import logging
from http import HTTPStatus
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException

from amprep.errors import AmprepError, ErrorCode

MEDIA_TYPE = "application/problem+json"
log = logging.getLogger("amprep.api")


class ApiError(Exception):
    """An answer other than success: HTTP status, stable code, one-line detail, optional extensions."""

    def __init__(self, status: int, code: ErrorCode | str, detail: str, **extra: Any) -> None:
        super().__init__(detail)
        self.status, self.code, self.detail, self.extra = status, str(code), detail, extra


def problem(status: int, code: str, detail: str, instance: str | None = None, **extra: Any) -> JSONResponse:
    body = {"type": "about:blank", "title": HTTPStatus(status).phrase, "status": status, "detail": detail,
            "code": code, "instance": instance} | {k: v for k, v in extra.items() if v is not None}
    headers = {"WWW-Authenticate": "Bearer"} if status == 401 else None
    return JSONResponse(body, status_code=status, media_type=MEDIA_TYPE, headers=headers)


_CODE_OF_STATUS = {404: ErrorCode.NOT_FOUND, 405: ErrorCode.INVALID_REQUEST, 413: ErrorCode.UPLOAD_TOO_LARGE,
                   401: ErrorCode.UNAUTHORIZED, 406: ErrorCode.NOT_ACCEPTABLE}


def install(app: FastAPI) -> None:
    """Map ApiError, AmprepError, validation errors, HTTP errors and anything unexpected to problem+json."""

    @app.exception_handler(ApiError)
    async def _api(request: Request, exc: ApiError) -> JSONResponse:
        return problem(exc.status, exc.code, exc.detail, request.url.path, **exc.extra)

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
        return problem(exc.status_code, code.value, str(exc.detail), request.url.path)

    @app.exception_handler(Exception)
    async def _unexpected(request: Request, exc: Exception) -> JSONResponse:
        log.exception("unexpected error on %s", request.url.path)
        return problem(500, ErrorCode.INTERNAL_ERROR.value, "unexpected server error (logged)", request.url.path)
