"""The upload limit, enforced while the body streams in: 413 problem+json as soon as it is crossed."""

from __future__ import annotations

from starlette.datastructures import Headers
from starlette.exceptions import HTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from .problems import problem


class UploadTooLarge(HTTPException):
    def __init__(self, limit: int) -> None:
        super().__init__(413, f"the upload is over the limit of {limit:,} bytes")


class UploadLimit:
    """Rejects a declared Content-Length over `limit` before reading, and stops a stream once it passes `limit`."""

    def __init__(self, app: ASGIApp, limit: int, paths: tuple[str, ...] = ("/v1/jobs",)) -> None:
        self.app, self.limit, self.paths = app, limit, paths

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["method"] != "POST" or scope["path"] not in self.paths:
            return await self.app(scope, receive, send)
        declared = Headers(scope=scope).get("content-length")
        if declared and declared.isdigit() and int(declared) > self.limit:
            detail = f"the upload ({int(declared):,} bytes) is over the limit of {self.limit:,} bytes"
            response = problem(413, "upload_too_large", detail, scope["path"])
            return await response(scope, receive, send)
        total = 0

        async def limited() -> Message:
            nonlocal total
            message = await receive()
            if message["type"] == "http.request":
                total += len(message.get("body", b""))
                if total > self.limit:
                    raise UploadTooLarge(self.limit)
            return message

        await self.app(scope, limited, send)
