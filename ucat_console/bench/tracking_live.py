"""``ucat-console bench tracking-live``: the console's own loop, at real time beside other work,
in every mode: does the robot still go where it is sent, and does the tracking alarm stay quiet?

``bench tracking`` runs the loop as fast as it can on a quiet process. Here the console runs
as ``ucat-console run`` does (the shipped ``sim-tuned``, the simulated robot in the console's
process, its loop paced by the wall clock) while ``--hogs`` child processes spin
(:class:`~ucat_console.bench.load.CpuLoad`). For each mode, ``--starts`` times (a new console
each time, the simulated sensors' noise from seeds 0, 1, ...), the robot is armed at rest at its
start depth and sent at ``--velocity`` m/s (yaw rate 0); ``--step-at`` s later the depth
setpoint steps ``--depth-step`` m deeper; the run ends ``--seconds`` s after arming. A mode is
reported by the worst of its starts (the tracking alarms of all of them added). The
simulator's truth is sampled every 0.1 s of wall time:

* ``heading_max_deg``: the largest heading error against the heading at arming, over the
  whole run (from rest, through the depth step);
* ``depth_dev_m``: the largest depth error from ``--step-at`` + 45 s on;
* ``speed_in_band``: the share of samples within +-0.025 m/s of the velocity from 30 s on
  until the step;
* ``tracking_alarms``: the tracking failsafe's triggers (a normal start under load must raise
  none), and every other failsafe triggered;
* the loop's largest lag behind the wall clock, its stalls, and the load average.

Figures depend on the machine and its load (reported with them); they are for the docs,
never test assertions.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import tempfile
import time
from pathlib import Path
from typing import Any

#: the modes run: (label, loop mode, MPC formulation), as ``bench tracking`` names them
MODES: tuple[tuple[str, str, str], ...] = (
    ("baseline", "baseline", "paper"),
    ("mpc", "mpc", "paper"),
    ("mpc_sync", "mpc_sync", "paper"),
    ("mpc_closed", "mpc", "closed_stroke"),
)
SPEED_BAND = 0.025  # m/s
SPEED_FROM = 30.0  # s after arming
DEPTH_FROM = 45.0  # s after the step


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def run_mode(mode: str, formulation: str, *, seconds: float, step_at: float, depth_step: float,
             velocity: float, config: str = "sim-tuned", seed: int = 0) -> dict[str, Any]:
    """One mode's run on a console at real time (module docstring), the simulated sensors'
    noise from ``seed``; its figures."""
    from ucat_console.backend.access import LOCAL
    from ucat_console.backend.supervisor import Supervisor
    from ucat_console.config import load_config
    from ucat_console.telemetry import channels as ch

    cfg = load_config(config)
    cfg = cfg.replace(loop=cfg.loop.replace(mode=mode, mpc=cfg.loop.mpc.replace(formulation=formulation)),
                      plant=cfg.plant.replace(seed=seed))
    failsafes: list[str] = []
    with tempfile.TemporaryDirectory() as tmp:
        cfg = cfg.replace(console=cfg.console.replace(record_on_arm=False))
        sup = Supervisor(cfg, sessions_dir=tmp)
        sup.stream.subscribe(lambda c, e: failsafes.append(e.code) if e.source == "failsafe" else None, [ch.EVENTS])
        sup.start()
        samples: list[tuple[float, float, float, float]] = []  # (t since arming, heading error, depth, speed)
        lag = 0.0
        try:
            deadline = time.monotonic() + 60.0
            while sup.loop.truth() is None or sup.loop.time < 1.0:
                if time.monotonic() > deadline:
                    raise RuntimeError(f"{mode}: the loop did not start within 60 s")
                time.sleep(0.05)
            truth = sup.loop.truth()
            depth0, yaw0 = truth.position[2], truth.euler[2]
            sup.set_setpoints(LOCAL, velocity=velocity, depth=depth0, yaw_rate=0.0)
            sup.arm(LOCAL)
            t_arm = sup.loop.time
            stepped = False
            while sup.running:
                t = sup.loop.time - t_arm
                if t >= seconds:
                    break
                if not stepped and t >= step_at:
                    sup.set_setpoints(LOCAL, depth=depth0 + depth_step)
                    stepped = True
                truth = sup.loop.truth()
                samples.append((t, math.degrees(abs(_wrap(truth.euler[2] - yaw0))), truth.position[2],
                                truth.velocity[0]))
                lag = max(lag, time.perf_counter() - sup.clock.wall_deadline(sup.loop.time))
                time.sleep(0.1)
            stalls = sup.loop.stalls
            fault = sup.fault
        finally:
            sup.stop()
    target = depth0 + depth_step
    speeds = [u for t, _, _, u in samples if SPEED_FROM <= t < step_at]
    depths = [abs(d - target) for t, _, d, _ in samples if t >= step_at + DEPTH_FROM]
    return {
        "mode": mode, "formulation": formulation, "seed": seed, "samples": len(samples), "fault": fault,
        "heading_max_deg": max((h for _, h, _, _ in samples), default=math.nan),
        "depth_dev_m": max(depths, default=math.nan),
        "speed_in_band": (sum(abs(u - velocity) <= SPEED_BAND for u in speeds) / len(speeds)) if speeds else math.nan,
        "tracking_alarms": failsafes.count("tracking"),
        "failsafes": sorted(set(failsafes)),
        "max_lag_s": lag, "stalls": stalls,
    }


def worst(starts: list[dict[str, Any]]) -> dict[str, Any]:
    """One mode's starts summed up: the worst of each figure, the alarms and stalls added, the
    failsafes of any start, every start's figures under ``starts``."""
    def most(key: str) -> float:
        return max((r[key] for r in starts if not math.isnan(r[key])), default=math.nan)
    band = [r["speed_in_band"] for r in starts if not math.isnan(r["speed_in_band"])]
    return {
        "mode": starts[0]["mode"], "formulation": starts[0]["formulation"],
        "samples": sum(r["samples"] for r in starts),
        "fault": "; ".join(f"seed {r['seed']}: {r['fault']}" for r in starts if r["fault"]),
        "heading_max_deg": most("heading_max_deg"), "depth_dev_m": most("depth_dev_m"),
        "speed_in_band": min(band, default=math.nan),
        "tracking_alarms": sum(r["tracking_alarms"] for r in starts),
        "failsafes": sorted({f for r in starts for f in r["failsafes"]}),
        "max_lag_s": most("max_lag_s"), "stalls": sum(r["stalls"] for r in starts),
        "load_average": max(r["load_average"] for r in starts), "starts": starts,
    }


