"""``ucat-console bench load``: the simulated robot behind its device emulators (real drivers,
the shipped ``sim-devices``) swimming under CPU load, and its recovery when the load ends.

Child processes that spin (:class:`CpuLoad`) keep the machine's load average up for
``--minutes``; the robot is armed and swims at 0.2 m/s throughout (armed again if anything
disarmed it). Nothing is injected, so every drive fault, sensor fault and failsafe counted
is a spurious one: the busy machine faking it. The loop's lag behind the wall clock is
sampled every 0.1 s, during the load and for ``--after`` s after it, for the time it takes
to come back under 100 ms.

Figures depend on the machine and its load (reported with them); they are for the docs,
never test assertions (``tests/backend/test_load.py`` runs a short version and counts the
faults only).
"""

from __future__ import annotations

import argparse
import collections
import json
import logging
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

#: the lag the loop must come back under after the load (s)
LAG_GOAL = 0.1
#: the load average the machine is to be held at (the goal's "load average >= 8")
LOAD_GOAL = 8.0
#: levels of a device event that count as a fault
FAULT_LEVELS = ("error", "fatal")
SENSORS = ("imu", "dvl", "pressure")


#: a child that spins until stopped or until its parent is gone (the parent killed before it
#: could stop it: the spinning ends within about a second)
_SPIN = """
import os, sys
parent = int(sys.argv[1])  # given: the parent may be gone before this line runs
while os.getppid() == parent:
    for _ in range(1_000_000):
        pass
"""


class CpuLoad:
    """``n`` child processes that spin until stopped (each ended by its own id) or until this
    process is gone."""

    def __init__(self, n: int) -> None:
        if n < 0:
            raise ValueError(f"n: {n} must be >= 0")
        self.n = n
        self._procs: list[subprocess.Popen] = []

    def start(self) -> CpuLoad:
        for _ in range(self.n):
            self._procs.append(subprocess.Popen([sys.executable, "-c", _SPIN, str(os.getpid())],
                                                stdin=subprocess.DEVNULL))
        return self

    def stop(self) -> None:
        procs, self._procs = self._procs, []
        for p in procs:
            p.kill()
        for p in procs:
            p.wait()

    def __enter__(self) -> CpuLoad:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


def rig_config(sessions: str) -> Any:
    """The emulated rig as the console ships it, drives powered only while armed, no
    automatic recording."""
    from ucat_console.config import load_config

    cfg = load_config("sim-devices")
    return cfg.replace(devices=cfg.devices.replace(enable_at_start=False),
                       console=cfg.console.replace(record_on_arm=False, sessions_dir=sessions))


class EventCount:
    """The faults the stream carries: drive and sensor faults, failsafes, by kind."""

    def __init__(self) -> None:
        self.by: collections.Counter[tuple[str, str]] = collections.Counter()
        self.faults: list[Any] = []

    def __call__(self, channel: str, ev: Any) -> None:
        self.by[(ev.source, ev.code)] += 1
        if self.is_fault(ev):
            self.faults.append(ev)

    @staticmethod
    def is_fault(ev: Any) -> bool:
        from ucat_console.backend.safety import failsafe_names

        device = ev.source.startswith("epos2") or ev.source in SENSORS
        # the tracking alarm judges the control (a start from rest may lag its reference),
        # not a device or the timing: counted in ``events``, not as a fault
        judged = ev.source == "failsafe" and ev.code in failsafe_names() and ev.code != "tracking"
        return (device and ev.level in FAULT_LEVELS) or judged

    def drive_faults(self) -> int:
        return sum(1 for e in self.faults if e.source.startswith("epos2"))

    def sensor_faults(self) -> int:
        return sum(1 for e in self.faults if e.source in SENSORS)

    def failsafes(self) -> int:
        return sum(1 for e in self.faults if e.source == "failsafe")


