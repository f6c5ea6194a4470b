"""The browser tests' harness: the console a browser test serves (:func:`browser_console`),
the page helpers here, and the fixtures of this folder's ``conftest.py`` (``browser``:
Playwright's headless Chromium; ``chromium`` and ``frozen_browser``, for a test that freezes
the browser). Screenshots go to :data:`ARTIFACTS`."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from playwright.sync_api import Locator, Page, expect
from support import Console, console_config

ARTIFACTS = Path(__file__).resolve().parents[2] / "test-artifacts"
# how long the page may take to show what the server sent: generous, since the page renders
# in software on the cores the supervisor runs on (a wait, not a timing assertion)
expect.set_options(timeout=15_000)


#: the pilot token of the browser tests' consoles
TOKEN = "browser-test-token"


def browser_console(sessions_dir: Path, pilot_gone: float | None = None, base: str | None = None,
                    **console: Any) -> Console:
    """A served console on the simulated robot in real time for a browser test: the pilot
    token :data:`TOKEN`, the live view at rates a software-rendered page keeps up with,
    ``console`` settings and, when given, the pilot-gone timeout (s, hold) and the shipped
    configuration ``base`` ("sim-tuned": a robot that swims)."""
    cfg = console_config(TOKEN, pilot_gone, base, **{"scene_rate": 15.0, "plot_rate": 5.0, **console})
    return Console(cfg, sessions_dir, serve=True)


def open_page(browser: Any, url: str, width: int = 1280, height: int = 800, context: Any = None) -> Page:
    """A new page on ``url`` (in ``context``, else a context of its own of the given size),
    connected to the console, its status bar shown."""
    page = context.new_page() if context is not None else browser.new_page(viewport={"width": width, "height": height})
    page.goto(url)
    page.wait_for_function("() => !document.body.innerText.includes('Connecting...')", timeout=30_000)
    # the page's script comes with the page's first batch, which a loaded machine may take long to render
    expect(page.locator("#ucat-armed")).to_be_visible(timeout=60_000)
    return page


def gui_input(page: Page, label: str) -> Locator:
    """The input of the GUI row whose label starts with ``label``."""
    label_el = page.locator("label", has_text=re.compile("^" + re.escape(label))).first
    row = label_el.locator("xpath=ancestor::div[contains(@class, 'Flex-root')][1]")
    return row.locator("input:not([type='hidden'])").first


def take_control(page: Page, token: str = TOKEN) -> None:
    """Present the pilot token and press Take control (the caller waits for what follows)."""
    gui_input(page, "Pilot token").fill(token)
    page.get_by_role("button", name="Take control").click()


def become_pilot(page: Page) -> None:
    """Take control with :data:`TOKEN` where nobody else is the pilot, and wait for the page
    to say so."""
    take_control(page)
    expect(page.get_by_text("You are the pilot")).to_be_visible()


def inside_viewport(page: Page, selector: str) -> bool:
    """Whether the element ``selector`` is wholly inside the page's viewport."""
    box = page.locator(selector).bounding_box()
    vp = page.viewport_size
    return (box is not None and box["width"] > 0 and box["x"] >= 0 and box["y"] >= 0
            and box["x"] + box["width"] <= vp["width"] and box["y"] + box["height"] <= vp["height"])
