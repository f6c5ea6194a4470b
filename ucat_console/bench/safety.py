"""``ucat-console bench safety``: how the console treats a frozen pilot, a token spammer and
a crowd of pages, measured against ``ucat-console run`` on the simulated robot.

* **Frozen pilot**: a headless Chromium page takes control, the robot is armed and swims at
  0.2 m/s, then every process of the browser is stopped (SIGSTOP). Detection time: from
  the stop to the ``pilot_gone`` failsafe event (wall clock). docs/performance.md states the goal:
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
* **Disarm under spam**: the sessions folder holds ``--sessions`` copies of a recorded
  ``--session-seconds`` s session (the simulated robot, swimming); the pilot (a raw page) arms
  the robot swimming at 0.2 m/s while ``--spammers`` raw viewers click Review's "Refresh list"
  ``--spam-rate`` times a second each (within the page guard's message rate) and press the
  pilot's controls of their own pages. After ``--spam-before`` s of it the pilot presses
  DISARM: the disarm delay is from sending the press to the supervisor disarmed. Also the
  plans that missed their hand-over (``plan_overruns``) during the spam, against as long
  without it. The goal: within 0.5 s.
* **Slow link**: the pilot's raw page reads 50 kB/s (``--slow-rate``) while the robot swims
  and the live view sends at its configured rates: whether it stays the pilot for
  ``--slow-seconds`` s, its heartbeats' round trips (the console's own measure) and whether
  its status bar says "link slow".

Figures depend on the machine and its load (reported with them); they are for docs/performance.md,
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
                        # the last trial's failsafe clears once the supervisor sees the new pilot
                        _wait(lambda: not any(s.active for s in sup.safety.states() if s.name == "pilot_gone"),
                              30.0, "the last trial's pilot_gone failsafe cleared")
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


def _sessions_folder(directory: Path, copies: int, seconds: float) -> dict[str, Any]:
    """``copies`` copies of one recorded session of ``seconds`` s (the simulated robot
    swimming at 0.2 m/s, on its simulated clock) in ``directory``; its size and the time
    one listing of the folder takes."""
    import shutil

    from ucat_console.backend.access import LOCAL
    from ucat_console.backend.loop.clock import SimulatedClock
    from ucat_console.backend.sessions import files, index
    from ucat_console.backend.supervisor import Supervisor

    rec = directory / "recording"
    sup = Supervisor(_config(), clock=SimulatedClock(), sessions_dir=rec)
    try:
        sup.set_setpoints(LOCAL, velocity=0.2)
        sup.start_recording(LOCAL, "disarm-under-spam bench")
        sup.arm(LOCAL)
        sup.step(seconds)
        [path] = sup.stop_recording(LOCAL)
    finally:
        sup.stop()
    size = path.stat().st_size
    for k in range(copies):
        shutil.copy(path, directory / files.part_name(f"bench-{k:03d}", 1))
    shutil.rmtree(rec)
    t0 = time.perf_counter()
    index.list_sessions(directory)
    return {"copies": copies, "session_s": seconds, "file_bytes": size, "listing_s": time.perf_counter() - t0}


def _config() -> Any:
    from ucat_console.config import load_config

    return load_config("sim-tuned")


def _pilot(app: Any, sup: Any, **kw: Any) -> Any:
    from ucat_console.bench.raw_page import RawPage

    page = RawPage(app.url, **kw)
    page.wait_for("Take control", timeout=120.0)
    before = sup.access.pilot
    page.take_control(TOKEN)
    _wait(lambda: sup.access.pilot not in (None, before), 60.0, "the pilot taking control")
    return page


def disarm_under_spam(trials: int, copies: int = 23, session_seconds: float = 60.0, spammers: int = 1,
                      rate: float = 20.0, before: float = 5.0) -> dict[str, Any]:
    from ucat_console.backend.access import LOCAL
    from ucat_console.bench.raw_page import RawPage

    delays: list[float] = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = _sessions_folder(Path(tmp), copies, session_seconds)
        sup, app, events = _console(tmp, 2.0)
        stop = threading.Event()
        threads: list[threading.Thread] = []
        try:
            pilot = _pilot(app, sup)
            disarm = pilot.wait_for("DISARM", "GuiButtonMessage")
            pages = [RawPage(app.url) for _ in range(spammers)]

            def spam(page: RawPage) -> None:
                refresh = page.wait_for("Refresh list", "GuiButtonMessage", timeout=120.0)
                own = [page.wait_for(label, "GuiButtonMessage", timeout=120.0)
                       for label in ("Arm motors", "DISARM", "Apply setpoints")]
                k = 0
                while not stop.is_set():
                    try:
                        page.update(refresh, value=True)
                        if k % 4 == 0:
                            for uuid in own:
                                page.update(uuid, value=True)
                    except Exception:
                        return
                    k += 1
                    stop.wait(1.0 / rate)

            sup.arm(LOCAL)
            sup.set_setpoints(LOCAL, velocity=0.2)
            time.sleep(before)  # as long without the spam
            quiet_overruns = sup.health().plan_overruns
            sup.disarm(LOCAL)
            overruns0 = sup.health().plan_overruns
            t_spam = time.monotonic()
            for page in pages:
                threads.append(threading.Thread(target=spam, args=(page,), daemon=True))
                threads[-1].start()
            for trial in range(trials):
                sup.arm(LOCAL)
                time.sleep(before)  # the spam going on
                t0 = time.monotonic()
                pilot.update(disarm, value=True)
                _wait(lambda: not sup.armed, 120.0, "the pilot's disarm")
                delays.append(time.monotonic() - t0)
                log.info("disarm under spam, trial %d: %.3f s", trial + 1, delays[-1])
            spam_s = time.monotonic() - t_spam
            spam_overruns = sup.health().plan_overruns - overruns0
            jobs_done, jobs_refused = app.jobs.done, app.jobs.refused
        finally:
            stop.set()
            for t in threads:
                t.join(timeout=10.0)
            sup.stop()
            app.stop()
    return {"trials": trials, "folder": folder, "spammers": spammers, "spam_rate_hz": rate,
            "delay_median_s": statistics.median(delays), "delay_max_s": max(delays), "delays_s": delays,
            "spam_s": spam_s, "plan_overruns_during_spam": spam_overruns,
            "plan_overruns_before_spam": quiet_overruns, "quiet_s": before,
            "jobs_run": jobs_done, "jobs_refused": jobs_refused}


def slow_link(rate: float = 50_000.0, seconds: float = 60.0) -> dict[str, Any]:
    from ucat_console.backend.access import LOCAL

    with tempfile.TemporaryDirectory() as tmp:
        sup, app, events = _console(tmp, 2.0)
        try:
            pilot = _pilot(app, sup)
            cid = sup.access.pilot
            sup.arm(LOCAL)
            sup.set_setpoints(LOCAL, velocity=0.2)
            time.sleep(2.0)  # the live view at full traffic
            n = len(events)
            pilot.read_rate = rate
            read0, t0 = pilot.bytes_read, time.monotonic()
            rtts: list[float] = []
            slow_seen = 0.0
            while time.monotonic() - t0 < seconds and sup.access.pilot == cid:
                state = app.guard.link_state(cid)
                if state is not None and state["answers"]:
                    rtts.append(state["rtt"])
                if pilot.bar.get("link_slow") and not slow_seen:
                    slow_seen = time.monotonic() - t0
                time.sleep(0.25)
            stayed = sup.access.pilot == cid
            held = time.monotonic() - t0
            read = pilot.bytes_read - read0
            gone = [e.message for _, e in events[n:] if e.code in ("pilot_gone", "pilot_left")]
            pilot.close()
        finally:
            sup.stop()
            app.stop()
    return {"rate_bytes_s": rate, "seconds": seconds, "stayed_pilot": stayed, "pilot_for_s": held,
            "read_bytes_s": read / held, "rtt_median_s": statistics.median(rtts) if rtts else None,
            "rtt_max_s": max(rtts) if rtts else None, "link_slow_shown_after_s": slow_seen or None,
            "gone_events": gone}


PARTS = ("frozen", "takeover", "crowd", "link-loss", "spam", "slow-link")


def measure(trials: int = 10, spam_trials: int = 10, rounds: int = 10, pages: int = 40,
            pilot_gone: float = 2.0, link_trials: int = 5, parts: tuple[str, ...] = PARTS,
            disarm_trials: int = 5, copies: int = 23, session_seconds: float = 60.0, spammers: int = 1,
            spam_rate: float = 20.0, spam_before: float = 5.0, slow_rate: float = 50_000.0,
            slow_seconds: float = 60.0) -> dict[str, Any]:
    from ucat_console.bench.machine import machine_info

    out: dict[str, Any] = {"machine": machine_info(None), "load_before": os.getloadavg()[0]}
    if "frozen" in parts:
        out["frozen_pilot"] = frozen_pilot(trials, pilot_gone)
    if "takeover" in parts:
        out["takeover_under_spam"] = takeover_under_spam(spam_trials)
    if "crowd" in parts:
        out["crowd"] = crowd(rounds, pages)
    if "link-loss" in parts:
        out["link_loss"] = link_loss(link_trials)
    if "spam" in parts:
        out["disarm_under_spam"] = disarm_under_spam(disarm_trials, copies, session_seconds, spammers,
                                                     spam_rate, spam_before)
    if "slow-link" in parts:
        out["slow_link"] = slow_link(slow_rate, slow_seconds)
    out["load_after"] = os.getloadavg()[0]
    return out


def format_result(r: dict[str, Any]) -> str:
    lines = []
    if "frozen_pilot" in r:
        f = r["frozen_pilot"]
        lines.append(f"frozen pilot (SIGSTOP, {f['trials']} trials, pilot_gone timeout {f['pilot_gone_timeout_s']:g} s): "
                     f"failsafe after median {f['detection_median_s']:.2f} s, max {f['detection_max_s']:.2f} s")
    if "takeover_under_spam" in r:
        s = r["takeover_under_spam"]
        lines.append(f"take-over while a page spams wrong tokens ({s['trials']} trials): median "
                     f"{s['takeover_median_s'] * 1e3:.0f} ms, max {s['takeover_max_s'] * 1e3:.0f} ms "
                     f"({s['wrong_tokens_refused']} wrong tokens refused)")
    if "crowd" in r:
        c = r["crowd"]
        lines.append(f"pages connecting at once: {c['broken_total']} broken of {c['rounds']} x {c['pages']}")
    if "link_loss" in r:
        x = r["link_loss"]
        lines.append(f"link loss ({x['trials']} trials): the page's banner after median "
                     f"{x['banner_median_s']:.2f} s, max {x['banner_max_s']:.2f} s")
    if "disarm_under_spam" in r:
        d = r["disarm_under_spam"]
        f = d["folder"]
        lines.append(
            f"disarm under spam ({d['trials']} trials; {d['spammers']} viewer(s) clicking Refresh list "
            f"{d['spam_rate_hz']:g}/s; {f['copies']} sessions of {f['session_s']:g} s, {f['file_bytes'] / 1e6:.1f} MB "
            f"each, one listing {f['listing_s']:.2f} s): DISARM applied after median {d['delay_median_s'] * 1e3:.0f} ms, "
            f"max {d['delay_max_s'] * 1e3:.0f} ms; plan overruns {d['plan_overruns_during_spam']} in "
            f"{d['spam_s']:.0f} s of spam ({d['plan_overruns_before_spam']} in {d['quiet_s']:g} s without); "
            f"{d['jobs_run']} page jobs run, {d['jobs_refused']} refused")
    if "slow_link" in r:
        x = r["slow_link"]
        rtt = (f"heartbeat round trip median {x['rtt_median_s']:.2f} s, max {x['rtt_max_s']:.2f} s"
               if x["rtt_median_s"] is not None else "no heartbeat answered")
        shown = (f"'link slow' shown after {x['link_slow_shown_after_s']:.1f} s" if x["link_slow_shown_after_s"]
                 else "'link slow' never shown")
        lines.append(f"pilot reading {x['rate_bytes_s'] / 1e3:g} kB/s: "
                     f"{'stayed the pilot' if x['stayed_pilot'] else 'LOST the pilot'} for {x['pilot_for_s']:.0f} s "
                     f"(read {x['read_bytes_s'] / 1e3:.0f} kB/s); {rtt}; {shown}")
    lines.append(f"load average {r['load_before']:.1f} before, {r['load_after']:.1f} after")
    return "\n".join(lines)


def register_bench(kinds: argparse._SubParsersAction) -> None:
    p = kinds.add_parser("safety", help="frozen pilot detection, take-over under token spam, simultaneous pages, "
                                        "link loss, DISARM under a viewer's spam, a pilot on a slow link")
    p.add_argument("--trials", type=int, default=10, help="frozen-pilot trials (SIGSTOP on a Chromium page)")
    p.add_argument("--spam-trials", type=int, default=10, help="take-over trials under token spam")
    p.add_argument("--rounds", type=int, default=10, help="rounds of simultaneous connects")
    p.add_argument("--pages", type=int, default=40, help="pages connecting at once in each round")
    p.add_argument("--pilot-gone", type=float, default=2.0, help="failsafe.pilot_gone.timeout, s")
    p.add_argument("--link-trials", type=int, default=5, help="link-loss trials (the console stopped under a page)")
    p.add_argument("--parts", nargs="+", choices=PARTS, default=list(PARTS), help="which measures to run")
    p.add_argument("--disarm-trials", type=int, default=5, help="DISARM presses under spam")
    p.add_argument("--sessions", type=int, default=23, help="sessions in the folder the spam lists")
    p.add_argument("--session-seconds", type=float, default=60.0, help="length of each of those sessions, s")
    p.add_argument("--spammers", type=int, default=1, help="viewers clicking Refresh list")
    p.add_argument("--spam-rate", type=float, default=20.0, help="clicks a second of each viewer")
    p.add_argument("--spam-before", type=float, default=5.0, help="seconds of spam before each DISARM")
    p.add_argument("--slow-rate", type=float, default=50_000.0, help="the slow pilot's reading rate, bytes/s")
    p.add_argument("--slow-seconds", type=float, default=60.0, help="how long the slow pilot is watched, s")
    p.add_argument("--json", type=Path, default=None, help="write the results as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    for name in ("trials", "spam_trials", "rounds", "pages", "link_trials", "disarm_trials", "sessions",
                 "spammers"):
        if getattr(args, name) < 1:
            raise ValueError(f"--{name.replace('_', '-')}: must be at least 1")
    for name in ("pilot_gone", "session_seconds", "spam_rate", "slow_rate", "slow_seconds"):
        if not getattr(args, name) > 0:
            raise ValueError(f"--{name.replace('_', '-')}: must be a positive number")
    if not args.spam_rate <= 100.0:
        raise ValueError("--spam-rate: at most 100 clicks a second (the page guard allows 120 messages)")
    if args.spam_before < 0:
        raise ValueError("--spam-before: must not be negative")
    from ucat_console.cli.compiled import prepare_all

    prepare_all("sim-tuned")
    r = measure(args.trials, args.spam_trials, args.rounds, args.pages, args.pilot_gone, args.link_trials,
                tuple(args.parts), args.disarm_trials, args.sessions, args.session_seconds, args.spammers,
                args.spam_rate, args.spam_before, args.slow_rate, args.slow_seconds)
    print(format_result(r))
    if args.json is not None:
        args.json.write_text(json.dumps(r, indent=1))
    return 0
