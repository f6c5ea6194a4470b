"""The whole application's configuration: one frozen :class:`AppConfig`, TOML in and out.

:class:`AppConfig` composes the blocks defined beside the code that uses them (the
closed loop's ``loop``, which holds the controller's ``mpc``, ``body``, ``baseline``,
``executor``, ``power``; the simulated robot's ``plant``; the ``recorder``; the limits on reading session
files, ``review``; the efficiency figures and their comparison, ``metrics``; the efficiency seeker, ``seek``;
the drivers' ``devices``; the vehicle's ``camera``; the live ROS 2 topics, ``ros2``; the pilot's ``access``, beside
the access control; the ``failsafe`` rules, beside the safety monitor) with the console's own
blocks defined here: ``console`` (web server, plots, supervision) and ``foxglove`` (the live
Foxglove server). This module composes; it is imported by the supervisor and the tools
(command line, benchmarks, experiments), never by the parts it composes.
``robot``, the one robot selector, picks the robot the supervisor drives: ``"sim"`` (the
in-process simulator), ``"sim-devices"`` (the simulator behind the device emulators,
through the drivers) or ``"hardware"`` (the drivers on the robot's devices, ``[devices]``).

A file of an older version (and the configuration an older recording holds) named the
robot with two keys, ``robot = "sim" | "rig"`` and ``devices.robot``; it loads as the one
selector they meant, with a warning naming the keys to replace (:func:`migrate_robot`).

One TOML file configures a run; every table is optional, and its tables follow the object
tree (``[loop.mpc]`` is ``app.loop.mpc``)::

    robot = "sim"
    [loop]
    mode = "mpc_sync"
    [loop.mpc]
    lam_st = 2.0
    [failsafe.pilot_gone]
    action = "hold"
    timeout = 3.0
    escalate = "surface"
    escalate_after = 20.0

One tree, each value held once: the controller blocks (``mpc``, ``body``, ``baseline``,
``executor``, ``power``) live in the closed loop's :class:`LoopConfig` (``app.loop``, what
the loop is handed). An older file wrote them as top-level tables (``[mpc]``); it loads, with
a warning naming the tables to rewrite (:func:`migrate_loop_blocks`). Errors name the dotted
key and the allowed range.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Self
from urllib.parse import urlsplit

import tomli_w

from ucat_console import shipped
from ucat_console.backend.access import AccessConfig
from ucat_console.backend.camera.config import CameraConfig
from ucat_console.backend.devices.config import DevicesConfig
from ucat_console.backend.failsafe_config import FailsafeConfig
from ucat_console.backend.ros_config import Ros2Config
from ucat_console.backend.robots import robot as registered_robot
from ucat_console.backend.robots import robot_names
from ucat_console.backend.loop.config import LoopConfig
from ucat_console.backend.review.metrics import MetricsConfig
from ucat_console.backend.seek.config import SeekConfig
from ucat_console.backend.sessions.limits import ReviewConfig
from ucat_console.backend.sessions.recorder import RecorderConfig
from ucat_console.backend.sim.params import PlantConfig
from ucat_console.typedconf import Config, from_dict, param, to_dict

log = logging.getLogger(__name__)

#: the controller blocks an older file wrote as top-level tables (``[mpc]``), now ``[loop.mpc]``
OLD_LOOP_TABLES = ("mpc", "baseline", "body", "executor", "power")


@dataclass(frozen=True)
class ConsoleConfig(Config):
    """The console process: web server, live view, supervision (console.md)."""

    host: str = param(
        "127.0.0.1", doc="address the web server binds; anything but loopback is warned about"
    )
    port: int = param(8080, lo=0, hi=65535, doc="web server port (0: any free port)")
    allowed_origins: tuple[str, ...] = param(
        (), doc="web origins besides the console's own whose pages may connect, e.g. "
        "'https://console.example.org' for a reverse proxy (each scheme://host[:port])",
    )
    heartbeat_period: float = param(
        0.25, lo=0.05, hi=5.0, unit="s", doc="how often every page is asked to prove it is alive",
    )
    page_timeout: float = param(
        10.0, lo=1.0, hi=3600.0, unit="s",
        doc="a viewer's page that has not answered for this long is closed (the pilot's: failsafe.pilot_gone.timeout)",
    )
    max_pages_per_address: int = param(
        16, lo=1, hi=100_000,
        doc="pages (websockets) one remote address may have open at once, this machine's too; another one "
        "is closed as it opens, with the reason; behind a reverse proxy every page has the proxy's address",
    )
    scene_rate: float = param(40.0, lo=1.0, hi=60.0, unit="Hz", doc="3-D view update rate")
    plot_rate: float = param(12.0, lo=1.0, hi=30.0, unit="Hz", doc="plot refresh rate")
    history: float = param(30.0, lo=5.0, hi=600.0, unit="s", doc="initial plot history window")
    dark: bool = param(True, doc="dark theme for a page that has not chosen (each browser remembers its choice)")
    shadows: bool = param(False, doc="shadows in the 3-D view (costly where the browser renders in software)")
    environment_map: bool = param(
        False, doc="image-based lighting in the 3-D view (costly where the browser renders in software)"
    )
    max_history: float = param(600.0, lo=5.0, hi=3600.0, unit="s", doc="longest history window")
    max_plot_points: int = param(
        600, lo=50, hi=10_000, doc="points per series sent on each plot refresh (longer windows are decimated)"
    )
    trail_points: int = param(600, lo=10, hi=100_000, doc="points in the 3-D trail")
    trail_spacing: float = param(0.05, lo=0.001, hi=10.0, unit="m", doc="distance between trail points")
    supervise_period: float = param(
        0.05, lo=0.005, hi=0.5, unit="s",
        doc="the loop runs in chunks of this length; failsafes and status act between chunks (arming at the loop's next event)",
    )
    max_lag: float = param(
        0.25, lo=0.02, hi=10.0, unit="s",
        doc="a real-time loop held back further than this behind the wall clock (a busy computer) "
        "skips ahead to the present and records the stall (Event loop/stall) instead of replaying "
        "the missed time; a shorter lag is caught up",
    )
    health_period: float = param(5.0, lo=0.5, hi=3600.0, unit="s", doc="terminal health line period")
    record_on_arm: bool = param(True, doc="start recording when the motors are armed")
    record_tail: float = param(
        5.0, lo=0.0, hi=3600.0, unit="s",
        doc="a recording started by arming stops this long after disarming, and after the last "
        "fault (a failsafe, a drive fault) cleared, so that its clearing is recorded",
    )
    record_tail_max: float = param(
        120.0, lo=0.0, hi=86400.0, unit="s",
        doc="a recording started by arming stops this long after disarming at the latest, "
        "whether or not the faults have cleared",
    )
    write_reports: bool = param(
        True, doc="write a run's HTML report (<session id>.report.html, beside its parts) in the "
        "background when its recording stops (docs/review.md)",
    )
    sessions_dir: str = param(
        "", doc="where recordings go; empty: $UCAT_CONSOLE_SESSIONS, else the user's data folder "
        "(ucat-console paths prints it)",
    )
    sim_early: float = param(
        0.01, lo=0.0, hi=0.02, unit="s",
        doc="simulated robot only: loop events due within this much wall time run at once, together "
        "(fewer wake-ups of the loop; 0: each waits for its own time)",
    )
    floor_depth: float = param(3.0, lo=0.1, hi=1000.0, unit="m", doc="depth of the floor grid in the 3-D view")
    drive_velocity_step: float = param(0.05, lo=0.001, hi=1.0, unit="m/s", doc="W/S key: forward velocity step")
    drive_yaw_step: float = param(0.05, lo=0.001, hi=2.0, unit="rad/s", doc="Q/E key: yaw rate step")
    drive_depth_step: float = param(0.1, lo=0.01, hi=5.0, unit="m", doc="R/F key: depth step")
    drive_depth_rate: float = param(0.2, lo=0.01, hi=2.0, unit="m/s",
                                    doc="gamepad: depth change at full stick")

    def _check(self) -> None:
        if self.record_tail_max < self.record_tail:
            raise ValueError(f"record_tail_max: {self.record_tail_max:g} s is shorter than record_tail "
                             f"{self.record_tail:g} s; allowed: at least record_tail")


@dataclass(frozen=True)
class FoxgloveConfig(Config):
    """The live Foxglove server, ``run --foxglove-port`` (sessions.md, The live robot)."""

    allowed_origins: tuple[str, ...] = param(
        (), doc="web origins whose pages may read the live telemetry besides pages of this machine "
        "(http(s)://localhost, 127.0.0.1, [::1]) and desktop apps; e.g. 'https://app.foxglove.dev' for "
        "the Foxglove web app (each scheme://host[:port])",
    )

    def _check(self) -> None:
        for origin in self.allowed_origins:
            try:
                parts = urlsplit(origin)
                ok = parts.port is None or parts.port > 0  # a port that is not a number raises
            except ValueError:
                ok = False
            if not ok or parts.scheme not in ("http", "https") or not parts.hostname \
                    or parts.path not in ("", "/") or parts.query or parts.fragment or parts.username is not None:
                raise ValueError(f"allowed_origins: {origin!r} is not a web origin; allowed: "
                                 "scheme://host[:port] with scheme http or https, e.g. 'https://app.foxglove.dev'")


@dataclass(frozen=True)
class AppConfig(Config):
    """Everything one run of the console needs (module docstring)."""

    robot: str = param(
        "sim", choices=robot_names,
        doc="the robot to drive: sim: in-process simulator; sim-devices: simulator behind the device "
        "emulators, through the drivers; hardware: the drivers on the robot's devices ([devices])",
    )
    loop: LoopConfig = LoopConfig()
    plant: PlantConfig = PlantConfig()
    recorder: RecorderConfig = RecorderConfig()
    review: ReviewConfig = ReviewConfig()
    metrics: MetricsConfig = MetricsConfig()
    seek: SeekConfig = SeekConfig()
    console: ConsoleConfig = ConsoleConfig()
    access: AccessConfig = AccessConfig()
    failsafe: FailsafeConfig = FailsafeConfig()
    devices: DevicesConfig = DevicesConfig()
    camera: CameraConfig = CameraConfig()
    foxglove: FoxgloveConfig = FoxgloveConfig()
    ros2: Ros2Config = Ros2Config()

    def _check(self) -> None:
        deepest, envelope = self.devices.plausibility.max_depth, self.loop.max_depth
        if deepest < envelope:
            raise ValueError(
                f"devices.plausibility.max_depth: {deepest:g} m is shallower than loop.max_depth "
                f"{envelope:g} m: the depth readings of a robot sent that deep would be dropped as "
                f"implausible; allowed: at least loop.max_depth (or lower loop.max_depth)")
        hb, gone = self.console.heartbeat_period, self.failsafe.pilot_gone.timeout
        if 3.0 * hb > gone:
            raise ValueError(
                f"console.heartbeat_period: {hb:g} s is too long for failsafe.pilot_gone.timeout "
                f"{gone:g} s: a page is asked for a heartbeat every period and is gone after "
                f"three unanswered ones at the least; allowed: at most {gone / 3.0:g} s")

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Self:
        if isinstance(data, dict):
            data = migrate_loop_blocks(migrate_sim_depth(migrate_robot(data)))
        return from_dict(cls, data)

    def to_dict(self, redact: bool = False) -> dict[str, Any]:
        """The configuration as TOML tables; ``redact`` leaves the secret fields out."""
        return to_dict(self, redact)

    def to_toml(self, redact: bool = False) -> str:
        return tomli_w.dumps(self.to_dict(redact))

    @property
    def simulated(self) -> bool:
        """Whether the robot is (or is behind the emulators of) the simulated plant."""
        return registered_robot(self.robot).simulated


def migrate_robot(data: dict[str, Any]) -> dict[str, Any]:
    """``data`` with an older version's two robot keys (``robot = "sim" | "rig"`` and
    ``devices.robot``) made the one selector they meant, with a warning naming the keys to
    replace; ValueError for a pair that meant nothing (``"rig"`` with ``devices.robot = "sim"``)."""
    devices = data.get("devices")
    old = devices.get("robot") if isinstance(devices, dict) else None
    top = data.get("robot")
    if old is None and top != "rig":
        return data
    if top == "rig":
        new = "sim-devices" if old is None else old
        if new == "sim":
            raise ValueError("devices.robot: 'sim' is the in-process simulator, robot = 'rig' the drivers; "
                             "the robot is one key now: robot = 'sim', 'sim-devices' or 'hardware'")
    else:
        new = "sim" if top is None else top  # the simulator ignored devices.robot
    data = {**data, "robot": new}
    if isinstance(devices, dict):
        data["devices"] = {k: v for k, v in devices.items() if k != "robot"}
    keys = " and ".join(k for k, given in (("robot = 'rig'", top == "rig"),
                                            (f"devices.robot = {old!r}", old is not None)) if given)
    log.warning("configuration: %s: the robot is one key now; loaded as robot = %r (write that instead)",
                keys, new)
    return data


def migrate_sim_depth(data: dict[str, Any]) -> dict[str, Any]:
    """``data`` with an older version's ``console.sim_depth`` made the simulated robot's one
    start, ``devices.start.depth``, with a warning naming the key to replace; ValueError
    when both are given and differ."""
    console = data.get("console")
    if not isinstance(console, dict) or "sim_depth" not in console:
        return data
    depth = console["sim_depth"]
    devices = data.get("devices") if isinstance(data.get("devices"), dict) else {}
    start = devices.get("start") if isinstance(devices.get("start"), dict) else {}
    if "depth" in start and start["depth"] != depth:
        raise ValueError(f"console.sim_depth: {depth!r} and devices.start.depth {start['depth']!r} both give the "
                         "simulated robot's start depth; keep devices.start.depth only")
    log.warning("configuration: console.sim_depth: the simulated robot's start is devices.start now; loaded as "
                "devices.start.depth = %r (write that instead)", depth)
    return {**data, "console": {k: v for k, v in console.items() if k != "sim_depth"},
            "devices": {**devices, "start": {**start, "depth": depth}}}


def migrate_loop_blocks(data: dict[str, Any]) -> dict[str, Any]:
    """``data`` with an older version's top-level controller tables (``[mpc]``, ``[body]``,
    ...) moved into the loop's table, where the object tree holds them (``[loop.mpc]``), with a
    warning naming the tables to rewrite; ValueError naming both keys when a key is given in
    both places with different values."""
    old = [name for name in OLD_LOOP_TABLES if name in data]
    if not old:
        return data
    loop = data.get("loop", {})
    if not isinstance(loop, dict):
        raise ValueError(f"loop: expected a table, got {loop!r}")
    merged = dict(loop)
    for name in old:
        merged[name] = _merged(data[name], loop[name], name, f"loop.{name}") if name in loop else data[name]
    log.warning("configuration: %s: the controller blocks are tables of [loop] now; loaded as %s "
                "(write those instead)", ", ".join(f"[{n}]" for n in old), ", ".join(f"[loop.{n}]" for n in old))
    return {**{k: v for k, v in data.items() if k not in old}, "loop": merged}


def _merged(old: Any, new: Any, old_key: str, new_key: str) -> Any:
    """One value given at ``old_key`` and ``new_key``: tables merged key by key, equal values
    kept; ValueError naming both keys when they differ."""
    if isinstance(old, dict) and isinstance(new, dict):
        return {**old, **new, **{k: _merged(old[k], new[k], f"{old_key}.{k}", f"{new_key}.{k}")
                                 for k in old.keys() & new.keys()}}
    if old != new:
        raise ValueError(f"{old_key}: {old!r} and {new_key} {new!r} both give it; keep {new_key} only")
    return new


def load_config(path: str | Path | None) -> AppConfig:
    """The configuration in ``path``, a file or the name of a shipped configuration
    (``sim-tuned``: :mod:`ucat_console.shipped`); defaults everywhere when None."""
    return AppConfig() if path is None else AppConfig.from_toml(shipped.config_path(path))


def known_configs() -> dict[str, str]:
    """The shipped configurations' (and the defaults') names by the hash of their TOML text,
    as a recording stores it: the run library names a recording that names none by an exact
    match (the shell's ``sessions`` commands and the console's Review tab)."""
    from ucat_console.backend.sessions.library_read import config_hash

    out = {config_hash(AppConfig().to_toml(redact=True)): "default"}
    for name in shipped.config_names():
        try:
            out[config_hash(load_config(name).to_toml(redact=True))] = name
        except ValueError:  # a shipped file this version cannot read: it names nothing
            continue
    return out
