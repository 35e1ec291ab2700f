"""The key guard, before any route reads a request's body: with API keys configured, a request without a valid key
is a 401 at once (an anonymous 150 MB upload is not read first); without keys, the server answers only its own
machine (loopback clients) unless AMPREP_ALLOW_INSECURE_BIND — however it was started (`amprep serve`, uvicorn,
Docker). The health checks, the API's own documentation, the job kinds and the dashboard's pages are open."""

from __future__ import annotations

from starlette.datastructures import Headers
from starlette.types import ASGIApp, Receive, Scope, Send

from amprep.errors import ErrorCode
from amprep.serve import is_loopback
from amprep.settings import hash_key

from .problems import problem

OPEN_PATHS = frozenset({"/healthz", "/readyz", "/docs", "/redoc", "/openapi.json", "/v1/kinds", "/"})
#: the dashboard's pages and files hold no data (they call the API with the user's key)
OPEN_PREFIXES = ("/static/", "/jobs/")


def is_open(path: str) -> bool:
    """True for a path served without a key: health, the API docs, the job kinds, the dashboard's pages and files."""
    return path in OPEN_PATHS or path.startswith(OPEN_PREFIXES)


def _loopback(client: tuple[str, int] | None) -> bool:
    """True for a client on this machine (None or starlette's 'testclient': an in-process test client)."""
    return client is None or client[0] == "testclient" or is_loopback(client[0].split("%")[0])


def valid_key(authorization: str | None, keys: frozenset[str]) -> str | None:
    """The sha256 digest of the Bearer key of an Authorization header when it is one of `keys`, else None."""
    scheme, _, key = (authorization or "").partition(" ")
    if scheme.lower() != "bearer" or not key.strip():
        return None
    digest = hash_key(key.strip())
    return digest if digest in keys else None


class KeyGuard:
    """ASGI middleware: 401 problem+json for a request the server must not serve, before the app sees its body."""

    def __init__(self, app: ASGIApp, keys: frozenset[str], allow_insecure: bool) -> None:
        self.app, self.keys, self.allow_insecure = app, keys, allow_insecure

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or is_open(scope["path"]):
            return await self.app(scope, receive, send)
        detail = None
        if self.keys:
            header = Headers(scope=scope).get("authorization")
            if valid_key(header, self.keys) is None:
                detail = ("this server needs an API key: Authorization: Bearer KEY" if not header
                          else "the API key is not valid")
        elif not self.allow_insecure and not _loopback(scope.get("client")):
            detail = ("this server has no API keys and answers only its own machine: configure AMPREP_API_KEYS "
                      "(see `amprep key`)")
        if detail is None:
            return await self.app(scope, receive, send)
        response = problem(401, ErrorCode.UNAUTHORIZED.value, detail, scope["path"])
        await response(scope, receive, send)
