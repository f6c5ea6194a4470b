"""``ucat-console run``: the console (supervisor, robot, web page), or a headless run.

    ucat-console run                         # simulated robot, page on http://127.0.0.1:8080
    ucat-console run --config sim-tuned      # a shipped configuration, by name
    ucat-console run --config pool.toml --port 0
    ucat-console run --headless --duration 60 --mode mpc_sync --velocity 0.2 --depth 1 --record
    ucat-console run --foxglove-port 8765     # and the live robot in Foxglove / Lichtblick
    ucat-console run --ros2                   # and the live robot as ROS 2 topics (rmw_zenoh)
    ucat-console run --headless --manoeuvre e4_ladder   # a scripted manoeuvre (docs/manoeuvres.md)

With the page, the motors stay disarmed until the pilot (the page that entered the token
printed below) arms them. ``--headless`` runs without a page and arms at once with the
given setpoints, for ``--duration`` seconds of robot time from arming (real time; ``--fast``
runs the simulator as fast as it goes). Ctrl-C disarms, stops the motors and closes the files.
``--manoeuvre NAME|FILE`` (headless) runs a scripted manoeuvre once armed, recorded, for
its own length unless ``--duration`` says otherwise, and prints each segment's figures at
its end (``ucat-console manoeuvres list`` lists the shipped ones).

The compiled code is prepared first in child processes (:mod:`ucat_console.compiled`: the first run on a
machine compiles it, with its progress on the terminal and on the loading page, whose
server the console then takes over: one server, one address, for the run). A start
that fails (or is stopped) before the run begins leaves no session file behind.
"""

from __future__ import annotations

import argparse
import math
import signal
import sys
import time
from pathlib import Path
from typing import Any

from ucat_console.backend.loop.modes import mode_names
from ucat_console import compiled


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="run the console: supervisor, robot (simulated by default), web page")
    p.add_argument("--config", default=None, metavar="NAME|FILE",
                   help="configuration: a shipped one's name (sim-tuned, sim-devices, robot) or a TOML file")
    p.add_argument("--host", default=None, help="address to bind (default 127.0.0.1; others are warned about)")
    p.add_argument("--port", type=int, default=None, help="port (default 8080; 0: any free port)")
    p.add_argument("--headless", action="store_true", help="no web page: arm at once and run --duration s")
    p.add_argument("--fast", action="store_true", help="headless simulator runs as fast as it can")
    p.add_argument("--duration", type=float, default=None, metavar="S",
                   help="stop after S s of robot time (headless: from arming)")
    p.add_argument("--mode", choices=mode_names(), default=None, help="fin controller")
    p.add_argument("--velocity", type=float, default=None, help="forward velocity setpoint, m/s")
    p.add_argument("--depth", type=float, default=None, help="depth setpoint, m")
    p.add_argument("--yaw-rate", type=float, default=None, help="yaw rate setpoint, rad/s")
    p.add_argument("--manoeuvre", default=None, metavar="NAME|FILE",
                   help="headless: run this scripted manoeuvre (a shipped one's name or a TOML file; "
                        "`ucat-console manoeuvres list`), recorded; the run lasts as long as it unless --duration")
    p.add_argument("--record", action="store_true", help="record the whole run")
    p.add_argument("--sessions-dir", type=Path, default=None, metavar="DIR",
                   help="where recordings go (default: the configuration's console.sessions_dir, "
                        "else $UCAT_CONSOLE_SESSIONS, else the user's data folder)")
    p.add_argument("--playback", default=None, metavar="FILE",
                   help="open this session file (in the sessions directory) in the Review tab")
    p.add_argument("--foxglove-port", type=int, default=None, metavar="P",
                   help="also serve the live telemetry to Foxglove / Lichtblick (read-only "
                        "WebSocket on --host, port P; 0: any free port)")
    p.add_argument("--ros2", action="store_true",
                   help="also publish the live telemetry as ROS 2 topics through zenoh, for ROS 2 nodes on "
                        "rmw_zenoh (the configuration's [ros2]: domain, node, router endpoint; the 'ros' extra)")
    p.set_defaults(func=run)


def config_name(value: str | None) -> str:
    """The name a recording gives its configuration: a shipped one's name, a file's name
    (``mine.toml``), ``default`` for the defaults."""
    from ucat_console import shipped

    if value is None:
        return "default"
    return str(value) if shipped.is_name(value) else Path(value).name