def measure(modes: tuple[str, ...], hogs: int, seconds: float, step_at: float, depth_step: float,
            velocity: float, progress: Any = None, starts: int = 1) -> dict[str, Any]:
    """Each mode started ``starts`` times from rest (the sensors' noise from seeds 0, 1, ...)
    beside ``hogs`` spinning processes; per mode the worst of its starts (:func:`worst`)."""
    from ucat_console.bench.load import CpuLoad
    from ucat_console.bench.machine import machine_info

    if not 0.0 < step_at < seconds:
        raise ValueError(f"--step-at: {step_at:g} s must lie within the run's {seconds:g} s")
    if starts < 1:
        raise ValueError(f"--starts: at least one start per mode, got {starts}")
    out: dict[str, Any] = {"machine": machine_info(None), "hogs": hogs, "seconds": seconds, "step_at": step_at,
                           "depth_step": depth_step, "velocity": velocity, "starts": starts, "modes": {}}
    load = CpuLoad(hogs).start()
    try:
        for label, mode, formulation in MODES:
            if label not in modes:
                continue
            runs = []
            for seed in range(starts):
                r = run_mode(mode, formulation, seconds=seconds, step_at=step_at, depth_step=depth_step,
                             velocity=velocity, seed=seed)
                r["load_average"] = os.getloadavg()[0]
                runs.append(r)
            out["modes"][label] = worst(runs)
            if progress is not None:
                progress(format_mode(label, out["modes"][label]))
    finally:
        load.stop()
    return out


def format_mode(label: str, r: dict[str, Any]) -> str:
    others = [f for f in r["failsafes"] if f != "tracking"]
    n = len(r.get("starts", ())) or 1
    return (f"{label:10s} {n} start{'s' if n > 1 else ''}, worst: heading max {r['heading_max_deg']:5.1f} deg, depth dev {r['depth_dev_m']:.3f} m, "
            f"speed in band {100 * r['speed_in_band']:3.0f} %, tracking alarms {r['tracking_alarms']}"
            f"{', other failsafes ' + ' '.join(others) if others else ''}; lag max {1e3 * r['max_lag_s']:.0f} ms, "
            f"stalls {r['stalls']}, load average {r['load_average']:.1f}"
            + (f"; STOPPED: {r['fault']}" if r["fault"] else ""))


def format_result(r: dict[str, Any]) -> str:
    head = (f"live console at real time beside {r['hogs']} spinning processes ({r['machine'].get('cpu_model', '?')}): "
            f"from rest to {r['velocity']:g} m/s, depth step {r['depth_step']:+g} m at {r['step_at']:g} s, "
            f"{r['seconds']:g} s per start, {r.get('starts', 1)} start(s) per mode")
    return "\n".join([head, *(format_mode(label, m) for label, m in r["modes"].items())])


def register_bench(kinds: argparse._SubParsersAction) -> None:
    p = kinds.add_parser("tracking-live", help="the console's loop at real time under CPU load: heading, depth, "
                                               "speed and the tracking alarm, in every mode")
    p.add_argument("--modes", nargs="+", choices=[m[0] for m in MODES], default=[m[0] for m in MODES])
    p.add_argument("--hogs", type=int, default=2, help="spinning processes beside the console")
    p.add_argument("--seconds", type=float, default=150.0, help="each mode's run from arming, s")
    p.add_argument("--step-at", type=float, default=60.0, help="when the depth setpoint steps, s after arming")
    p.add_argument("--depth-step", type=float, default=0.5, help="the depth step, m")
    p.add_argument("--velocity", type=float, default=0.2, help="the velocity setpoint from rest, m/s")
    p.add_argument("--starts", type=int, default=1, help="starts from rest per mode (the sensors' noise from "
                                                          "seeds 0, 1, ...); the worst of them is reported")
    p.add_argument("--json", type=Path, default=None, help="write the results as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.hogs < 0:
        raise ValueError("--hogs: must not be negative")
    if not args.seconds > 0 or not args.velocity > 0:
        raise ValueError("--seconds and --velocity: must be positive")
    from ucat_console.compiled import prepare_all

    prepare_all("sim-tuned")
    r = measure(tuple(args.modes), args.hogs, args.seconds, args.step_at, args.depth_step, args.velocity,
                progress=lambda line: print(line, flush=True), starts=args.starts)
    print(format_result(r))
    if args.json is not None:
        args.json.write_text(json.dumps(r, indent=1))
    return 0
