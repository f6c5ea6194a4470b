"""``ucat-console bench safety``: how the console treats a frozen pilot, a token spammer and
a crowd of pages, measured against ``ucat-console run`` on the simulated robot.

* **Take-over under spam**: a raw page sends a wrong token every 0.1 s; another raw page
  from the same address presents the right one. Take-over time: from sending the token
  to being the pilot.
* **Crowd**: rounds of pages connecting at the same moment; a page is broken when it does
  not get its controls or its *Take control* does not make it the pilot.
* **Disarm under spam**: the sessions folder holds ``--sessions`` copies of a recorded
  ``--session-seconds`` s session (the simulated robot, swimming); the pilot (a raw page) arms
  the robot swimming at 0.2 m/s while ``--spammers`` raw viewers click Review's "Refresh list"
  ``--spam-rate`` times a second each (within the page guard's message rate) and press the
  pilot's controls of their own pages. After ``--spam-before`` s of it the pilot presses
  DISARM: the disarm delay is from sending the press to the supervisor disarmed. Also the
  plans that missed their hand-over (``plan_overruns``) during the spam, against as long
  without it. The goal: within 0.5 s.
* **Pilot's link dropped while a request waits**: the pilot (a raw page) flies, armed at
  0.2 m/s; another raw page asks it for control with the token and sits idle; then the
  pilot's page stops reading and answering (a dropped link, TCP left open). Who flies once
  the console has seen the pilot gone (nobody: a request never takes control by waiting),
  whether the ``pilot_gone`` failsafe triggered, and the time from the drop to its hold.
  Then the operator comes back on a new page with the token: the time from sending the
  token to the page showing it flies, and from its DISARM press to the robot disarmed.
* **Hand-over**: a new raw page asks the pilot for control; the pilot presses *Hand over*.
  The time from that press to the new pilot's page showing it flies, and to its first
  command (a velocity, applied with *Apply setpoints*) in force in the supervisor.
* **Slow link**: the pilot's raw page reads 50 kB/s (``--slow-rate``) while the robot swims
  and the live view sends at its configured rates: whether it stays the pilot for
  ``--slow-seconds`` s, its heartbeats' round trips (the console's own measure) and whether
  its status bar says "link slow".

The measures in headless Chromium (a frozen pilot, link loss, a slow link's connect and
DISARM, restarts) are in :mod:`.safety_browser`, the failsafe triggers in
:mod:`.safety_failsafes`, what they share in :mod:`.safety_console`.

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

from ucat_console.bench.safety_browser import frozen_pilot, link_loss, restarts, slow_connect, slow_disarm
from ucat_console.bench.safety_console import TOKEN, event_time, sim_tuned, start_console, take_pilot, wait_until
from ucat_console.bench.safety_failsafes import failsafe_triggers

log = logging.getLogger(__name__)

def takeover_under_spam(trials: int) -> dict[str, Any]:
    from ucat_console.bench.raw_page import RawPage

    times: list[float] = []
    refused = 0
    with tempfile.TemporaryDirectory() as tmp:
        sup, app, events = start_console(tmp, 2.0)
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
                wait_until(lambda: sup.access.pilot not in (None, before), 30.0, "the pilot taking control")
                times.append(time.monotonic() - t0)
                page.click("Release control")
                wait_until(lambda: sup.access.pilot is None, 30.0, "the release")
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
        sup, app, events = start_console(tmp, 2.0, pages=pages + 1)
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
                        wait_until(lambda: sup.access.pilot not in (None, before), 10.0, "taking control")
                        p.click("Release control")
                        wait_until(lambda: sup.access.pilot is None, 10.0, "releasing control")
                    except Exception:
                        broken += 1
                for p in opened:
                    p.close()
                wait_until(lambda: not sup.access.clients, 60.0, "the pages gone")
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
    sup = Supervisor(sim_tuned(), clock=SimulatedClock(), sessions_dir=rec)
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


def disarm_under_spam(trials: int, copies: int = 23, session_seconds: float = 60.0, spammers: int = 1,
                      rate: float = 20.0, before: float = 5.0) -> dict[str, Any]:
    from ucat_console.backend.access import LOCAL
    from ucat_console.bench.raw_page import RawPage

    delays: list[float] = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = _sessions_folder(Path(tmp), copies, session_seconds)
        sup, app, events = start_console(tmp, 2.0)
        stop = threading.Event()
        threads: list[threading.Thread] = []
        try:
            pilot = take_pilot(app, sup)
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
                wait_until(lambda: not sup.armed, 120.0, "the pilot's disarm")
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
        sup, app, events = start_console(tmp, 2.0)
        try:
            pilot = take_pilot(app, sup)
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


def pilot_drop(trials: int, pilot_gone: float) -> dict[str, Any]:
    from ucat_console.backend.access import LOCAL
    from ucat_console.bench.raw_page import RawPage

    runs: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        sup, app, events = start_console(tmp, pilot_gone)
        try:
            for trial in range(trials):
                a = take_pilot(app, sup)
                a_id = sup.access.pilot
                wait_until(lambda: not sup.safety.active(), 30.0, "the last trial's failsafe cleared")
                sup.arm(LOCAL)
                sup.set_setpoints(LOCAL, velocity=0.2)
                wait_until(lambda: sup._last_body is not None and sup._last_body.velocity[0] > 0.05, 60.0,
                      "the robot swimming")
                b = RawPage(app.url)
                b.wait_for("Take control", timeout=120.0)
                b.take_control(TOKEN)
                b_id = wait_until(lambda: sup.access.pending, 30.0, "the request for control")
                n = len(events)
                t0 = time.monotonic()
                a.answer_heartbeats = False  # the pilot's link drops
                a.stop_reading()
                if event_time(events, n, "access", "pilot_left", pilot_gone + 30.0) is None:
                    raise TimeoutError("the console never saw the pilot's page gone")
                pilot = sup.access.pilot
                t_hold = event_time(events, n, "failsafe", "pilot_gone", pilot_gone + 2.0)
                try:
                    held = t_hold is not None and wait_until(lambda: sup.setpoints.velocity == 0.0, 5.0, "the hold")
                except TimeoutError:
                    held = False
                run: dict[str, Any] = {
                    "pilot_after": "nobody" if pilot is None else "the waiting page" if pilot == b_id
                    else f"client {pilot}",
                    "failsafe": t_hold is not None, "hold_s": None if t_hold is None else t_hold - t0,
                    "held": held and sup.armed,
                }
                c = RawPage(app.url)  # the operator, back with the token
                c.wait_for("Take control", timeout=120.0)
                n = len(events)
                t1 = time.monotonic()
                c.take_control(TOKEN)
                try:
                    wait_until(lambda: c.bar.get("you_pilot"), 10.0, "the returning operator's page flying")
                except TimeoutError:
                    run.update(control_s=None, disarm_s=None)
                    sup.disarm(LOCAL)
                else:
                    t2 = time.monotonic()
                    c.update(c.bar["disarm_uuid"], value=True)
                    t3 = event_time(events, n, "supervisor", "disarmed", 30.0)
                    run.update(control_s=t2 - t1, disarm_s=None if t3 is None else t3 - t2)
                runs.append(run)
                log.info("pilot drop trial %d: %s", trial + 1, run)
                wait_until(lambda: not sup.armed, 30.0, "the robot disarmed")
                if sup.access.pilot is not None:
                    sup.release(sup.access.pilot)
                for p in (a, b, c):
                    p.close()
                wait_until(lambda: a_id not in sup.access.clients, 60.0, "the dropped page gone")
        finally:
            sup.stop()
            app.stop()
    done = [r for r in runs if r["hold_s"] is not None]
    took = [r for r in runs if r["disarm_s"] is not None]
    return {"trials": trials, "pilot_gone_timeout_s": pilot_gone,
            "pilot_after": sorted({r["pilot_after"] for r in runs}),
            "failsafe_triggered": sum(r["failsafe"] for r in runs), "held": sum(r["held"] for r in runs),
            "hold_median_s": statistics.median(r["hold_s"] for r in done) if done else None,
            "hold_max_s": max(r["hold_s"] for r in done) if done else None,
            "control_median_s": statistics.median(r["control_s"] for r in took) if took else None,
            "disarm_median_s": statistics.median(r["disarm_s"] for r in took) if took else None,
            "disarm_max_s": max(r["disarm_s"] for r in took) if took else None,
            "runs": runs}


def handover(trials: int) -> dict[str, Any]:
    from ucat_console.backend.access import LOCAL
    from ucat_console.bench.raw_page import RawPage

    to_page: list[float] = []
    to_command: list[float] = []
    with tempfile.TemporaryDirectory() as tmp:
        sup, app, events = start_console(tmp, 2.0)
        try:
            pilot = take_pilot(app, sup)
            sup.arm(LOCAL)
            sup.set_setpoints(LOCAL, velocity=0.1)
            for trial in range(trials):
                asker = RawPage(app.url)
                asker.wait_for("Take control", timeout=120.0)
                asker.take_control(TOKEN)
                asker_id = wait_until(lambda: sup.access.pending, 30.0, "the request for control")
                accept = pilot.wait_for(f"Hand over to client {asker_id}", "GuiButtonMessage")
                wait_until(lambda: pilot.element(accept).get("visible"), 30.0, "the pilot's page showing the request")
                velocity = 0.2 if trial % 2 == 0 else 0.1
                t0 = time.monotonic()
                pilot.update(accept, value=True)
                wait_until(lambda: asker.bar.get("you_pilot"), 30.0, "the new pilot's page flying")
                to_page.append(time.monotonic() - t0)
                asker.set_value("Velocity m/s", velocity)
                asker.click("Apply setpoints")
                wait_until(lambda: sup.setpoints.velocity == velocity, 30.0, "the new pilot's setpoint in force")
                to_command.append(time.monotonic() - t0)
                log.info("hand-over trial %d: the new pilot's page after %.3f s, its command after %.3f s",
                         trial + 1, to_page[-1], to_command[-1])
                pilot.close()
                pilot = asker
            pilot.close()
        finally:
            sup.stop()
            app.stop()
    return {"trials": trials, "page_median_s": statistics.median(to_page), "page_max_s": max(to_page),
            "command_median_s": statistics.median(to_command), "command_max_s": max(to_command),
            "page_s": to_page, "command_s": to_command}


PARTS = ("frozen", "takeover", "crowd", "link-loss", "spam", "slow-link", "drop", "handover",
         "slow-connect", "slow-disarm", "restart", "failsafes")


def measure(trials: int = 10, spam_trials: int = 10, rounds: int = 10, pages: int = 40,
            pilot_gone: float = 2.0, link_trials: int = 5, parts: tuple[str, ...] = PARTS,
            disarm_trials: int = 5, copies: int = 23, session_seconds: float = 60.0, spammers: int = 1,
            spam_rate: float = 20.0, spam_before: float = 5.0, slow_rate: float = 50_000.0,
            slow_seconds: float = 60.0, drop_trials: int = 5, handover_trials: int = 10,
            connect_delay: float = 1.0, connect_trials: int = 3, disarm_delay: float = 0.6,
            slow_disarm_trials: int = 5, restart_count: int = 10, spinners: int = 2,
            failsafe_trials: int = 5) -> dict[str, Any]:
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
    if "drop" in parts:
        out["pilot_drop"] = pilot_drop(drop_trials, pilot_gone)
    if "handover" in parts:
        out["handover"] = handover(handover_trials)
    if "slow-connect" in parts:
        out["slow_connect"] = slow_connect(connect_delay, connect_trials)
    if "slow-disarm" in parts:
        out["slow_disarm"] = slow_disarm(disarm_delay, slow_disarm_trials)
    if "restart" in parts:
        out["restart"] = restarts(restart_count, spinners)
    if "failsafes" in parts:
        out["failsafes"] = failsafe_triggers(failsafe_trials)
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
    if "pilot_drop" in r:
        x = r["pilot_drop"]
        hold = (f"hold after median {x['hold_median_s']:.2f} s, max {x['hold_max_s']:.2f} s"
                if x["hold_median_s"] is not None else "no hold")
        back = (f"the token back in control after median {x['control_median_s'] * 1e3:.0f} ms, its DISARM "
                f"applied after median {x['disarm_median_s'] * 1e3:.1f} ms, max {x['disarm_max_s'] * 1e3:.1f} ms"
                if x["disarm_median_s"] is not None else "the token did NOT take control back")
        lines.append(f"pilot's link dropped while a page waits for its hand-over ({x['trials']} trials, pilot_gone "
                     f"timeout {x['pilot_gone_timeout_s']:g} s): pilot after: {', '.join(x['pilot_after'])}; "
                     f"failsafe in {x['failsafe_triggered']} of {x['trials']}, {hold}; {back}")
    if "handover" in r:
        x = r["handover"]
        lines.append(f"hand-over accepted ({x['trials']} trials): the new pilot's page flying after median "
                     f"{x['page_median_s'] * 1e3:.0f} ms, its first command in force after median "
                     f"{x['command_median_s'] * 1e3:.0f} ms, max {x['command_max_s'] * 1e3:.0f} ms")
    if "slow_connect" in r:
        x = r["slow_connect"]
        lines.append(f"a page through {x['delay_each_way_s']:g} s each way ({x['trials']} trials): loaded after median "
                     f"{x['loaded_median_s']:.1f} s, its socket open after median {x['socket_median_s']:.1f} s, "
                     f"max {x['socket_max_s']:.1f} s, its first state after median {x['connect_median_s']:.1f} s, "
                     f"max {x['connect_max_s']:.1f} s; the pilot "
                     f"{x['control_median_s']:.1f} s (median) after Take control")
    if "slow_disarm" in r:
        x = r["slow_disarm"]
        applied = (f"after median {x['disarm_median_s']:.2f} s, max {x['disarm_max_s']:.2f} s"
                   if x["applied"] else "")
        lines.append(f"DISARM through {x['delay_each_way_s']:g} s each way: applied {x['applied']} of "
                     f"{x['trials']} {applied}".rstrip())
        if x.get("disarmed_otherwise"):
            lines.append(f"  disarmed before the click's DISARM arrived: {', '.join(x['disarmed_otherwise'])}")
    if "restart" in r:
        x = r["restart"]
        lines.append(f"console restarted {x['restarts']} times under {x['spinners']} spinning processes: the "
                     f"pilot's page the pilot again {x['back']} of {x['restarts']} times, after median "
                     f"{x['from_up_median_s']:.1f} s, max {x['from_up_max_s']:.1f} s from the console serving "
                     f"(median {x['from_stop_median_s']:.1f} s, max {x['from_stop_max_s']:.1f} s from the stop)")
    if "failsafes" in r:
        x = r["failsafes"]
        for name, f in x["triggers"].items():
            lines.append(f"failsafe {name} ({x['trials']} trials, timeout {f['timeout_s']:g} s, {f['action']}): "
                         f"detection to action beyond the timeout median {f['median_s'] * 1e3:.0f} ms, "
                         f"p99 {f['p99_s'] * 1e3:.0f} ms, max {f['max_s'] * 1e3:.0f} ms")
    lines.append(f"load average {r['load_before']:.1f} before, {r['load_after']:.1f} after")
    return "\n".join(lines)


def register_bench(kinds: argparse._SubParsersAction) -> None:
    p = kinds.add_parser("safety", help="frozen pilot detection, take-over under token spam, simultaneous pages, "
                                        "link loss, DISARM under a viewer's spam, a pilot on a slow link, the "
                                        "pilot's link dropped while a page waits for control, a hand-over")
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
    p.add_argument("--drop-trials", type=int, default=5,
                   help="trials of the pilot's link dropping while a page waits for its hand-over")
    p.add_argument("--handover-trials", type=int, default=10, help="hand-overs accepted by the pilot")
    p.add_argument("--connect-delay", type=float, default=1.0,
                   help="slow-connect: the link's delay each way, s (1.0: a 2 s round trip)")
    p.add_argument("--connect-trials", type=int, default=3, help="slow-connect: pages connected")
    p.add_argument("--disarm-delay", type=float, default=0.6, help="slow-disarm: the link's delay each way, s")
    p.add_argument("--slow-disarm-trials", type=int, default=5, help="slow-disarm: DISARM presses")
    p.add_argument("--restarts", type=int, default=10, help="restart: restarts of the console")
    p.add_argument("--spinners", type=int, default=2, help="restart: processes spinning meanwhile")
    p.add_argument("--failsafe-trials", type=int, default=5, help="causes of each new failsafe on the emulated rig")
    p.add_argument("--json", type=Path, default=None,
                   help="write the results as JSON (into the file's other parts' results when only some parts run)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    for name in ("trials", "spam_trials", "rounds", "pages", "link_trials", "disarm_trials", "sessions",
                 "spammers", "drop_trials", "handover_trials", "connect_trials", "slow_disarm_trials", "restarts",
                 "failsafe_trials"):
        if getattr(args, name) < 1:
            raise ValueError(f"--{name.replace('_', '-')}: must be at least 1")
    if args.spinners < 0:
        raise ValueError("--spinners: must not be negative")
    for name in ("pilot_gone", "session_seconds", "spam_rate", "slow_rate", "slow_seconds", "connect_delay",
                 "disarm_delay"):
        if not getattr(args, name) > 0:
            raise ValueError(f"--{name.replace('_', '-')}: must be a positive number")
    if not args.spam_rate <= 100.0:
        raise ValueError("--spam-rate: at most 100 clicks a second (the page guard allows 120 messages)")
    if args.spam_before < 0:
        raise ValueError("--spam-before: must not be negative")
    from ucat_console.compiled import prepare_all

    prepare_all("sim-tuned")
    r = measure(args.trials, args.spam_trials, args.rounds, args.pages, args.pilot_gone, args.link_trials,
                tuple(args.parts), args.disarm_trials, args.sessions, args.session_seconds, args.spammers,
                args.spam_rate, args.spam_before, args.slow_rate, args.slow_seconds, args.drop_trials,
                args.handover_trials, args.connect_delay, args.connect_trials, args.disarm_delay,
                args.slow_disarm_trials, args.restarts, args.spinners, args.failsafe_trials)
    print(format_result(r))
    if args.json is not None:
        if set(args.parts) != set(PARTS) and args.json.exists():  # the other parts' results stay
            run_of = ("machine", "load_before", "load_after")  # this run's, kept beside the file's
            r = {**json.loads(args.json.read_text()), **{k: v for k, v in r.items() if k not in run_of},
                 **{f"{k}_{'_'.join(args.parts)}": r[k] for k in run_of}}
        args.json.write_text(json.dumps(r, indent=1))
    return 0