def _config(args: argparse.Namespace) -> Any:
    from ucat_console.config import load_config

    cfg = load_config(args.config)
    console = cfg.console
    if args.host is not None:
        console = console.replace(host=args.host)
    if args.port is not None:
        console = console.replace(port=args.port)
    loop = cfg.loop if args.mode is None else cfg.loop.replace(mode=args.mode)
    ros2 = cfg.ros2.replace(enabled=True) if args.ros2 else cfg.ros2
    return cfg.replace(console=console, loop=loop, ros2=ros2)


def _foxglove_server(port: int, cfg: Any, sup: Any) -> Any:
    """The read-only Foxglove server on the console's address (its URL printed)."""
    from ucat_console.backend.foxglove_live import FoxgloveServer
    from ucat_console.backend.sessions.foxglove import robot_geometry
    from ucat_console.ui.app import is_loopback

    host = cfg.console.host
    if not is_loopback(host):
        print(f"WARNING: the Foxglove server binds {host}: the telemetry is readable from "
              "other machines", file=sys.stderr)
    fox = FoxgloveServer(sup.stream, host=host, port=port, epoch_offset=sup.wall0,
                         geometry=robot_geometry(cfg.plant), allowed_origins=cfg.foxglove.allowed_origins)
    print(f"Foxglove server on {fox.url}  (port {fox.port}; open it in Foxglove or Lichtblick: "
          f"Open connection, Foxglove WebSocket; read-only)", flush=True)
    return fox


def _check_ros2(cfg: Any) -> None:
    """ValueError naming the extra to install when the ROS 2 topics are on and zenoh is missing
    (said before anything starts)."""
    if not cfg.ros2.enabled:
        return
    from ucat_console.backend.ros_live import import_zenoh

    try:
        import_zenoh()
    except ImportError as e:
        raise ValueError(f"--ros2 / ros2.enabled: {e}") from None


def _ros2_publisher(cfg: Any, sup: Any) -> Any:
    """The live ROS 2 publisher (its node and endpoints printed)."""
    from ucat_console.backend.ros_live import Ros2Publisher

    ros = Ros2Publisher(sup.stream, cfg.ros2, epoch_offset=sup.wall0, plant=cfg.plant)
    r = cfg.ros2
    odom = next(name for name in ros.topics if name.endswith("/odom"))
    print(f"ROS 2 node {ros.node_name} on domain {r.domain_id}: {len(ros.topics)} topics through zenoh "
          f"({r.mode}, connecting to {', '.join(r.connect) or 'nothing'}; read them with "
          f"RMW_IMPLEMENTATION=rmw_zenoh_cpp, e.g. ros2 topic echo {odom})", flush=True)
    return ros


#: how often the page's address and the pilot token are printed again on a terminal (s)
TOKEN_REPEAT = 60.0


def _prepare_with_page(cfg: Any) -> tuple[Any, Any, Any]:
    """Serve the loading page at once and compile in child processes; (the configuration
    with the port the page got, the preparation, which goes on with what may wait, the
    loading page, still serving: the console takes its server over). A preparation that
    fails or is stopped stops the page."""
    from ucat_console.ui.loading import LoadingPage

    page = LoadingPage(cfg, cfg.console.host, cfg.console.port)
    print(f"U-CAT console on {_url(cfg.console.host, page.port)}  (starting: the page shows the progress)",
          flush=True)
    try:
        prep = compiled.prepare(cfg, compiled.console_steps(cfg), on_progress=page.set_progress)
    except BaseException:
        page.stop()
        raise
    return cfg.replace(console=cfg.console.replace(port=page.port)), prep, page


def _url(host: str, port: int) -> str:
    """The page's address on ``host`` (any address: this machine's loopback one)."""
    host = host if host not in ("0.0.0.0", "::") else "127.0.0.1"
    return f"http://[{host}]:{port}" if ":" in host else f"http://{host}:{port}"


def _wait_first_step(sup: Any) -> None:
    """Until the loop has run its first event: its first steps load the compiled code from
    numba's cache, and a command sent meanwhile (the headless run's arming) would wait
    longer than a command waits on a busy machine. Ends early when the loop stops."""
    deadline = time.monotonic() + 600.0
    while sup.running and sup.loop.time <= 0.0 and time.monotonic() < deadline:
        time.sleep(0.02)


