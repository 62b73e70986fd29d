"""Headless Chromium for the browser test and the README screenshot: Debian's chromium driven by Playwright,
with software WebGL (there is no GPU on a CI machine)."""

from __future__ import annotations

import shutil

__all__ = ["CHROMIUM_ARGS", "find_chromium"]

CHROMIUM_ARGS = (
    "--no-sandbox",
    "--use-angle=swiftshader",  # WebGL without a GPU
    "--enable-unsafe-swiftshader",
    "--disable-background-networking",  # no traffic beyond the page under test
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--disable-quic",
)


def find_chromium() -> str | None:
    """The chromium executable on PATH (Debian names it chromium; some systems chromium-browser)."""
    return shutil.which("chromium") or shutil.which("chromium-browser")
