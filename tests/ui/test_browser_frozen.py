"""A pilot's browser frozen (SIGSTOP on every Chromium process) while the robot is armed and
moving: the console notices within the pilot-gone timeout, the failsafe acts, the page's
socket is closed, and when the browser wakes its page is a viewer again."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Iterator

import pytest
from support import wait_for

pytest.importorskip("playwright.sync_api")
from playwright.sync_api import expect, sync_playwright  # noqa: E402

from ucat_console.backend.access import LOCAL  # noqa: E402
from ucat_console.backend.supervisor import Supervisor  # noqa: E402
from ucat_console.bench.chromium import Chromium  # noqa: E402
from ucat_console.config import (  # noqa: E402
    AccessConfig,
    AppConfig,
    ConsoleConfig,
    FailsafeConfig,
    FailsafeRule,
)
from ucat_console.telemetry import channels as ch  # noqa: E402
from ucat_console.ui.app import ConsoleApp  # noqa: E402

pytestmark = [pytest.mark.browser, pytest.mark.slow]
TOKEN = "frozen-browser-token"
PILOT_GONE = 2.0
expect.set_options(timeout=15_000)


@pytest.fixture
def chromium() -> Iterator[Chromium]:
    try:
        c = Chromium()
    except FileNotFoundError as e:
        pytest.skip(str(e))
    yield c
    c.close()


def gui_input(page, label: str):
    label_el = page.locator("label", has_text=re.compile("^" + re.escape(label))).first
    return label_el.locator("xpath=ancestor::div[contains(@class, 'Flex-root')][1]").locator(
        "input:not([type='hidden'])").first


def test_a_frozen_pilot_browser_trips_pilot_gone_and_wakes_up_a_viewer(chromium: Chromium, tmp_path: Path) -> None:
    cfg = AppConfig(
        access=AccessConfig(token=TOKEN),
        console=ConsoleConfig(port=0, record_on_arm=False, scene_rate=15.0, plot_rate=5.0),
        failsafe=FailsafeConfig(pilot_gone=FailsafeRule("hold", PILOT_GONE)),
    )
    sup = Supervisor(cfg, sessions_dir=tmp_path)
    events: list = []
    sup.stream.subscribe(lambda c, m: events.append(m), [ch.EVENTS])
    app = ConsoleApp(sup)
    app.start()
    sup.start()
    try:
        with sync_playwright() as p:
            browser = p.chromium.connect_over_cdp(chromium.ws_url)
            page = browser.contexts[0].new_page() if browser.contexts else browser.new_page()
            page.set_viewport_size({"width": 1400, "height": 900})
            page.goto(app.url)
            page.wait_for_function("() => !document.body.innerText.includes('Connecting...')", timeout=30_000)
            gui_input(page, "Pilot token").fill(TOKEN)
            page.get_by_role("button", name="Take control").click()
            wait_for(lambda: sup.access.pilot is not None, what="the page taking control")
            cid = sup.access.pilot
            sup.arm(LOCAL)
            sup.set_setpoints(LOCAL, velocity=0.2)
            wait_for(lambda: sup._last_body is not None and sup._last_body.velocity[0] > 0.02, timeout=60.0,
                     what="the robot moving")
            n = len(events)
            chromium.freeze()
            fired = wait_for(lambda: next((e for e in events[n:] if e.source == "failsafe"
                                           and e.code == "pilot_gone"), None),
                             timeout=PILOT_GONE + 30.0, what="the pilot_gone failsafe")
            assert fired.data["action"] == "hold"
            assert sup.setpoints.velocity == 0.0 and sup.access.pilot is None
            wait_for(lambda: cid not in app.guard.clients, what="the frozen page's socket closed")
            chromium.thaw()
            # the page reconnects as a new page: a viewer, which must present the token again
            expect(page.get_by_text("Read-only").first).to_be_visible(timeout=30_000)
            assert sup.access.pilot is None and sup.armed  # the robot holds; nobody flies
            browser.close()
    finally:
        if chromium.stopped:
            chromium.thaw()
        sup.stop()
        app.stop()
