"""Fixtures for the web panel tests: a free TCP port, headless Debian chromium via Playwright."""

from __future__ import annotations

import shutil
import socket

import pytest

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = [
    "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
    "--disable-component-update", "--disable-sync",
]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def browser_page():
    """A Playwright page in headless Debian chromium (skips naming the missing binary)."""
    if not shutil.which(CHROMIUM):
        pytest.skip(f"no {CHROMIUM}: Debian's chromium is not installed (scripts/install_browser.sh)")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS)
        page = browser.new_page(viewport={"width": 1200, "height": 800})
        yield page
        browser.close()
