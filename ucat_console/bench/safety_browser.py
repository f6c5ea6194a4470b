"""``bench safety``'s measures in headless Chromium:

* **Frozen pilot**: a headless Chromium page takes control, the robot is armed and swims at
  0.2 m/s, then every process of the browser is stopped (SIGSTOP). Detection time: from
  the stop to the ``pilot_gone`` failsafe event (wall clock). docs/performance.md states the goal:
  within ``failsafe.pilot_gone.timeout`` + 1 s.
* **Link loss**: a headless Chromium page shows the console, then the console stops
  (server and supervisor gone). Banner time: from the stop to the page showing its
  link-loss banner, by the page's own clock (``Date.now()``, the same wall clock as the
  bench's). The issue's goal: within 2 s.
* **Slow connect**: a headless Chromium page through a link that delays every chunk
  ``--connect-delay`` s each way (1.0: a 2 s round trip; ``bench/delay_proxy.py``): from its
  navigation to its HTML loaded, to its socket open and to the status bar's first state,
  and from its *Take control* to the page flying. The goal: connected (the first state)
  within 10 s through a 2 s round trip.
* **Slow DISARM**: the pilot's Chromium page through ``--disarm-delay`` s each way, the robot
  armed: from the click on the bar's DISARM (its event, by the page's wall clock) to the
  supervisor disarmed; a press not applied within 20 s is counted (a page declared gone
  under load has its DISARM refused). The goal: within the link's delay + 0.5 s.
* **Restart**: the pilot's Chromium page while the console is stopped and started again on
  the same port ``--restarts`` times, ``--spinners`` processes spinning throughout: from the
  restarted console serving to the page the pilot again (its kept token, no reload). The
  goal: within 10 s of every restart.

Figures depend on the machine and its load; they are for docs/performance.md, never test assertions.
"""

from __future__ import annotations

import logging
import statistics
import tempfile
import time
from typing import Any

from ucat_console.bench.safety_console import TOKEN, start_console, wait_until

log = logging.getLogger(__name__)


def frozen_pilot(trials: int, pilot_gone: float) -> dict[str, Any]:
    from playwright.sync_api import sync_playwright

    from ucat_console.backend.access import LOCAL
    from ucat_console.bench.chromium import Chromium

    times: list[float] = []
    with tempfile.TemporaryDirectory() as tmp:
        sup, app, events = start_console(tmp, pilot_gone)
        try:
            with sync_playwright() as p:
                for trial in range(trials):
                    with Chromium() as chrome:
                        browser = p.chromium.connect_over_cdp(chrome.ws_url)
                        page = browser.contexts[0].new_page()
                        page.goto(app.url)
                        page.wait_for_function("() => !document.body.innerText.includes('Connecting...')",
                                               timeout=60_000)
                        box = page.locator("label", has_text="Pilot token").first.locator(
                            "xpath=ancestor::div[contains(@class, 'Flex-root')][1]").locator("input").first
                        box.fill(TOKEN)
                        page.get_by_role("button", name="Take control").click()
                        wait_until(lambda: sup.access.pilot is not None, 30.0, "the page taking control")
                        # the last trial's failsafe clears once the supervisor sees the new pilot
                        wait_until(lambda: not any(s.active for s in sup.safety.states() if s.name == "pilot_gone"),
                              30.0, "the last trial's pilot_gone failsafe cleared")
                        if not sup.armed:
                            sup.arm(LOCAL)
                        sup.set_setpoints(LOCAL, velocity=0.2)
                        wait_until(lambda: sup._last_body is not None and sup._last_body.velocity[0] > 0.05, 60.0,
                              "the robot swimming")
                        n = len(events)
                        t0 = time.monotonic()
                        chrome.freeze()
                        t_fired = wait_until(lambda: next((t for t, e in events[n:] if e.source == "failsafe"
                                                      and e.code == "pilot_gone"), None), pilot_gone + 60.0,
                                        "the pilot_gone failsafe")
                        times.append(t_fired - t0)
                        log.info("frozen pilot trial %d: pilot_gone after %.2f s", trial + 1, times[-1])
                        chrome.thaw()
                        try:
                            browser.close()
                        except Exception:
                            pass
        finally:
            sup.stop()
            app.stop()
    return {"trials": trials, "pilot_gone_timeout_s": pilot_gone,
            "detection_median_s": statistics.median(times), "detection_max_s": max(times),
            "detection_s": times}


#: records, in the page, the wall-clock time at which the link-loss banner first shows
_BANNER_WATCH = """
new MutationObserver((_, obs) => {
  const b = document.getElementById("ucat-banner");
  if (b && b.style.display === "block") { window.__bannerAt = Date.now(); obs.disconnect(); }
}).observe(document, {subtree: true, attributes: true, attributeFilter: ["style"]});
"""


