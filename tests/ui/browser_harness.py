"""The browser tests' harness: the page helpers here and the fixtures of this folder's
``conftest.py`` (``chromium`` and ``frozen_browser``, for a test that freezes the browser).
Screenshots go to :data:`ARTIFACTS`."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from playwright.sync_api import Locator, Page, expect

ARTIFACTS = Path(__file__).resolve().parents[2] / "test-artifacts"
# how long the page may take to show what the server sent: generous, since the page renders
# in software on the cores the supervisor runs on (a wait, not a timing assertion)
expect.set_options(timeout=15_000)


def open_page(browser: Any, url: str, width: int = 1280, height: int = 800, context: Any = None) -> Page:
    """A new page on ``url`` (in ``context``, else a context of its own of the given size),
    connected to the console."""
    page = context.new_page() if context is not None else browser.new_page(viewport={"width": width, "height": height})
    page.goto(url)
    page.wait_for_function("() => !document.body.innerText.includes('Connecting...')", timeout=30_000)
    return page


def gui_input(page: Page, label: str) -> Locator:
    """The input of the GUI row whose label starts with ``label``."""
    label_el = page.locator("label", has_text=re.compile("^" + re.escape(label))).first
    row = label_el.locator("xpath=ancestor::div[contains(@class, 'Flex-root')][1]")
    return row.locator("input:not([type='hidden'])").first


def take_control(page: Page, token: str) -> None:
    """Present the pilot token and press Take control (the caller waits for what follows)."""
    gui_input(page, "Pilot token").fill(token)
    page.get_by_role("button", name="Take control").click()
