"""Failsafes: each watches one cause, triggers after its timeout, latches until the cause clears.

The :class:`SafetyMonitor` is a telemetry subscriber (sensor channels and events) plus two
inputs from the supervisor (the pilot's presence, :meth:`SafetyMonitor.pilot_left` and
:meth:`SafetyMonitor.pilot_present`). :meth:`SafetyMonitor.check` is called with the
present time; it returns the failsafes that triggered or cleared since the last call. The
supervisor carries out the configured action (hold, surface, disarm, warn) and records an
Event for each change.

Failsafes (``FailsafeConfig`` has one rule, action and timeout, for each):

* ``pilot_gone``: a pilot was in control and no pilot page has been connected for
  ``timeout`` s; clears when a pilot takes control again.
* ``imu`` / ``dvl`` / ``depth``: no valid reading for ``timeout`` s (silent, or only
  invalid readings: a DVL report with ``valid`` False, a non-finite value); clears with the
  next valid reading.
* ``motor``: a motor controller reported a fault (an Event from a source ``epos2.*`` with a
  code of :data:`MOTOR_FAULTS`) that has lasted ``timeout`` s; clears when every such fault
  has been reported cleared (:data:`MOTOR_CLEARS`).
* ``planner_late``: at least ``late_plans`` late plans (loop Events ``late_plan``) within
  the last ``timeout`` s; clears when fewer remain in that window.
* ``tracking``: while the fins are driven, the depth, the forward speed or the heading
  (``body/tracking``) has been further than its band (``tracking_depth``,
  ``tracking_speed``, ``tracking_heading``) from what the body layer holds it to for
  ``timeout`` s; clears when every axis is back within its band. Warns by default: the
  robot does not go where it is sent.

Times are the supervisor's clock (the loop's time). A valid sensor reading counts at its
own time ``t`` (the robot stamps readings with the loop's time; one more than a minute away
from the last check counts at that check's time); events are stamped with the time of the
check before they arrived, so their resolution is the supervisor's check period.
"""

from __future__ import annotations

import collections
import logging
import math
import threading
from dataclasses import dataclass
from typing import Any

from ucat_console.robot.readings import DepthReading, DvlVelocity, ImuReading
from ucat_console.config import FailsafeConfig, FailsafeRule
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.events import Event

log = logging.getLogger(__name__)

#: every failsafe, in display order
FAILSAFES = ("pilot_gone", "imu", "dvl", "depth", "motor", "planner_late", "tracking")
SENSORS = ("imu", "dvl", "depth")
#: motor controller event codes that start a fault (a ``quick_stop`` event is the other
#: drives' safe-state reaction to one of these, which the failsafe already counts)
MOTOR_FAULTS = frozenset({"fault", "emcy", "heartbeat_lost"})
#: event codes that clear motor faults, and which
MOTOR_CLEARS: dict[str, frozenset[str]] = {
    "fault_cleared": frozenset({"fault", "emcy"}),
    "emcy_reset": frozenset({"emcy"}),
    "heartbeat_restored": frozenset({"heartbeat_lost"}),
}
#: the channels the monitor subscribes to
CHANNELS = (ch.IMU, ch.DVL, ch.DEPTH, ch.EVENTS, ch.BODY_TRACKING, ch.BODY_ALLOCATION)
#: the tracked axes: (name, the message's error field, the band's config field, unit)
TRACKED = (("depth", "depth_error", "tracking_depth", "m"), ("speed", "speed_error", "tracking_speed", "m/s"),
           ("heading", "heading_error", "tracking_heading", "rad"))


@dataclass(frozen=True)
class FailsafeState:
    """One failsafe as shown: its rule, whether it is active, and why."""

    name: str
    action: str
    timeout: float
    active: bool
    since: float | None  # time it triggered
    cause: str  # what is (or was last) wrong, "" when nothing


@dataclass(frozen=True)
class Transition:
    """A failsafe that triggered (``active``) or cleared at time ``t``."""

    name: str
    active: bool
    t: float
    action: str
    cause: str


def _finite(*values: float) -> bool:
    isfinite = math.isfinite
    for v in values:
        if not (isinstance(v, (int, float)) and isfinite(v)):
            return False
    return True


def reading_valid(reading: Any) -> bool:
    """Whether a sensor reading carries usable data."""
    if isinstance(reading, ImuReading):
        return _finite(*reading.gyro, *reading.accel_g)
    if isinstance(reading, DvlVelocity):
        return bool(reading.valid) and _finite(reading.vx, reading.vy, reading.vz)
    if isinstance(reading, DepthReading):
        return _finite(reading.depth_m)
    return False


_CLOCK_SLACK = 60.0  # s
_SENSOR_OF = {ch.IMU: "imu", ch.DVL: "dvl", ch.DEPTH: "depth"}