def link_loss(trials: int) -> dict[str, Any]:
    from playwright.sync_api import sync_playwright

    from ucat_console.bench.ui import CHROMIUM, CHROMIUM_ARGS

    times: list[float] = []
    with tempfile.TemporaryDirectory() as tmp, sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            for trial in range(trials):
                sup, app, _ = start_console(tmp, 2.0)
                try:
                    page = browser.new_page()
                    page.add_init_script(_BANNER_WATCH)
                    page.goto(app.url)
                    page.wait_for_function("() => window.__ucat && window.__ucat.state !== null", timeout=60_000)
                    time.sleep(1.0)  # a few states received, as an open page has
                finally:
                    t0 = time.time()
                    sup.stop()
                    app.stop()
                page.wait_for_function("() => window.__bannerAt !== undefined", timeout=60_000)
                times.append(page.evaluate("() => window.__bannerAt") / 1e3 - t0)
                log.info("link loss trial %d: banner after %.2f s", trial + 1, times[-1])
                page.close()
        finally:
            browser.close()
    return {"trials": trials, "banner_median_s": statistics.median(times), "banner_max_s": max(times),
            "banner_s": times}


def _chromium_page(browser: Any, url: str) -> Any:
    """A page on ``url`` at 1280x800 whose status bar shows the console's state."""
    page = browser.new_page(viewport={"width": 1280, "height": 800})
    page.goto(url, timeout=120_000)
    page.wait_for_function("() => window.__ucat && window.__ucat.state !== null", timeout=120_000)
    return page


def _take_control(page: Any) -> None:
    box = page.locator("label", has_text="Pilot token").first.locator(
        "xpath=ancestor::div[contains(@class, 'Flex-root')][1]").locator("input").first
    box.fill(TOKEN)
    page.get_by_role("button", name="Take control").click()


_YOU_PILOT = "() => window.__ucat && window.__ucat.state && window.__ucat.state.you_pilot"


def slow_connect(delay: float, trials: int) -> dict[str, Any]:
    """A Chromium page through a link delaying every chunk ``delay`` s each way
    (:class:`~ucat_console.bench.delay_proxy.DelayProxy`): from the page's navigation to its
    HTML loaded, to its socket open (viser's client logs "Connected!") and to the status
    bar's first state, and from its *Take control* to the page showing it flies."""
    from playwright.sync_api import sync_playwright

    from ucat_console.bench.delay_proxy import DelayProxy
    from ucat_console.bench.ui import CHROMIUM, CHROMIUM_ARGS

    loaded: list[float] = []
    socket: list[float] = []
    connect: list[float] = []
    control: list[float] = []
    with tempfile.TemporaryDirectory() as tmp, sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        sup, app, _ = start_console(tmp, 2.0)
        proxy = DelayProxy(app.port, delay)
        try:
            for trial in range(trials):
                page = browser.new_page(viewport={"width": 1280, "height": 800})
                opened: list[float] = []  # when viser's client logs its socket open
                page.on("console", lambda m: opened.append(time.monotonic()) if m.text.startswith("Connected!") else None)
                t0 = time.monotonic()
                page.goto(proxy.url, timeout=120_000, wait_until="domcontentloaded")
                loaded.append(time.monotonic() - t0)
                page.wait_for_function("() => window.__ucat && window.__ucat.state !== null", timeout=120_000)
                connect.append(time.monotonic() - t0)
                # the console message reaches here after the page logged it, at times after the
                # first state it preceded (Playwright delivers it once its text is resolved)
                socket.append(min(opened[0] - t0, connect[-1]) if opened else connect[-1])
                t1 = time.monotonic()
                _take_control(page)
                page.wait_for_function(_YOU_PILOT, timeout=120_000)
                control.append(time.monotonic() - t1)
                log.info("slow link %.1f s each way, trial %d: page loaded after %.1f s, socket open after %.1f s, "
                         "first state after %.1f s, pilot %.1f s later", delay, trial + 1, loaded[-1], socket[-1],
                         connect[-1], control[-1])
                page.close()
                wait_until(lambda: sup.access.pilot is None, 30.0, "the closed page's control released")
        finally:
            proxy.close()
            sup.stop()
            app.stop()
            browser.close()
    return {"delay_each_way_s": delay, "trials": trials, "loaded_median_s": statistics.median(loaded),
            "socket_median_s": statistics.median(socket), "socket_max_s": max(socket),
            "connect_median_s": statistics.median(connect),
            "connect_max_s": max(connect), "connect_s": connect, "control_median_s": statistics.median(control),
            "control_max_s": max(control)}


def _arm_when_allowed(sup: Any, timeout: float = 120.0) -> None:
    """Arm as the console itself, once no failsafe refuses it (on a machine busy enough, the
    loop watchdog may have disarmed the robot and holds the arming off until the loop steps
    again); TimeoutError with the last refusal after ``timeout`` s."""
    from ucat_console.backend.access import LOCAL
    from ucat_console.backend.supervisor import CommandRefused

    refused = [""]

    def arm() -> bool:
        try:
            sup.arm(LOCAL)
            return True
        except CommandRefused as e:
            refused[0] = str(e)
            time.sleep(0.1)  # asked again a few times a second
            return False

    try:
        wait_until(arm, timeout, "arming")
    except TimeoutError as e:
        raise TimeoutError(f"{e}: {refused[0]}") from None