def swim_under_load(load_s: float, after_s: float, hogs: int, *, settle_s: float = 3.0,
                    velocity: float = 0.2, sample_s: float = 0.1,
                    progress: Any = None) -> dict[str, Any]:
    """Arm the emulated rig, swim at ``velocity``, load the machine with ``hogs`` spinning
    processes for ``load_s`` s, then watch ``after_s`` s more. Faults counted, lag sampled."""
    from ucat_console.backend.access import LOCAL
    from ucat_console.backend.supervisor import CommandRefused, Supervisor
    from ucat_console.telemetry import channels as ch

    count = EventCount()
    lags: list[tuple[float, float]] = []  # (s since the load ended (negative: during), lag)
    loads: list[tuple[float, float]] = []  # (s since the load began, 1-minute load average)
    rearmed = 0
    with tempfile.TemporaryDirectory() as tmp:
        sup = Supervisor(rig_config(tmp))
        sup.stream.subscribe(count, [ch.EVENTS])
        sup.start()
        try:
            deadline = time.monotonic() + 30.0
            while sup.loop.time < settle_s and time.monotonic() < deadline:
                time.sleep(0.05)
            sup.set_setpoints(LOCAL, velocity=velocity)
            sup.arm(LOCAL)
            load = CpuLoad(hogs).start()
            t_load = time.monotonic()
            t_end = t_load + load_s
            next_report = t_load
            try:
                while True:
                    now = time.monotonic()
                    if load is not None and now >= t_end:
                        load.stop()
                        load = None
                    if now >= t_end + after_s:
                        break
                    lags.append((now - t_end, time.perf_counter() - sup.clock.wall_deadline(sup.loop.time)))
                    if not loads or now - t_load - loads[-1][0] >= 1.0:
                        loads.append((now - t_load, os.getloadavg()[0]))
                    if not sup.armed and not sup.fault:
                        try:
                            sup.arm(LOCAL)
                            rearmed += 1
                        except CommandRefused:
                            pass  # a failsafe still active: counted, tried again
                    if progress is not None and now >= next_report:
                        next_report = now + 30.0
                        progress(f"{now - t_load:5.0f} s: load average {os.getloadavg()[0]:.1f}, "
                                 f"drive faults {count.drive_faults()}, sensor faults {count.sensor_faults()}, "
                                 f"failsafes {count.failsafes()}, stalls {sup.loop.stalls}")
                    time.sleep(sample_s)
            finally:
                if load is not None:
                    load.stop()
            stalls, overruns, plans = sup.loop.stalls, sup.loop.plan_overruns, sup.loop.plans_made
            skipped = getattr(sup.clock, "skipped", 0.0)
        finally:
            sup.stop()
    return {
        "load_s": load_s, "after_s": after_s, "hogs": hogs, "velocity": velocity,
        "drive_faults": count.drive_faults(), "sensor_faults": count.sensor_faults(),
        "failsafes": count.failsafes(), "rearmed": rearmed,
        "faults": [{"t": e.t, "source": e.source, "code": e.code, "message": e.message} for e in count.faults],
        "events": {f"{s}/{c}": n for (s, c), n in sorted(count.by.items())},
        "stalls": stalls, "skipped_s": skipped, "plan_overruns": overruns, "plans_made": plans,
        **lag_figures(lags), **load_figures(loads, load_s),
    }