class SafetyMonitor:
    """Watches the failsafe causes (module docstring); thread-safe."""

    def __init__(self, cfg: FailsafeConfig | None = None, t0: float = 0.0) -> None:
        self.cfg = cfg or FailsafeConfig()
        self._lock = threading.Lock()
        self._now = float(t0)
        self._last_valid: dict[str, float] = {s: float(t0) for s in SENSORS}
        self._invalid: dict[str, int] = {s: 0 for s in SENSORS}  # invalid readings since the last valid one
        self._had_pilot = False
        self._pilot_left: float | None = None
        self._motor: dict[str, dict[str, float]] = {}  # source -> fault code -> since
        self._late: collections.deque[float] = collections.deque()
        self._off_track: dict[str, tuple[float, float]] = {}  # axis -> (since, the last error)
        self._allocation: Any = None  # the last BodyAllocation
        self._active: dict[str, float] = {}  # name -> since
        self._cause: dict[str, str] = {n: "" for n in FAILSAFES}

    def rule(self, name: str) -> FailsafeRule:
        if name not in FAILSAFES:
            raise ValueError(f"failsafe: {name!r} is not one of {', '.join(FAILSAFES)}")
        return getattr(self.cfg, name)

    # ------------------------------------------------------------------ inputs
    def on_message(self, channel: str, msg: Any) -> None:
        """Telemetry subscriber (subscribe it to :data:`CHANNELS`)."""
        self.on_messages(((channel, msg),))

    def on_messages(self, items: Any) -> None:
        """Telemetry subscriber of (channel, message) lists (``subscribe_batches``)."""
        events = []
        with self._lock:
            last_valid, invalid, now = self._last_valid, self._invalid, self._now
            for channel, msg in items:
                sensor = _SENSOR_OF.get(channel)
                if sensor is None:
                    if channel == ch.EVENTS and isinstance(msg, Event):
                        events.append(msg)
                    elif channel == ch.BODY_TRACKING:
                        self._track(msg)
                    elif channel == ch.BODY_ALLOCATION:
                        self._allocation = msg
                elif reading_valid(msg):
                    t = msg.t
                    # readings carry the loop's time; one off by more than a minute does not
                    if not (isinstance(t, (int, float)) and abs(t - now) <= _CLOCK_SLACK):
                        t = now
                    if t > last_valid[sensor]:
                        last_valid[sensor] = t
                    invalid[sensor] = 0
                else:
                    invalid[sensor] += 1
        for ev in events:
            self.on_event(ev)

    def _track(self, msg: Any) -> None:
        """A tracking message: each axis out of its band since when (the lock is held)."""
        off = self._off_track
        for axis, field, band, _unit in TRACKED:
            err = getattr(msg, field, math.nan)
            if msg.driving and _finite(err) and abs(err) > getattr(self.cfg, band):
                since = off[axis][0] if axis in off else msg.t
                off[axis] = (since, err)
            else:
                off.pop(axis, None)

    def on_event(self, ev: Event) -> None:
        with self._lock:
            if ev.source.startswith("epos2"):
                faults = self._motor.setdefault(ev.source, {})
                if ev.code in MOTOR_FAULTS:
                    faults.setdefault(ev.code, self._now)
                elif ev.code in MOTOR_CLEARS:
                    for code in MOTOR_CLEARS[ev.code]:
                        faults.pop(code, None)
                elif ev.code == "recovered" and isinstance(ev.data.get("fault"), str):
                    faults.pop(ev.data["fault"], None)
            elif ev.source == "loop" and ev.code == "late_plan":
                self._late.append(self._now)

    def note_invalid(self, sensor: str, what: str = "") -> None:
        """A reading of ``sensor`` was refused before it reached the stream (non-finite)."""
        if sensor not in SENSORS:
            raise ValueError(f"sensor: {sensor!r} is not one of {', '.join(SENSORS)}")
        with self._lock:
            self._invalid[sensor] += 1

    def pilot_present(self, now: float | None = None) -> None:
        with self._lock:
            self._had_pilot = True
            self._pilot_left = None

    def pilot_left(self, now: float | None = None) -> None:
        """The pilot's page is gone (at ``now``; default: the last check's time)."""
        with self._lock:
            if self._had_pilot and self._pilot_left is None:
                self._pilot_left = self._now if now is None else float(now)

    def pilot_released(self) -> None:
        """The pilot gave up control on purpose: nobody is expected to fly."""
        with self._lock:
            self._had_pilot = False
            self._pilot_left = None

    # ------------------------------------------------------------------ evaluation
    def check(self, now: float) -> list[Transition]:
        """Evaluate every failsafe at ``now``; the ones that triggered or cleared."""
        out: list[Transition] = []
        with self._lock:
            self._now = float(now)
            causes = self._causes(now)
            for name in FAILSAFES:
                rule: FailsafeRule = getattr(self.cfg, name)
                cause = causes.get(name)
                if cause is not None:
                    self._cause[name] = cause
                was = name in self._active
                if cause is not None and not was:
                    self._active[name] = now
                    out.append(Transition(name, True, now, rule.action, cause))
                elif cause is None and was:
                    del self._active[name]
                    out.append(Transition(name, False, now, rule.action, self._cause[name]))
        for tr in out:
            log.log(logging.ERROR if tr.active else logging.INFO, "failsafe %s %s: %s",
                    tr.name, "triggered" if tr.active else "cleared", tr.cause)
        return out

    def _causes(self, now: float) -> dict[str, str]:
        cfg = self.cfg
        causes: dict[str, str] = {}
        if self._pilot_left is not None:
            gone = now - self._pilot_left
            if gone >= cfg.pilot_gone.timeout:
                causes["pilot_gone"] = f"no pilot page for {gone:.1f} s"
        for s in SENSORS:
            rule = getattr(cfg, s)
            quiet = now - self._last_valid[s]
            if quiet > rule.timeout:
                n = self._invalid[s]
                what = f"{n} invalid readings" if n else "silent"
                causes[s] = f"{s.upper()} without a valid reading for {quiet:.1f} s ({what})"
        faults = []
        for source, codes in sorted(self._motor.items()):
            for code, since in sorted(codes.items()):
                if now - since >= cfg.motor.timeout:
                    faults.append(f"{source} {code}")
        if faults:
            causes["motor"] = "motor controller fault: " + ", ".join(faults)
        window = cfg.planner_late.timeout
        late = self._late
        while late and now - late[0] > window:
            late.popleft()
        if len(late) >= cfg.late_plans:
            causes["planner_late"] = f"{len(late)} late plans in the last {window:g} s"
        off = [f"{axis} {err:+.2f} {unit} off its reference for {now - since:.0f} s"
               for axis, _f, _b, unit in TRACKED if axis in self._off_track
               for since, err in (self._off_track[axis],) if now - since >= cfg.tracking.timeout]
        if off:
            causes["tracking"] = "not tracking: " + ", ".join(off)
        return causes

    # ------------------------------------------------------------------ reading
    def sensor_silence(self, sensor: str, now: float) -> tuple[float, int]:
        """(seconds since ``sensor``'s last valid reading at ``now``, invalid readings since)."""
        if sensor not in SENSORS:
            raise ValueError(f"sensor: {sensor!r} is not one of {', '.join(SENSORS)}")
        with self._lock:
            return max(0.0, now - self._last_valid[sensor]), self._invalid[sensor]

    def recent_late_plans(self) -> int:
        """Late plans within the planner_late window (at the last check)."""
        with self._lock:
            return len(self._late)

    def control(self) -> tuple[list[str], list[str]]:
        """(the axes the allocation cuts now, each as "axis: given of asked"; the tracked axes
        off their band now, each as "axis error unit for s")."""
        with self._lock:
            a, now = self._allocation, self._now
            cut = []
            if a is not None:
                units = {"surge": (a.surge, a.surge_applied, "N"), "heave": (a.heave, a.heave_applied, "N"),
                         "yaw": (a.yaw, a.yaw_applied, "N m")}
                for axis in a.cut:
                    if axis == "coast":
                        cut.append("coasting: the hull's drag slows the robot")
                    elif axis in units:
                        asked, given, unit = units[axis]
                        cut.append(f"{axis}: {given:.2f} of {asked:.2f} {unit}")
            off = [f"{axis} {err:+.2f} {unit} for {max(0.0, now - since):.0f} s"
                   for axis, _f, _b, unit in TRACKED if axis in self._off_track
                   for since, err in (self._off_track[axis],)]
            return cut, off

    def motor_faults(self) -> list[str]:
        """The motor controller faults reported and not cleared ("source code")."""
        with self._lock:
            return [f"{src} {code}" for src, codes in sorted(self._motor.items()) for code in sorted(codes)]

    def active(self) -> tuple[str, ...]:
        with self._lock:
            return tuple(n for n in FAILSAFES if n in self._active)

    def is_active(self, name: str) -> bool:
        with self._lock:
            return name in self._active

    def states(self) -> list[FailsafeState]:
        with self._lock:
            out = []
            for name in FAILSAFES:
                rule: FailsafeRule = getattr(self.cfg, name)
                out.append(FailsafeState(
                    name=name, action=rule.action, timeout=rule.timeout,
                    active=name in self._active, since=self._active.get(name),
                    cause=self._cause[name],
                ))
            return out