def run(args: argparse.Namespace) -> int:
    from ucat_console.backend.access import LOCAL
    from ucat_console.backend.robots import robot
    from ucat_console.backend.loop.clock import SimulatedClock
    from ucat_console.backend.supervisor import Supervisor
    from ucat_console.telemetry import channels as ch
    from ucat_console.ui.app import is_loopback

    if args.duration is not None and (not math.isfinite(args.duration) or args.duration <= 0):
        raise ValueError(f"--duration: expected a positive number of seconds, got {args.duration}")
    if args.playback is not None and args.headless:
        raise ValueError("--playback: only with the web page (not --headless)")
    if args.fast and not args.headless:
        raise ValueError("--fast: only with --headless")
    if args.manoeuvre is not None and not args.headless:
        raise ValueError("--manoeuvre: only with --headless (on the page: the Drive tab's Manoeuvre folder)")
    cfg = _config(args)
    _check_ros2(cfg)
    script = None
    if args.manoeuvre is not None:  # a bad file is said before anything starts
        from ucat_console.backend.manoeuvre_files import load_script

        script = load_script(args.manoeuvre, cfg.loop)
    if args.fast and not robot(cfg.robot).computed_readings:
        raise ValueError(f"--fast: only with a robot whose readings the console computes (sim), not {cfg.robot!r}")
    if not args.headless and not is_loopback(cfg.console.host):
        print(f"WARNING: binding to {cfg.console.host}: the page is reachable from other machines "
              "(control still needs the pilot token)", file=sys.stderr)

    def on_term(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, on_term)
    loading = None  # the loading page, until the console takes its server over
    try:
        if args.headless:  # no formulation switch without a page: only what the run needs
            prep = compiled.prepare(cfg, compiled.needed_steps(cfg))
        else:
            cfg, prep, loading = _prepare_with_page(cfg)
    except KeyboardInterrupt:
        print("\nstopped while starting", file=sys.stderr)
        signal.signal(signal.SIGTERM, previous)
        return 1
    except BaseException:
        signal.signal(signal.SIGTERM, previous)
        raise
    background = [s for s in prep.steps if not s.needed]
    if background and not prep.complete:
        print("compiling in the background: " + ", ".join(s.text for s in background)
              + " (switching to it waits for this)", flush=True)
    try:
        sup = Supervisor(cfg, clock=SimulatedClock() if args.fast else None,
                         planner_ready=lambda f: prep.done(compiled.planner_step(f)), sessions_dir=args.sessions_dir,
                         config_name=config_name(args.config))
    except BaseException:
        prep.cancel()
        if loading is not None:
            loading.stop()
        signal.signal(signal.SIGTERM, previous)
        raise
    started = False  # the run has begun: from here on its recording is kept
    app = None
    scripted = None
    fox = None
    ros = None
    last_power: list[Any] = [None]
    sup.stream.subscribe(lambda c, m: last_power.__setitem__(0, m), [ch.POWER])
    battery = BatteryEnergy()
    sup.stream.subscribe(lambda c, m: battery.add(m.t, m.total), [ch.POWER_ELECTRICAL])
    try:
        sup.set_setpoints(LOCAL, velocity=args.velocity, depth=args.depth, yaw_rate=args.yaw_rate)
        if not args.headless:
            from ucat_console.ui.app import ConsoleApp

            app = ConsoleApp(sup, loading_page=loading)
            loading = None
            app.start()
            if args.playback is not None:
                name = Path(args.playback).name
                directory = app.sessions_dir
                if Path(args.playback).resolve().parent != directory.resolve():
                    raise ValueError(f"--playback: {args.playback} is not in the sessions "
                                     f"directory {directory}")
                if not (directory / name).is_file():
                    raise ValueError(f"--playback: {args.playback}: no such session file")
                app.initial_session = name  # every page opens it in its Review tab
        if args.foxglove_port is not None:
            fox = _foxglove_server(args.foxglove_port, cfg, sup)
        sup.start()
        if fox is not None:  # the stream's clock is set to the wall clock at start, as the recorder's
            fox.epoch_offset = sup.wall0
        if cfg.ros2.enabled:  # after start: the stream's clock is then set to the wall clock (wall0)
            ros = _ros2_publisher(cfg, sup)
        if args.record:
            print(f"recording session {sup.start_recording(LOCAL)}")
        if app is not None:
            print(f"U-CAT console ready on {app.url}  (port {app.port})")
            print(f"pilot token: {sup.access.token}")
        t_stop = args.duration
        if app is None:
            _wait_first_step(sup)
            sup.arm(LOCAL)
            print(f"headless run: mode {sup.mode}, setpoints {sup.setpoints}, motors armed")
            if args.duration is not None:
                # counted from arming: a fast loop runs on while the command reaches it
                t_stop = sup.loop.time + args.duration
            if script is not None:
                scripted = _start_script(sup, script)
        started = True
        period = cfg.console.health_period
        next_health = time.monotonic() + period
        next_token = time.monotonic() + TOKEN_REPEAT
        # again and again only where a person reads it: never into a file or a log collector
        repeat_token = sys.stdout.isatty()
        announced = prep.complete
        while sup.running:
            if t_stop is not None and sup.loop.time >= t_stop:
                break
            if scripted is not None and t_stop is None and scripted.finished:
                break
            time.sleep(0.1 if not args.fast else 0.02)
            now = time.monotonic()
            if now >= next_health:
                next_health += period
                print(sup.health().line(), flush=True)
            if prep.complete and not announced:
                announced = True
                print("compiled in the background: everything is ready" if not prep.error
                      else f"the background compile failed: {prep.error}", flush=True)
            if app is not None and now >= next_token and repeat_token:  # findable on the terminal
                next_token += TOKEN_REPEAT
                print(f"U-CAT console on {app.url}  pilot token: {sup.access.token}", flush=True)
        if sup.fault:
            print(f"the closed loop stopped: {sup.fault}", file=sys.stderr)
    except KeyboardInterrupt:
        print("\nstopping: disarming and closing files", file=sys.stderr)
    finally:
        paths = sup.recorder.paths
        if not started:  # a start that failed or was stopped: no session file (nor its report)
            sup.recorder.discard()
            paths = []
        sup.stop()
        h = sup.health()  # after stopping: disarmed
        if fox is not None:
            fox.stop()
        if ros is not None:
            ros.close()
        if app is not None:
            app.stop()
        elif loading is not None:  # the console did not take its server over
            loading.stop()
        prep.cancel()  # a background compile still running is not waited for
        signal.signal(signal.SIGTERM, previous)
    p = last_power[0]
    print(h.line())
    if p is not None:
        epm = f"{p.energy_per_metre:.1f} J/m" if math.isfinite(p.energy_per_metre) else "n/a"
        print(f"distance {p.distance:.2f} m; the fins' shaft (encoders, while armed): energy {p.energy:.1f} J, "
              f"energy per metre {epm}, mean power {p.mean_total:.2f} W")
    print(battery.line())
    if scripted is not None:
        print(f"manoeuvre {scripted.name}: {scripted.reason or 'not finished'}; "
              f"{len(scripted.results)} of {len(scripted.script.segments)} segments measured")
    for path in paths:
        print(f"recorded {path}")
    return 1 if sup.fault else 0


