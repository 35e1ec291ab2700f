"""The dashboard's pages (`/`, `/jobs/{id}`), its static files (`/static`) and the API docs (`/docs`, `/redoc`), all
served from files inside the package: no CDN, nothing fetched at run time. The pages hold no data; they call the API
with the key the user enters (kept in the browser's session storage)."""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter
from fastapi.openapi.docs import get_redoc_html, get_swagger_ui_html
from fastapi.responses import FileResponse, HTMLResponse
from fastapi.staticfiles import StaticFiles

STATIC = Path(__file__).resolve().parent.parent / "static"
FAVICON = "/static/favicon.svg"

router = APIRouter(include_in_schema=False)


def static_files() -> StaticFiles:
    """The /static mount: the pages' own files, the built bundles (dist/) and the vendored libraries (vendor/)."""
    return StaticFiles(directory=STATIC, check_dir=True)


def _page(name: str) -> FileResponse:
    return FileResponse(STATIC / name, media_type="text/html", headers={"Cache-Control": "no-cache"})


@router.get("/")
async def index() -> FileResponse:
    return _page("index.html")


@router.get("/jobs/{job_id}")
async def job_page(job_id: str) -> FileResponse:
    return _page("job.html")


@router.get("/docs")
async def swagger() -> HTMLResponse:
    return get_swagger_ui_html(openapi_url="/openapi.json", title="amprep API", swagger_favicon_url=FAVICON,
                               swagger_js_url="/static/vendor/swagger-ui-bundle.js",
                               swagger_css_url="/static/vendor/swagger-ui.css")


@router.get("/redoc")
async def redoc() -> HTMLResponse:
    return get_redoc_html(openapi_url="/openapi.json", title="amprep API", redoc_favicon_url=FAVICON,
                          redoc_js_url="/static/vendor/redoc.standalone.js", with_google_fonts=False)
