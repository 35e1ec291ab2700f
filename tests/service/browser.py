"""Headless Chromium from Debian's packages, driven by Playwright (never a browser download), for the dashboard's
tests and bench/dashboard.py; every request that would leave the server under test is refused and recorded."""

from __future__ import annotations

import io
import os
import shutil
from urllib.parse import urlsplit

import numpy as np

ARGS = ["--no-sandbox", "--disable-background-networking", "--disable-component-update", "--disable-sync",
        "--no-first-run", "--disable-default-apps", "--enable-unsafe-swiftshader", "--disable-quic"]


def chromium_path() -> str | None:
    """The system Chromium (AMPREP_CHROMIUM, else chromium on PATH)."""
    return os.environ.get("AMPREP_CHROMIUM") or shutil.which("chromium") or shutil.which("chromium-browser")


def guard_host(page, base_url: str, outside: list[str]) -> None:  # type: ignore[no-untyped-def]
    """Abort (and append to `outside`) every request of `page` to a host other than base_url's."""
    host = urlsplit(base_url).netloc

    def route(r):  # type: ignore[no-untyped-def]
        u = urlsplit(r.request.url)
        if u.scheme in ("http", "https", "ws", "wss") and u.netloc != host:
            outside.append(r.request.url)
            return r.abort()
        return r.continue_()

    page.route("**/*", route)


def pixels(png: bytes) -> np.ndarray:
    """A screenshot as an (h, w, 3) uint8 array."""
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))


def drawn_fraction(img: np.ndarray, background: tuple[int, int, int] = (0xE9, 0xED, 0xF2)) -> float:
    """Fraction of pixels that differ from the view's background colour by more than 24 in some channel."""
    return float((np.abs(img.astype(int) - np.array(background)).max(axis=2) > 24).mean())


def near_colour(img: np.ndarray, rgb: tuple[int, int, int], tol: int = 40) -> int:
    """Pixels within `tol` of `rgb` in every channel."""
    return int((np.abs(img.astype(int) - np.array(rgb)).max(axis=2) <= tol).sum())


def saturated_fraction(img: np.ndarray) -> float:
    """Fraction of pixels whose channels spread by more than 40 (coloured, not grey)."""
    i = img.astype(int)
    return float(((i.max(axis=2) - i.min(axis=2)) > 40).mean())


def have_browser() -> None:
    """Fail with what to install when the system Chromium is missing."""
    import pytest

    if chromium_path() is None:
        pytest.fail("no system Chromium: `apt-get install chromium` (.ci/run does it), or set AMPREP_CHROMIUM")