def _start_script(sup: Any, script: Any) -> Any:
    """The scripted manoeuvre started (its plan printed); each segment's figures are printed
    as they come."""
    from ucat_console.backend.access import LOCAL
    from ucat_console.control.scripted import plan
    from ucat_console.telemetry import channels as ch

    def on_event(channel: str, ev: Any) -> None:
        if ev.source == "manoeuvre":
            print(f"{ev.t:8.1f} s  {ev.message}", flush=True)

    sup.stream.subscribe(on_event, [ch.EVENTS])
    print(plan(script), flush=True)
    run = sup.start_script(LOCAL, script)
    print(f"manoeuvre {script.name} started, recording session {run.session}", flush=True)
    return run


class BatteryEnergy:
    """The drives' battery power over the run (``power/electrical``), by the trapezoid rule
    between consecutive finite readings: a reading a drive did not answer (NaN) is not taken
    as zero, and the time it spans is left out (and said)."""

    def __init__(self) -> None:
        self.energy = 0.0
        self.covered = 0.0
        self.skipped = 0
        self._last: tuple[float, float] | None = None

    def add(self, t: float, total: float) -> None:
        if not math.isfinite(total):
            self.skipped += 1
            self._last = None
            return
        if self._last is not None and t > self._last[0]:
            self.energy += 0.5 * (total + self._last[1]) * (t - self._last[0])
            self.covered += t - self._last[0]
        self._last = (t, total)

    def line(self) -> str:
        if self.covered <= 0.0:
            return "the drives' battery power: no readings"
        gaps = f" ({self.skipped} readings without every drive left out)" if self.skipped else ""
        return (f"the drives' battery power (whole run): energy {self.energy:.1f} J, mean "
                f"{self.energy / self.covered:.2f} W over {self.covered:.1f} s{gaps}")
