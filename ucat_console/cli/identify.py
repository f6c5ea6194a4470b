"""``ucat-console identify SESSION...``: the fin model identified from recordings.

Fits the controller's C_D and C_L (or ``--fit scale``: one factor on both; ``--fit plate``:
the simulated fin's plate model, ``control.plate_model``: C_D, C_L and the profile drag C_D0)
to the recorded encoder angles and rates, DVL velocity and IMU of the sessions (ids or part
files), with the hull's damping and added mass from ``--config`` (default: the configuration the first
session recorded), prints the coefficients with 95 % intervals and writes, into ``--out``,
``identified.toml`` (the ``[loop.mpc]`` fragment to load), ``identify.json`` (every window) and
``residuals.png`` (with the ``experiments`` extra).

``--run`` first runs the identification manoeuvre (mode "identify") on the configured robot
and records it: on the simulated robot as fast as it computes (``--realtime`` for real
time), on the device rig in real time; the manoeuvre's steps are ``[loop.manoeuvre]``.
``ucat-console run --headless --mode identify --record --duration S`` records the same.

``--trim`` identifies the designed body layer's heave trim instead (``[loop.body] heave_trim``):
the heave force the fins gave while the robot hovered at its depth in the sessions
(``control.identification.hover_trim``); record a hover with ``ucat-console run --headless
--record --velocity 0 --depth D --duration S`` (or at the pool), then run it on the session.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import json
import math
from pathlib import Path
from typing import Any


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("identify", help="identify the fin coefficients from recorded sessions")
    p.add_argument("sessions", nargs="*", metavar="SESSION", help="session ids or part files")
    p.add_argument("--run", action="store_true", help="first run and record the identification manoeuvre")
    p.add_argument("--realtime", action="store_true", help="with --run on the simulated robot: real time")
    p.add_argument("--config", default=None, metavar="NAME|FILE",
                   help="configuration (a shipped one's name or a TOML file): the hull, the model to start from, the robot for --run")
    p.add_argument("--fit", choices=("coefficients", "scale", "plate"), default="coefficients",
                   help="fit C_D and C_L, one scale of the configured pair, or the plate model's C_D, C_L and profile "
                   "drag C_D0 (plate: the simulated fin, docs/fin-plant.md)")
    p.add_argument("--window", type=float, default=None, metavar="S", help="force-balance window (s)")
    p.add_argument("--dir", type=Path, default=None,
                   help="sessions directory (default: $UCAT_CONSOLE_SESSIONS, else the user's "
                        "data folder: ucat-console paths)")
    p.add_argument("--out", type=Path, default=Path("identify-out"), help="output directory")
    p.add_argument("--trim", action="store_true",
                   help="identify the body layer's heave trim from a recorded hover instead")
    p.set_defaults(func=run)


def _record_manoeuvre(cfg: Any, directory: Path | None, realtime: bool) -> Path:
    from ucat_console.backend.access import LOCAL
    from ucat_console.backend.loop.clock import SimulatedClock
    from ucat_console.backend.supervisor import Supervisor

    from ucat_console.backend.robots import robot

    fast = robot(cfg.robot).computed_readings and not realtime
    sup = Supervisor(cfg, clock=SimulatedClock() if fast else None, sessions_dir=directory)
    try:
        sup.start()
        sup.arm(LOCAL)
        man = sup.start_manoeuvre(LOCAL)
        print(f"identification manoeuvre: {len(cfg.loop.manoeuvre.steps)} steps of "
              f"{cfg.loop.manoeuvre.step_s:g} s, recording session {man.session}", flush=True)
        paths = man.wait()
    finally:
        sup.stop()
    if not paths:
        raise ValueError("identify --run: the manoeuvre recorded nothing")
    return paths[0]


def _trim(args: argparse.Namespace) -> int:
    from ucat_console.backend.identification import trim_sessions

    trim, toml = trim_sessions(args.sessions, args.dir, confined=False)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "identified.toml").write_text(toml)
    print(f"heave trim from {trim.seconds:.0f} s of hover: {trim.heave_trim:.3f} +- {trim.ci:.3f} N (95 %, down > 0)")
    print(f"wrote {args.out / 'identified.toml'} (its [loop.body] table: load it with --config)")
    return 0


def run(args: argparse.Namespace) -> int:
    from ucat_console.backend.identification import identify_sessions, residual_plots
    from ucat_console.config import load_config
    from ucat_console.control.identification import IdentifyConfig

    if not args.sessions and not args.run:
        raise ValueError("identify: name at least one SESSION, or --run the manoeuvre")
    if args.out.exists() and not args.out.is_dir():
        raise ValueError(f"--out: {args.out} exists and is not a directory")
    if args.trim:
        if args.run:
            raise ValueError("identify --trim: record a hover first (see --help), then name its session")
        return _trim(args)
    icfg = IdentifyConfig(fit=args.fit) if args.window is None else IdentifyConfig(fit=args.fit, window_s=args.window)
    cfg = load_config(args.config) if args.config is not None else None
    sessions = list(args.sessions)
    if args.run:
        from ucat_console.compiled import prepare_all

        prepare_all(args.config)
        sessions.append(str(_record_manoeuvre(cfg or load_config(None), args.dir, args.realtime)))
    rep = identify_sessions(sessions, args.dir, cfg, icfg, confined=False)
    r = rep.result
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "identified.toml").write_text(rep.toml)
    doc = {"sessions": list(rep.sessions), "config": rep.config_source,
           "result": {k: (None if isinstance(v, float) and math.isnan(v) else v)
                      for k, v in dataclasses.asdict(r).items() if k != "windows"},
           "windows": [dataclasses.asdict(w) for w in r.windows]}
    (args.out / "identify.json").write_text(json.dumps(doc, indent=1, default=float))
    print(f"identified from {len(rep.sessions)} session(s), hull from {rep.config_source}: "
          f"{len(r.windows)} windows ({r.steady_windows} steady), rms residual {r.rms_residual:.4f} N")
    print(f"  c_d = {r.c_d:.4f} +- {r.c_d_ci:.4f}   c_l = {r.c_l:.4f} +- {r.c_l_ci:.4f}   (95 %)")
    if r.fit == "plate":
        print(f"  plate: c_d0 = {r.c_d0:.4f} +- {r.c_d0_ci:.4f}   (95 %; the plate's lift held at its ratio)")
    if importlib.util.find_spec("matplotlib") is not None:
        print(f"wrote {residual_plots(r, args.out / 'residuals.png')}")
    else:
        print("residual plots need matplotlib (pip install 'ucat-console[experiments]')")
    print(f"wrote {args.out / 'identified.toml'} (load it with --config) and {args.out / 'identify.json'}")
    return 0
