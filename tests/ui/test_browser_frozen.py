"""A pilot's browser frozen (SIGSTOP on every Chromium process) while the robot is armed and
moving: the console notices within the pilot-gone timeout, the failsafe acts, the page's
socket is closed, and when the browser wakes its page comes back on a new connection and
is the pilot again by the token it kept (checked by the console as any token), the robot
still holding."""

from __future__ import annotations

from typing import Any, Callable

import pytest
from support import Console, console_config, wait_for

pytest.importorskip("playwright.sync_api")
from browser_harness import open_page, take_control  # noqa: E402

from ucat_console.backend.access import LOCAL  # noqa: E402

pytestmark = [pytest.mark.browser, pytest.mark.slow]
TOKEN = "frozen-browser-token"
PILOT_GONE = 2.0


def test_a_frozen_pilot_browser_trips_pilot_gone_and_wakes_up_the_pilot_again(
        chromium: Any, frozen_browser: Any, make_console: Callable[..., Console]) -> None:
    browser = frozen_browser
    console = make_console(console_config(TOKEN, PILOT_GONE, "sim-tuned", scene_rate=15.0, plot_rate=5.0),
                           serve=True)  # a robot that swims
    sup, app, events = console.sup, console.app, console.events
    page = open_page(browser, console.url, 1400, 900, browser.contexts[0] if browser.contexts else None)
    page.set_viewport_size({"width": 1400, "height": 900})
    take_control(page, TOKEN)
    wait_for(lambda: sup.access.pilot is not None, what="the page taking control")
    cid = sup.access.pilot
    sup.arm(LOCAL)
    sup.set_setpoints(LOCAL, velocity=0.2)
    wait_for(lambda: sup._last_body is not None and sup._last_body.velocity[0] > 0.02, timeout=60.0,
             what="the robot moving")
    n = len(events)
    try:  # thawed before the console stops
        chromium.freeze()
        fired = wait_for(lambda: next((e for e in events[n:] if e.source == "failsafe"
                                       and e.code == "pilot_gone"), None),
                         timeout=PILOT_GONE + 30.0, what="the pilot_gone failsafe")
        assert fired.data["action"] == "hold"
        assert sup.setpoints.velocity == 0.0 and sup.access.pilot is None
        wait_for(lambda: cid not in app.guard.clients, what="the frozen page's socket closed")
        chromium.thaw()
        # the page reconnects as a new page and presents its kept token again: the pilot once
        # more, on a new connection; the robot still holds what the failsafe set
        wait_for(lambda: sup.access.pilot not in (None, cid), timeout=60.0, what="the woken page the pilot again")
        assert sup.armed and sup.setpoints.velocity == 0.0
    finally:
        if chromium.stopped:
            chromium.thaw()
    page.close()
