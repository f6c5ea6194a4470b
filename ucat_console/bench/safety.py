"""``ucat-console bench safety``: how the console treats a frozen pilot, a token spammer and
a crowd of pages, measured against ``ucat-console run`` on the simulated robot.

* **Frozen pilot**: a headless Chromium page takes control, the robot is armed and swims at
  0.2 m/s, then every process of the browser is stopped (SIGSTOP). Detection time: from
  the stop to the ``pilot_gone`` failsafe event (wall clock). The README states the goal:
  within ``failsafe.pilot_gone.timeout`` + 1 s.
* **Take-over under spam**: a raw page sends a wrong token every 0.1 s; another raw page
  from the same address presents the right one. Take-over time: from sending the token
  to being the pilot.
* **Crowd**: rounds of pages connecting at the same moment; a page is broken when it does
  not get its controls or its *Take control* does not make it the pilot.
* **Link loss**: a headless Chromium page shows the console, then the console stops
  (server and supervisor gone). Banner time: from the stop to the page showing its
  link-loss banner, by the page's own clock (``Date.now()``, the same wall clock as the
  bench's). The issue's goal: within 2 s.

Figures depend on the machine and its load (reported with them); they are for the README,
never test assertions.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import statistics
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

TOKEN = "safety-bench-token"


def _console(tmp: str, pilot_gone: float) -> tuple[Any, Any, list]:
    from ucat_console.backend.supervisor import Supervisor
    from ucat_console.config import AccessConfig, ConsoleConfig, FailsafeConfig, FailsafeRule, load_config
    from ucat_console.telemetry import channels as ch
    from ucat_console.ui.app import ConsoleApp

    cfg = load_config("sim-tuned").replace(
        access=AccessConfig(token=TOKEN),
        console=ConsoleConfig(port=0, record_on_arm=False),
        failsafe=FailsafeConfig(pilot_gone=FailsafeRule("hold", pilot_gone)),
    )
    sup = Supervisor(cfg, sessions_dir=tmp)
    events: list = []
    sup.stream.subscribe(lambda c, m: events.append((time.monotonic(), m)), [ch.EVENTS])
    app = ConsoleApp(sup)
    app.start()
    sup.start()
    return sup, app, events


def _wait(pred: Any, timeout: float, what: str) -> Any:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        v = pred()
        if v:
            return v
        time.sleep(0.005)
    raise TimeoutError(f"gave up waiting for {what}")


def frozen_pilot(trials: int, pilot_gone: float) -> dict[str, Any]:
    from playwright.sync_api import sync_playwright

    from ucat_console.backend.access import LOCAL
    from ucat_console.bench.chromium import Chromium

    times: list[float] = []
    with tempfile.TemporaryDirectory() as tmp:
        sup, app, events = _console(tmp, pilot_gone)
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
                        _wait(lambda: sup.access.pilot is not None, 30.0, "the page taking control")
                        if not sup.armed:
                            sup.arm(LOCAL)
                        sup.set_setpoints(LOCAL, velocity=0.2)
                        _wait(lambda: sup._last_body is not None and sup._last_body.velocity[0] > 0.05, 60.0,
                              "the robot swimming")
                        n = len(events)
                        t0 = time.monotonic()
                        chrome.freeze()
                        t_fired = _wait(lambda: next((t for t, e in events[n:] if e.source == "failsafe"
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
                sup, app, _ = _console(tmp, 2.0)
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


def takeover_under_spam(trials: int) -> dict[str, Any]:
    from ucat_console.bench.raw_page import RawPage

    times: list[float] = []
    refused = 0
    with tempfile.TemporaryDirectory() as tmp:
        sup, app, events = _console(tmp, 2.0)
        try:
            spammer = RawPage(app.url)
            spammer.wait_for("Take control")
            stop = threading.Event()

            def spam() -> None:
                while not stop.is_set():
                    try:
                        spammer.take_control("wrong-token")
                    except Exception:
                        return
                    stop.wait(0.1)

            t = threading.Thread(target=spam, daemon=True)
            t.start()
            time.sleep(3.0)  # the spammer's page locks itself, and the address counts up
            for _ in range(trials):
                page = RawPage(app.url)
                page.wait_for("Take control")
                before = sup.access.pilot
                t0 = time.monotonic()
                page.take_control(TOKEN)
                _wait(lambda: sup.access.pilot not in (None, before), 30.0, "the pilot taking control")
                times.append(time.monotonic() - t0)
                page.click("Release control")
                _wait(lambda: sup.access.pilot is None, 30.0, "the release")
                page.close()
            refused = sum(1 for _, e in events if e.source == "access" and e.code == "refused")
            stop.set()
            t.join(timeout=5.0)
            spammer.close()
        finally:
            sup.stop()
            app.stop()
    return {"trials": trials, "takeover_median_s": statistics.median(times), "takeover_max_s": max(times),
            "wrong_tokens_refused": refused}


def crowd(rounds: int, pages: int) -> dict[str, Any]:
    from ucat_console.bench.raw_page import RawPage

    broken_per_round: list[int] = []
    with tempfile.TemporaryDirectory() as tmp:
        sup, app, events = _console(tmp, 2.0)
        try:
            for r in range(rounds):
                opened: list[RawPage] = []
                lock = threading.Lock()
                start = threading.Barrier(pages)
                failed = [0]

                def connect() -> None:
                    try:
                        start.wait(timeout=60.0)
                        p = RawPage(app.url)
                        p.wait_for("Take control", timeout=120.0)
                        with lock:
                            opened.append(p)
                    except Exception:
                        with lock:
                            failed[0] += 1

                threads = [threading.Thread(target=connect) for _ in range(pages)]
                for th in threads:
                    th.start()
                for th in threads:
                    th.join(timeout=300.0)
                broken = failed[0]
                for p in opened:
                    try:
                        before = sup.access.pilot
                        p.take_control(TOKEN)
                        _wait(lambda: sup.access.pilot not in (None, before), 10.0, "taking control")
                        p.click("Release control")
                        _wait(lambda: sup.access.pilot is None, 10.0, "releasing control")
                    except Exception:
                        broken += 1
                for p in opened:
                    p.close()
                _wait(lambda: not sup.access.clients, 60.0, "the pages gone")
                broken_per_round.append(broken)
                log.info("crowd round %d: %d of %d pages broken", r + 1, broken, pages)
        finally:
            sup.stop()
            app.stop()
    return {"rounds": rounds, "pages": pages, "broken_per_round": broken_per_round,
            "broken_total": sum(broken_per_round)}


def measure(trials: int = 10, spam_trials: int = 10, rounds: int = 10, pages: int = 40,
            pilot_gone: float = 2.0, link_trials: int = 5) -> dict[str, Any]:
    from ucat_console.bench.machine import machine_info

    out: dict[str, Any] = {"machine": machine_info(None), "load_before": os.getloadavg()[0]}
    out["frozen_pilot"] = frozen_pilot(trials, pilot_gone)
    out["takeover_under_spam"] = takeover_under_spam(spam_trials)
    out["crowd"] = crowd(rounds, pages)
    out["link_loss"] = link_loss(link_trials)
    out["load_after"] = os.getloadavg()[0]
    return out


def format_result(r: dict[str, Any]) -> str:
    f, s, c = r["frozen_pilot"], r["takeover_under_spam"], r["crowd"]
    return "\n".join([
        f"frozen pilot (SIGSTOP, {f['trials']} trials, pilot_gone timeout {f['pilot_gone_timeout_s']:g} s): "
        f"failsafe after median {f['detection_median_s']:.2f} s, max {f['detection_max_s']:.2f} s",
        f"take-over while a page spams wrong tokens ({s['trials']} trials): median {s['takeover_median_s'] * 1e3:.0f} ms, "
        f"max {s['takeover_max_s'] * 1e3:.0f} ms ({s['wrong_tokens_refused']} wrong tokens refused)",
        f"pages connecting at once: {c['broken_total']} broken of {c['rounds']} x {c['pages']}",
        f"link loss ({r['link_loss']['trials']} trials): the page's banner after median "
        f"{r['link_loss']['banner_median_s']:.2f} s, max {r['link_loss']['banner_max_s']:.2f} s",
        f"load average {r['load_before']:.1f} before, {r['load_after']:.1f} after",
    ])


def register_bench(kinds: argparse._SubParsersAction) -> None:
    p = kinds.add_parser("safety", help="frozen pilot detection, take-over under token spam, simultaneous pages")
    p.add_argument("--trials", type=int, default=10, help="frozen-pilot trials (SIGSTOP on a Chromium page)")
    p.add_argument("--spam-trials", type=int, default=10, help="take-over trials under token spam")
    p.add_argument("--rounds", type=int, default=10, help="rounds of simultaneous connects")
    p.add_argument("--pages", type=int, default=40, help="pages connecting at once in each round")
    p.add_argument("--pilot-gone", type=float, default=2.0, help="failsafe.pilot_gone.timeout, s")
    p.add_argument("--link-trials", type=int, default=5, help="link-loss trials (the console stopped under a page)")
    p.add_argument("--json", type=Path, default=None, help="write the results as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    for name in ("trials", "spam_trials", "rounds", "pages", "link_trials"):
        if getattr(args, name) < 1:
            raise ValueError(f"--{name.replace('_', '-')}: must be at least 1")
    if not args.pilot_gone > 0:
        raise ValueError("--pilot-gone: must be a positive number of seconds")
    from ucat_console.cli.compiled import prepare_all

    prepare_all("sim-tuned")
    r = measure(args.trials, args.spam_trials, args.rounds, args.pages, args.pilot_gone, args.link_trials)
    print(format_result(r))
    if args.json is not None:
        args.json.write_text(json.dumps(r, indent=1))
    return 0
