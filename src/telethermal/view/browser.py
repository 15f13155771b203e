"""Headless Chromium for the view's tests and benchmark, driven by Playwright.

Playwright's own browser download is not used: the distribution's Chromium
(``apt-get install chromium``) is launched by path, with everything that
would reach outside this machine switched off.
"""

from __future__ import annotations

import os
import shutil

from telethermal.errors import TelethermalError

ARGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
        "--disable-component-update", "--disable-sync", "--no-first-run",
        "--disable-default-apps", "--disable-extensions")


class BrowserUnavailable(TelethermalError, RuntimeError):
    """No Chromium, or no Playwright, on this machine."""


def find_chromium() -> str:
    """``TELETHERMAL_CHROMIUM``, else ``chromium`` or ``chromium-browser`` on PATH."""
    path = os.environ.get("TELETHERMAL_CHROMIUM") or shutil.which("chromium") or \
        shutil.which("chromium-browser")
    if not path:
        raise BrowserUnavailable("no Chromium found (install it with `apt-get install -y "
                                 "--no-install-recommends chromium`, or set "
                                 "TELETHERMAL_CHROMIUM to its path)")
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError as exc:
        raise BrowserUnavailable("the playwright package is not installed (pip install "
                                 "'telethermal[test]')") from exc
    return path


def launch(playwright, path: str | None = None):
    """A headless Chromium browser (close it when done)."""
    return playwright.chromium.launch(executable_path=path or find_chromium(), args=list(ARGS))