def lag_figures(lags: list[tuple[float, float]]) -> dict[str, Any]:
    """The loop's lag during the load and its recovery after it (samples: (s since the load
    ended, lag))."""
    during = [lag for t, lag in lags if t < 0.0]
    after = [(t, lag) for t, lag in lags if t >= 0.0]
    # from the load's end, the first sample after which every sample stays under the goal
    recovered = math.nan
    for t, lag in reversed(after):
        if lag >= LAG_GOAL:
            break
        recovered = t
    late = [lag for t, lag in after if t >= 5.0]
    return {
        "lag_max_during_s": max(during, default=math.nan),
        "lag_median_during_s": sorted(during)[len(during) // 2] if during else math.nan,
        "lag_back_under_goal_after_s": recovered,
        "lag_max_from_5s_after_s": max(late, default=math.nan),
    }


def load_figures(loads: list[tuple[float, float]], load_s: float) -> dict[str, Any]:
    """The 1-minute load average while loaded, once it has had a minute to build up, and how
    long it was at least :data:`LOAD_GOAL` (samples: (s since the load started, load average))."""
    built = [la for t, la in loads if 60.0 <= t <= load_s] or [la for t, la in loads if t <= load_s]
    loaded = [(t, la) for t, la in loads if t <= load_s]
    at_goal = sum(t1 - t0 for (t0, la), (t1, _) in zip(loaded, loaded[1:]) if la >= LOAD_GOAL)
    return {"loadavg_min": min(built, default=math.nan), "loadavg_mean": sum(built) / len(built) if built else math.nan,
            "loadavg_max": max((la for _, la in loads), default=math.nan), "load_at_goal_s": at_goal}


def format_result(r: dict[str, Any]) -> str:
    return "\n".join([
        f"emulated rig swimming at {r['velocity']} m/s, {r['hogs']} spinning processes for {r['load_s']:g} s "
        f"(1-minute load average {r['loadavg_min']:.1f}-{r['loadavg_max']:.1f}, mean {r['loadavg_mean']:.1f}, "
        f"at least {LOAD_GOAL:g} for {r.get('load_at_goal_s', math.nan):.0f} s), "
        f"then {r['after_s']:g} s without",
        f"spurious faults: drive {r['drive_faults']}, sensor {r['sensor_faults']}, failsafes {r['failsafes']} "
        f"(armed again {r['rearmed']} times)",
        f"loop: {r['stalls']} stalls skipped ({r['skipped_s']:.1f} s in all), lag max {r['lag_max_during_s'] * 1e3:.0f} ms "
        f"(median {r['lag_median_during_s'] * 1e3:.0f} ms) under load; back under {LAG_GOAL * 1e3:.0f} ms "
        f"{r['lag_back_under_goal_after_s']:.1f} s after the load ended, at most "
        f"{r['lag_max_from_5s_after_s'] * 1e3:.0f} ms from 5 s after",
        f"plans: {r['plans_made']}, overruns (a fin waited past the hand-over) {r['plan_overruns']}",
    ])


def register_bench(kinds: argparse._SubParsersAction) -> None:
    p = kinds.add_parser("load", help="the emulated rig swimming under CPU load: spurious faults, the loop's recovery")
    p.add_argument("--minutes", type=float, default=10.0, help="how long the machine is loaded")
    p.add_argument("--after", type=float, default=30.0, help="seconds watched after the load ends")
    p.add_argument("--hogs", type=int, default=8, help="spinning child processes (the load)")
    p.add_argument("--json", type=Path, default=None, help="write the results as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ucat_console.bench.machine import machine_info, speed_line

    if not 0.0 < args.minutes <= 600.0:
        raise ValueError(f"--minutes: {args.minutes} must be in (0, 600]")
    if not 0.0 < args.after <= 3600.0:
        raise ValueError(f"--after: {args.after} must be in (0, 3600]")
    if not 1 <= args.hogs <= 256:
        raise ValueError(f"--hogs: {args.hogs} must be in [1, 256]")
    if args.json is not None and not args.json.parent.exists():
        raise ValueError(f"--json: directory {args.json.parent} does not exist")
    machine = machine_info(None)  # before the load: the speed probe of the machine itself
    r = swim_under_load(60.0 * args.minutes, args.after, args.hogs, progress=lambda s: print(s, flush=True))
    r["machine"] = machine
    print(format_result(r))
    print(speed_line(machine))
    if args.json is not None:
        args.json.write_text(json.dumps(r, indent=1))
        print(f"wrote {args.json}")
    return 0
