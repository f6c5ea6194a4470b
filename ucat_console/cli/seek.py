"""``ucat-console seek``: seek efficiency headless on the simulated robot (docs/seek.md).

    ucat-console seek --config sim-tuned --velocity 0.2 --depth 1 --params mpc.st_opt mpc.lam_st --fast
    ucat-console seek --params baseline.frequency --mode baseline --candidates 8 --seed 3 --json seek.json

The robot is armed with the given setpoints and holds them for ``--hold`` s (default: the
configuration's ``seek.settle_s``); then one search runs over the parameters named (their
bounds are the configuration's ``[[seek.params]]``; all of them when none are named). Each
candidate is printed with its energy per metre, interval and verdict as it is measured, and
at the end the best with its interval; ``--json FILE`` writes them. The best stays in force
until the run ends (the console's configuration file is not changed).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path
from typing import Any

from ucat_console import compiled
from ucat_console.backend.loop.modes import mode_names


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("seek", help="seek efficiency headless: candidates of tunable parameters measured on "
                                    "electrical energy per metre")
    p.add_argument("--config", default=None, metavar="NAME|FILE",
                   help="configuration: a shipped one's name (sim-tuned ...) or a TOML file ([seek] holds the bounds)")
    p.add_argument("--velocity", type=float, default=None, help="forward velocity setpoint held, m/s")
    p.add_argument("--depth", type=float, default=None, help="depth setpoint held, m")
    p.add_argument("--yaw-rate", type=float, default=None, help="yaw rate setpoint held, rad/s")
    p.add_argument("--mode", choices=mode_names(), default=None, help="fin controller")
    p.add_argument("--params", nargs="+", default=(), metavar="KEY",
                   help="the parameters to vary (of the configuration's [[seek.params]]; default: all of them)")
    p.add_argument("--candidates", type=int, default=None, metavar="N", help="candidates (the start's included)")
    p.add_argument("--confirm", type=int, default=None, metavar="N",
                   help="the search's best N measured once more each; the least second measure wins (0: none)")
    p.add_argument("--seed", type=int, default=None, metavar="S", help="the search's seed")
    p.add_argument("--settle", type=float, default=None, metavar="S", help="settle time after each change, s")
    p.add_argument("--window", type=float, default=None, metavar="S", help="each candidate's measure window, s")
    p.add_argument("--hold", type=float, default=None, metavar="S",
                   help="hold the setpoints this long after arming before the seek starts (default: the settle time)")
    p.add_argument("--fast", action="store_true", help="the simulator runs as fast as it can (simulated time)")
    p.add_argument("--json", type=Path, default=None, metavar="FILE", help="write the candidates and the best here")
    p.add_argument("--sessions-dir", type=Path, default=None, metavar="DIR", help="where a recording would go")
    p.set_defaults(func=run)


def _config(args: argparse.Namespace) -> Any:
    from ucat_console.backend.robots import robot
    from ucat_console.config import load_config

    cfg = load_config(args.config)
    seek = cfg.seek
    changes = {k: v for k, v in (("settle_s", args.settle), ("window_s", args.window),
                                 ("max_candidates", args.candidates), ("seed", args.seed),
                                 ("confirm", args.confirm)) if v is not None}
    seek = seek.replace(**changes, drift_check=False)  # one search: the command ends with it
    seek.only(tuple(args.params))  # a parameter without bounds is said before anything starts
    loop = cfg.loop if args.mode is None else cfg.loop.replace(mode=args.mode)
    if args.fast and not robot(cfg.robot).computed_readings:
        raise ValueError(f"--fast: only with a robot whose readings the console computes (sim), not {cfg.robot!r}")
    if args.hold is not None and not (math.isfinite(args.hold) and args.hold >= 0.0):
        raise ValueError(f"--hold: expected seconds >= 0, got {args.hold}")
    return cfg.replace(seek=seek, loop=loop, console=cfg.console.replace(record_on_arm=False))


def run(args: argparse.Namespace) -> int:
    from ucat_console.backend.access import LOCAL
    from ucat_console.backend.loop.clock import SimulatedClock
    from ucat_console.backend.supervisor import Supervisor
    from ucat_console.cli.run import _wait_first_step, config_name
    from ucat_console.telemetry import channels as ch

    cfg = _config(args)
    prep = compiled.prepare(cfg, compiled.needed_steps(cfg))
    sup = Supervisor(cfg, clock=SimulatedClock() if args.fast else None, sessions_dir=args.sessions_dir,
                     planner_ready=lambda f: prep.done(compiled.planner_step(f)),
                     config_name=config_name(args.config))
    events: list[Any] = []

    def on_event(channel: str, ev: Any) -> None:
        if ev.source == "seek":
            events.append(ev)
            print(f"{ev.t:8.1f} s  {ev.message}", flush=True)

    sup.stream.subscribe(on_event, [ch.EVENTS])
    seek = None
    try:
        sup.set_setpoints(LOCAL, velocity=args.velocity, depth=args.depth, yaw_rate=args.yaw_rate)
        sup.start()
        _wait_first_step(sup)
        sup.arm(LOCAL)
        hold = cfg.seek.settle_s if args.hold is None else args.hold
        t_start = sup.loop.time + hold
        print(f"seek: mode {sup.mode}, setpoints {sup.setpoints}; holding them {hold:g} s first", flush=True)
        while sup.running and sup.loop.time < t_start:
            time.sleep(0.02 if args.fast else 0.1)
        seek = sup.start_seek(LOCAL, tuple(args.params))
        print(f"seek: {cfg.seek.max_candidates} candidates of {cfg.seek.settle_s:g} s settle and "
              f"{cfg.seek.window_s:g} s measure over " + ", ".join(
                  f"{p.name} [{p.lo:g}, {p.hi:g}]" for p in seek.params)
              + f"; then the best {cfg.seek.confirm} measured again", flush=True)
        while sup.running and not seek.finished:
            time.sleep(0.02 if args.fast else 0.2)
        if sup.fault:
            print(f"the closed loop stopped: {sup.fault}")
    except KeyboardInterrupt:
        print("\nstopping: disarming", flush=True)
    finally:
        sup.stop()
        prep.cancel()
    if seek is None:
        return 1
    best = seek.best
    if best is not None and best.energy is not None:
        e = best.energy
        print(f"best: #{best.index} " + ", ".join(f"{k} {v:.4g}" for k, v in best.values)
              + f": energy per metre {e.value:.1f} J/m [{e.lo:.1f}, {e.hi:.1f}] "
              f"({sup.cfg.metrics.confidence:.0%} interval)")
    else:
        print("best: none (no candidate was accepted)")
    print(f"seek: {seek.reason}; {len(seek.candidates)} candidates measured")
    if args.json is not None:
        out = {
            "reason": seek.reason,
            "params": [{"name": p.name, "lo": p.lo, "hi": p.hi} for p in seek.params],
            "start": seek.start_values,
            "candidates": [ev.data for ev in events if ev.code == "candidate"],
            "best": None if best is None or best.energy is None else {
                "index": best.index, "values": dict(best.values),
                "energy_per_metre": {"value": best.energy.value, "lo": _json(best.energy.lo),
                                     "hi": _json(best.energy.hi)}},
        }
        args.json.write_text(json.dumps(out, indent=2))
        print(f"wrote {args.json}")
    return 0 if seek.reason == "completed" and not sup.fault else 1


def _json(x: float) -> float | None:
    return x if math.isfinite(x) else None