def slow_disarm(delay: float, trials: int) -> dict[str, Any]:
    """The pilot's Chromium page through a link delaying every chunk ``delay`` s each way, the
    robot armed: from the click on the bar's DISARM (its event in the page, by the page's
    wall clock) to the supervisor disarmed; a disarm by anything else first (a failsafe) is
    counted apart, with its reason."""
    from playwright.sync_api import sync_playwright

    from ucat_console.backend.access import LOCAL
    from ucat_console.bench.delay_proxy import DelayProxy
    from ucat_console.bench.ui import CHROMIUM, CHROMIUM_ARGS

    times: list[float] = []
    otherwise: list[str] = []  # the reasons of disarms that came before the click's
    lost = 0
    with tempfile.TemporaryDirectory() as tmp, sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        sup, app, events = start_console(tmp, 2.0)
        proxy = DelayProxy(app.port, delay)
        try:
            page = _chromium_page(browser, proxy.url)
            _take_control(page)
            page.wait_for_function(_YOU_PILOT, timeout=120_000)
            # the press's moment by the page's clock (the wall clock, as the bench's): the click's
            # dispatch in a busy browser is not the link's
            page.evaluate("() => document.getElementById('ucat-disarm').addEventListener('click', "
                          "() => { window.__disarmAt = Date.now(); }, true)")
            for trial in range(trials):
                # the page shows the last trial's DISARM first: a button still enabled by an older
                # state may turn off under the click
                page.wait_for_function("() => document.getElementById('ucat-disarm').disabled", timeout=120_000)
                _arm_when_allowed(sup)
                page.wait_for_function("() => !document.getElementById('ucat-disarm').disabled", timeout=120_000)
                n = len(events)
                page.locator("#ucat-disarm").click()
                try:
                    wait_until(lambda: not sup.armed, 20.0, "DISARM through the slow link")
                except TimeoutError:  # refused or lost: counted, and the next trial starts afresh
                    lost += 1
                    log.warning("DISARM through %.1f s each way, trial %d: not applied", delay, trial + 1)
                    sup.disarm(LOCAL)
                    page.wait_for_function(_YOU_PILOT, timeout=120_000)  # back as the pilot (its kept token)
                    continue
                applied = time.time()
                reason = next((e.data.get("reason", "") for _, e in events[n:] if e.code == "disarmed"), "")
                if reason != "operator":  # something else disarmed (a failsafe): not the click's time
                    otherwise.append(reason or "unknown")
                    log.warning("DISARM through %.1f s each way, trial %d: disarmed by %s first", delay,
                                trial + 1, otherwise[-1])
                    continue
                times.append(applied - page.evaluate("() => window.__disarmAt") / 1e3)
                log.info("DISARM through %.1f s each way, trial %d: %.2f s", delay, trial + 1, times[-1])
        finally:
            proxy.close()
            sup.stop()
            app.stop()
            browser.close()
    return {"delay_each_way_s": delay, "trials": trials, "applied": len(times), "not_applied": lost,
            "disarmed_otherwise": otherwise,
            "disarm_median_s": statistics.median(times) if times else None,
            "disarm_max_s": max(times) if times else None, "disarm_s": times}


def restarts(count: int, spinners: int) -> dict[str, Any]:
    """The pilot's Chromium page while the console restarts ``count`` times on the same port,
    ``spinners`` processes spinning meanwhile: the time from the restarted console serving
    (and from the old one stopped) to the page the pilot again, by its kept token, without a
    reload."""
    import subprocess
    import sys

    from playwright.sync_api import sync_playwright

    from ucat_console.bench.ui import CHROMIUM, CHROMIUM_ARGS

    from_up: list[float] = []
    from_stop: list[float] = []
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(spinners)]
    with tempfile.TemporaryDirectory() as tmp, sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        sup, app, _ = start_console(tmp, 2.0)
        port = app.port
        try:
            page = _chromium_page(browser, app.url)
            _take_control(page)
            page.wait_for_function(_YOU_PILOT, timeout=120_000)
            for trial in range(count):
                t_stop = time.monotonic()
                sup.stop()
                app.stop()
                sup, app, _ = start_console(tmp, 2.0, port)
                t_up = time.monotonic()
                wait_until(lambda: sup.access.pilot is not None, 120.0, "the page back as the pilot")
                from_up.append(time.monotonic() - t_up)
                from_stop.append(time.monotonic() - t_stop)
                log.info("restart %d: the page the pilot again %.1f s after the console served (%.1f s after "
                         "the stop)", trial + 1, from_up[-1], from_stop[-1])
        finally:
            for h in hogs:
                h.kill()
                h.wait()
            sup.stop()
            app.stop()
            browser.close()
    return {"restarts": count, "spinners": spinners, "back": len(from_up),
            "from_up_median_s": statistics.median(from_up), "from_up_max_s": max(from_up), "from_up_s": from_up,
            "from_stop_median_s": statistics.median(from_stop), "from_stop_max_s": max(from_stop)}
