# Over 600 lines: every failsafe's trigger, latch and escalation run in one monitor, under one lock, so that no two failsafes act on stale state.
"""Failsafes: each watches one cause, triggers after its timeout, latches until the cause clears.

The :class:`SafetyMonitor` is a telemetry subscriber (sensor channels and events) plus two
inputs from the supervisor (the pilot's presence, :meth:`SafetyMonitor.pilot_left` and
:meth:`SafetyMonitor.pilot_present`). :meth:`SafetyMonitor.check` is called with the
present time; it returns the failsafes that triggered, escalated or cleared since the last
call. The supervisor carries out the action each carries (hold, surface, disarm, warn) and
records an Event for each change.

Escalation: a rule with ``escalate`` (hold, surface, disarm: acting more strongly than its
``action``) escalates when its failsafe has been active for ``escalate_after`` s: a second
Transition, active, with the escalated action (``escalated`` True). By default only
``pilot_gone`` escalates: hold, then disarm after 30 s.

Failsafes (``FailsafeConfig`` has one rule, action and timeout, for each):

* ``pilot_gone``: a pilot was in control and no pilot page has been connected for
  ``timeout`` s; clears when a pilot takes control again.
* ``imu`` / ``dvl`` / ``depth``: no valid reading for ``timeout`` s; clears with the next
  valid reading. The cause says what happened since the last valid reading: ``silent``
  (nothing came), ``garbled`` (messages dropped as corrupt), ``invalid`` (readings that
  came without valid data: a DVL report with ``valid`` False, a non-finite value, a
  broken current loop), ``implausible`` (readings dropped by the plausibility checks,
  ``devices.plausibility``, with the last one's reason), ``port error``, ``unreachable``,
  from the readings and from the sensor's driver events
  (``devices.reporting.READING_FAULTS``). A dropped reading never reaches the stream, so
  it is not a valid one.
* ``motor``: a motor controller reported a fault (an Event from a source ``epos2.*`` with a
  code of :data:`MOTOR_FAULTS`) that has lasted ``timeout`` s; clears when every such fault
  has been reported cleared (:data:`MOTOR_CLEARS`). The cause names each drive and what
  it reported (the event's message: the EMCY code and its name, how long no heartbeat came).
* ``planner_late``: at least ``late_plans`` late plans (loop Events ``late_plan``) within
  the last ``timeout`` s; clears when fewer remain in that window.
* ``tracking``: while the fins are driven, the depth, the forward speed or the heading
  (``body/tracking``) has been further than its band (``tracking_depth``,
  ``tracking_speed``, ``tracking_heading``) from its expected response for ``timeout`` s:
  outside the envelope between the body layer's reference and the slowest response the body
  layer is designed to give, started when the fins start their first stroke
  (:mod:`~ucat_console.backend.tracking_alarm`; ``tracking_delay``, ``tracking_bandwidth``,
  ``tracking_heading_bandwidth``, ``tracking_max_*``), so that a start from rest, the fins
  late on a busy computer, is not an alarm; or a fin is reported slow (loop Event
  ``fin_slow``, not yet ``fin_slow_cleared``: its cycles take longer than planned, a weak,
  lagging or stuck drive), at once. Clears when every axis is back within its band and no
  fin is slow. Warns by default: the robot does not go where it is sent.
* ``recording``: the session recorder failed to write (an Event ``recorder``/``write_failed``:
  a full disk, a removed drive) and has not been started again or acknowledged since (an
  Event ``recorder``/``failure_cleared``). Warns by default (``hold`` keeps the robot where
  it is until the operator acts): what the robot does from then on is not recorded.
* ``loop_watchdog``: the control loop has not stepped for ``timeout`` s (the supervisor's
  :class:`~ucat_console.backend.supervisor.watchdog.LoopWatchdog`, a thread of its own).
  It triggers at once, from the watchdog's thread (:meth:`SafetyMonitor.loop_stuck`: the
  loop's thread, which calls :meth:`SafetyMonitor.check`, is the one stuck), and clears at
  the first check after the loop steps again (:meth:`SafetyMonitor.loop_resumed`). It watches
  a loop paced by the wall clock only: under a simulated clock (``run --headless --fast``)
  the simulated robot stands still while the loop does, and a loop held back by a busy
  computer is a slower run, not a robot out of control.
* ``depth_limit``: every valid depth reading for ``timeout`` s deeper than ``max_depth``;
  clears with a valid reading within it.
* ``altitude``: every valid DVL altitude (finite, above 0: a report without one is not an
  altitude of 0 and neither starts nor clears it) for ``timeout`` s shorter than
  ``min_altitude``; clears with a valid altitude at least that long. Both surface by default.
* ``battery_low`` (warns) / ``battery_critical`` (surfaces): from the drives' electrical
  input (``power/electrical``): the lowest supply voltage of the drives that answered
  below ``battery_low_voltage`` / ``battery_critical_voltage`` for ``timeout`` s (a NaN
  voltage, a drive that did not answer, is left out, never a zero: that drive is the motor
  failsafe's), or, with a ``battery_capacity``, the energy the drives drew since the start
  leaving less than ``battery_low_reserve`` / ``battery_critical_reserve`` of it (at once;
  it never comes back). A voltage back above the threshold clears it.
* ``estimate``: the attitude estimate (the body state's orientation) disagrees with the
  accelerometer: every IMU reading taken at rest (the specific force within the EKF's
  ``accel_gate`` of g0; the others measure no gravity and are skipped) for ``timeout`` s
  further than ``estimate_innovation`` from the gravity direction the estimate predicts
  (``control.estimation.gravity_innovation``, the EKF correction's innovation as an angle);
  or the estimate stopped: IMU readings for ``timeout`` s past the last body state (a
  stalled loop, whose readings and states resume together, is not one). Clears with a
  reading within the bound and a body state.

Then each registered sensor's failsafe (:mod:`~ucat_console.backend.sensors`, its rule
``FailsafeConfig.rule(name)``): its readings (channel ``sensors/<name>``) tripping its
condition for ``timeout`` s (the cause is the condition's, from the first such reading's
time), or, when it has a ``stale_after``, no reading for ``stale_after`` + ``timeout`` s
since the sensor was opened (:meth:`SafetyMonitor.sensors_open`) or last read; clears with a
reading that does not trip it.
The first is the leak detector's, ``leak``: water at the probe (surface at once); an
unreadable detector keeps the last level read and is shown by its light, not counted as
water.

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

from ucat_console.backend.devices.reporting import READING_FAULTS
from ucat_console.backend.tracking_alarm import AxisModel, Envelope
from ucat_console.robot.readings import DepthReading, DvlVelocity, ImuReading
from ucat_console.backend.failsafe_config import FailsafeConfig, FailsafeRule
from ucat_console.backend.failsafe_rule import FIXED_FAILSAFES
from ucat_console.backend.sensors import SENSORS as REGISTERED
from ucat_console.backend.sensors import sensor_failsafe_names
from ucat_console.control.estimation import AttitudeConfig, gravity_innovation
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.events import Event

log = logging.getLogger(__name__)

#: the console's own failsafes, in display order (the registered sensors' come after them:
#: :func:`failsafe_names`)
FAILSAFES = FIXED_FAILSAFES
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
#: the channels the monitor subscribes to (and the registered sensors': :func:`channels`)
CHANNELS = (ch.IMU, ch.DVL, ch.DEPTH, ch.EVENTS, ch.BODY_TRACKING, ch.BODY_ALLOCATION, ch.POWER_ELECTRICAL,
            ch.BODY_STATE, *(ch.fin_strouhal(i) for i in range(ch.N_FINS)))


def failsafe_names() -> tuple[str, ...]:
    """Every failsafe, in display order: the console's own, then the registered sensors' (read live)."""
    return FAILSAFES + sensor_failsafe_names()


def channels() -> tuple[str, ...]:
    """The channels the monitor takes: :data:`CHANNELS` and those of the registered sensors
    with a failsafe (read live)."""
    return CHANNELS + tuple(s.channel for s in REGISTERED.values() if s.failsafe is not None)
#: the channels whose messages mark a fin's stroke starting
_STROKES = frozenset(ch.fin_strouhal(i) for i in range(ch.N_FINS))
#: the specific force's largest departure from g0 at which it measures gravity's direction (g0)
ACCEL_GATE = AttitudeConfig().accel_gate
#: the battery failsafes: (name, its voltage threshold, its reserve fraction)
BATTERY = (("battery_low", "battery_low_voltage", "battery_low_reserve"),
           ("battery_critical", "battery_critical_voltage", "battery_critical_reserve"))
#: the longest gap between two electrical messages counted as drawing power (s)
_ENERGY_GAP = 1.0
#: the tracked axes: (name, the message's error field, the band's config field, unit)
TRACKED = (("depth", "depth_error", "tracking_depth", "m"), ("speed", "speed_error", "tracking_speed", "m/s"),
           ("heading", "heading_error", "tracking_heading", "rad"))
#: each tracked axis's reference field
_REF = {"depth": "depth_ref", "speed": "speed_ref", "heading": "heading_ref"}


def expected_response(cfg: FailsafeConfig) -> dict[str, AxisModel]:
    """Each tracked axis's slowest expected response (``backend.tracking_alarm``)."""
    return {"depth": AxisModel(cfg.tracking_delay, cfg.tracking_bandwidth, cfg.tracking_max_dive_rate),
            "speed": AxisModel(cfg.tracking_delay, cfg.tracking_bandwidth, cfg.tracking_max_acceleration),
            "heading": AxisModel(cfg.tracking_delay, cfg.tracking_heading_bandwidth, cfg.tracking_max_yaw_rate,
                                 angle=True)}


@dataclass(frozen=True)
class FailsafeState:
    """One failsafe as shown: its rule, whether it is active, and why."""

    name: str
    action: str  # the action in force: the escalated one once the failsafe escalated
    timeout: float
    active: bool
    since: float | None  # time it triggered
    cause: str  # what is (or was last) wrong, "" when nothing


@dataclass(frozen=True)
class Transition:
    """A failsafe that triggered (``active``), escalated (``active`` and ``escalated``: its
    cause lasted the rule's ``escalate_after``; ``action`` is the escalated one) or cleared
    at time ``t``."""

    name: str
    active: bool
    t: float
    action: str
    cause: str
    escalated: bool = False


def _finite(*values: float) -> bool:
    isfinite = math.isfinite
    for v in values:
        if not (isinstance(v, (int, float)) and isfinite(v)):
            return False
    return True


def reading_valid(reading: Any) -> bool:
    """Whether a sensor reading carries usable data."""
    if isinstance(reading, ImuReading):
        return _finite(*reading.gyro, *reading.accel)
    if isinstance(reading, DvlVelocity):
        return bool(reading.valid) and _finite(reading.vx, reading.vy, reading.vz)
    if isinstance(reading, DepthReading):
        return _finite(reading.depth_m)
    return False


_CLOCK_SLACK = 60.0  # s
_SENSOR_OF = {ch.IMU: "imu", ch.DVL: "dvl", ch.DEPTH: "depth"}
#: the failsafe sensor of each sensor driver's event source
_SENSOR_OF_SOURCE = {"imu": "imu", "dvl": "dvl", "pressure": "depth"}
#: how a label reads with its count (messages or readings since the last valid one)
_COUNTED = {"garbled": "corrupt messages dropped", "invalid": "invalid readings",
            "implausible": "readings dropped"}


def fault_label(kinds: dict[str, Any]) -> str:
    """What happened to a sensor since its last valid reading, from the kinds seen with
    their counts and the last reason given (``{"garbled": [12, t, ""]}`` -> ``"garbled: 12
    corrupt messages dropped"``; ``{"implausible": [3, t, "depth 104.8 m beyond ..."]}`` ->
    ``"implausible: 3 readings dropped, depth 104.8 m beyond ..."``): ``silent`` only when
    nothing else was seen (a garbled line is not a silent one)."""
    parts = []
    for kind, (n, _t, why) in kinds.items():
        if kind == "silent":
            continue
        part = f"{kind}: {int(n)} {_COUNTED[kind]}" if kind in _COUNTED else kind
        parts.append(f"{part}, {why}" if why else part)
    return ", ".join(parts) or "silent"


def _note(kinds: dict[str, list[Any]], kind: str, n: int, t: float, why: str = "") -> None:
    """``n`` more of ``kind`` at time ``t`` (the latest ``why``, when given)."""
    seen = kinds.get(kind)
    if seen is None:
        kinds[kind] = [float(n), t, why]
    else:
        seen[0] += n
        seen[1] = max(seen[1], t)
        if why:
            seen[2] = why


def _stamp(t: Any, now: float) -> float:
    """A message's time, or ``now`` when it carries none near the loop's time."""
    return float(t) if isinstance(t, (int, float)) and abs(t - now) <= _CLOCK_SLACK else now


class SafetyMonitor:
    """Watches the failsafe causes (module docstring); thread-safe."""

    def __init__(self, cfg: FailsafeConfig | None = None, t0: float = 0.0) -> None:
        self.cfg = cfg or FailsafeConfig()
        self._lock = threading.Lock()
        self._now = float(t0)
        self._last_valid: dict[str, float] = {s: float(t0) for s in SENSORS}
        # what happened to each sensor since its last valid reading: kind -> [count, last time]
        self._kinds: dict[str, dict[str, list[Any]]] = {s: {} for s in SENSORS}
        self._had_pilot = False
        self._pilot_left: float | None = None
        self._motor: dict[str, dict[str, tuple[float, str]]] = {}  # source -> fault code -> (since, message)
        self._late: collections.deque[float] = collections.deque()
        self._off_track: dict[str, tuple[float, float]] = {}  # axis -> (since, the last error)
        self._expected = {axis: Envelope(m) for axis, m in expected_response(self.cfg).items()}
        self._driving = False  # the last tracking message's
        self._fins_started = False  # a stroke started since the fins were driven
        self._slow_fins: dict[int, tuple[float, str]] = {}  # paper fin -> (since, what was reported)
        self._fin_scale = ""  # what the loop reported of the fins' measured force scale ("": the model's)
        self._allocation: Any = None  # the last BodyAllocation
        self._recorder_failed: tuple[float, str] | None = None  # (since, why)
        self._loop_stuck: str | None = None  # why, while the loop watchdog holds it stuck
        #: the last valid depth and altitude: (time, value)
        self._depth: tuple[float, float] | None = None
        self._altitude: tuple[float, float] | None = None
        self._beyond: dict[str, tuple[float, float]] = {}  # depth_limit, altitude, battery_* -> (since, the last value)
        self._volts: tuple[float, float] | None = None  # the last lowest supply voltage: (time, V)
        self._power: tuple[float, float] | None = None  # the last battery power: (time, W)
        self._energy = 0.0  # J drawn by the drives since the start
        #: the registered sensors' failsafes: what trips each, (since, cause); the last reading's time
        self._tripped: dict[str, tuple[float, str]] = {}
        self._sensor_seen: dict[str, float] = {}
        self._estimate: tuple[float, Any] | None = None  # the last body state: (time, orientation)
        self._innovation: tuple[float, float] | None = None  # the last finite innovation: (time, rad)
        self._active: dict[str, float] = {}  # name -> since
        self._escalated: set[str] = set()  # active failsafes whose escalation acted
        self._cause: dict[str, str] = {}

    def rule(self, name: str) -> FailsafeRule:
        names = failsafe_names()
        if name not in names:
            raise ValueError(f"failsafe: {name!r} is not one of {', '.join(names)}")
        return self.cfg.rule(name)

    def sensors_open(self, names: tuple[str, ...], now: float | None = None) -> None:
        """The registered sensors ``names`` are open (at ``now``; default: the last check's
        time): a failsafe with a ``stale_after`` counts their silence from here."""
        with self._lock:
            t = self._now if now is None else float(now)
            for name in names:
                self._sensor_seen.setdefault(name, t)

    # ------------------------------------------------------------------ inputs
    def on_message(self, channel: str, msg: Any) -> None:
        """Telemetry subscriber (subscribe it to :data:`CHANNELS`)."""
        self.on_messages(((channel, msg),))

    def on_messages(self, items: Any) -> None:
        """Telemetry subscriber of (channel, message) lists (``subscribe_batches``)."""
        events = []
        with self._lock:
            last_valid, kinds, now = self._last_valid, self._kinds, self._now
            for channel, msg in items:
                sensor = _SENSOR_OF.get(channel)
                if sensor is None:
                    if channel.startswith("sensors/") and channel[8:] in REGISTERED:
                        self._sensor_reading(REGISTERED[channel[8:]], msg)
                    elif channel == ch.EVENTS and isinstance(msg, Event):
                        events.append(msg)
                    elif channel == ch.BODY_TRACKING:
                        self._track(msg)
                    elif channel == ch.BODY_ALLOCATION:
                        self._allocation = msg
                    elif channel == ch.POWER_ELECTRICAL:
                        self._electrical(msg)
                    elif channel == ch.BODY_STATE:
                        self._estimate = (_stamp(msg.t, now), msg.orientation)
                    elif channel in _STROKES and self._driving and not self._fins_started:
                        self._fins_started = True  # the expected response starts from here
                        for env in self._expected.values():
                            env.stop()
                elif reading_valid(msg):
                    t = msg.t
                    # readings carry the loop's time; one off by more than a minute does not
                    if not (isinstance(t, (int, float)) and abs(t - now) <= _CLOCK_SLACK):
                        t = now
                    if sensor == "imu" and self._estimate is not None:
                        rad = gravity_innovation(self._estimate[1], msg.accel, ACCEL_GATE)
                        if rad == rad:  # NaN: accelerating, no measurement of gravity
                            self._innovation = (t, rad)
                            self._limit("estimate", rad > self.cfg.estimate_innovation, t, rad)
                    if sensor == "depth":
                        self._depth = (t, msg.depth_m)
                        self._limit("depth_limit", msg.depth_m > self.cfg.max_depth, t, msg.depth_m)
                    if t > last_valid[sensor]:
                        last_valid[sensor] = t
                    k = kinds[sensor]
                    if k:  # what happened before this reading is over (a fault reported after it is not)
                        for kind in [kind for kind, (_, seen, _why) in k.items() if seen <= t]:
                            del k[kind]
                else:
                    _note(kinds[sensor], "invalid", 1, _stamp(msg.t, now))
                if sensor == "dvl":
                    alt = getattr(msg, "altitude", math.nan)
                    if _finite(alt) and alt > 0.0:  # no altitude is not an altitude of 0
                        t = _stamp(msg.t, now)
                        self._altitude = (t, alt)
                        self._limit("altitude", alt < self.cfg.min_altitude, t, alt)
        for ev in events:
            self.on_event(ev)

    def _sensor_reading(self, entry: Any, msg: Any) -> None:
        """A registered sensor's reading: whether it trips its failsafe, since when (the lock is held)."""
        fs = entry.failsafe
        if fs is None:
            return
        t = _stamp(getattr(msg, "t", None), self._now)
        self._sensor_seen[entry.name] = max(t, self._sensor_seen.get(entry.name, t))
        try:
            cause = fs.trips(msg) if fs.trips is not None else None
        except Exception:
            log.exception("sensor %s: its failsafe's condition failed", entry.name)
            cause = f"{entry.name}: its failsafe's condition could not be judged"
        if cause:
            since = self._tripped[fs.name][0] if fs.name in self._tripped else t
            self._tripped[fs.name] = (since, str(cause))
        else:
            self._tripped.pop(fs.name, None)

    def _limit(self, name: str, beyond: bool, t: float, value: float) -> None:
        """A reading beyond (or within) failsafe ``name``'s limit at ``t`` (the lock is held)."""
        if beyond:
            since = self._beyond[name][0] if name in self._beyond else t
            self._beyond[name] = (since, value)
        else:
            self._beyond.pop(name, None)

    def _electrical(self, msg: Any) -> None:
        """The drives' electrical input: the lowest voltage, the energy (the lock is held)."""
        t = _stamp(msg.t, self._now)
        volts = [v for v in msg.voltage if _finite(v)]
        if volts:  # a drive that did not answer (NaN) is left out, never a zero
            low = min(volts)
            self._volts = (t, low)
            for name, threshold, _reserve in BATTERY:
                self._limit(name, low < getattr(self.cfg, threshold), t, low)
        watts = math.fsum(w for w in msg.per_fin if _finite(w))
        last = self._power
        if last is not None and 0.0 < t - last[0] <= _ENERGY_GAP:  # the mean power since the last message
            self._energy += watts * (t - last[0])
        self._power = (t, watts)

    def _track(self, msg: Any) -> None:
        """A tracking message: each axis further than its band outside its expected response,
        since when (the lock is held)."""
        off = self._off_track
        driving = bool(msg.driving)
        if not driving:
            self._fins_started = False
        self._driving = driving
        for axis, field, band, _unit in TRACKED:
            env = self._expected[axis]
            if not driving:
                env.stop()
                off.pop(axis, None)
                continue
            ref, err = getattr(msg, _REF[axis], math.nan), getattr(msg, field, math.nan)
            known = _finite(ref, err)  # a missing one starts the envelope again from the next
            dist = env.off(msg.t, ref if known else math.nan, ref + err if known else math.nan)
            if _finite(dist) and abs(dist) > getattr(self.cfg, band):
                since = off[axis][0] if axis in off else msg.t
                off[axis] = (since, dist)
            else:
                off.pop(axis, None)

    def on_event(self, ev: Event) -> None:
        with self._lock:
            sensor = _SENSOR_OF_SOURCE.get(ev.source)
            if sensor is not None:
                kind = READING_FAULTS.get(ev.code)
                if kind is not None:
                    data = ev.data if isinstance(ev.data, dict) else {}
                    suppressed, dropped, why = data.get("suppressed", 0), data.get("dropped"), data.get("reason")
                    # a report of readings dropped says how many; a throttled event, how many more
                    n = dropped if isinstance(dropped, int) and dropped > 0 else \
                        1 + (suppressed if isinstance(suppressed, int) else 0)
                    _note(self._kinds[sensor], kind, n, _stamp(ev.t, self._now), why if isinstance(why, str) else "")
            elif ev.source.startswith("epos2"):
                faults = self._motor.setdefault(ev.source, {})
                if ev.code in MOTOR_FAULTS:
                    faults.setdefault(ev.code, (self._now, ev.message or ev.code))
                elif ev.code in MOTOR_CLEARS:
                    for code in MOTOR_CLEARS[ev.code]:
                        faults.pop(code, None)
                elif ev.code == "recovered" and isinstance(ev.data.get("fault"), str):
                    faults.pop(ev.data["fault"], None)
            elif ev.source == "loop" and ev.code == "late_plan":
                self._late.append(self._now)
            elif ev.source == "loop" and ev.code in ("fin_slow", "fin_slow_cleared"):
                fin = ev.data.get("fin") if isinstance(ev.data, dict) else None
                if isinstance(fin, int):
                    if ev.code == "fin_slow":
                        self._slow_fins.setdefault(fin, (self._now, ev.message))
                    else:
                        self._slow_fins.pop(fin, None)
            elif ev.source == "loop" and ev.code in ("fin_force_scale", "fin_force_scale_cleared"):
                self._fin_scale = ev.message if ev.code == "fin_force_scale" else ""
            elif ev.source == "recorder" and ev.code == "write_failed":
                why = ev.data.get("error")
                self._recorder_failed = (self._now, why if isinstance(why, str) else ev.message)
            elif ev.source == "recorder" and ev.code == "failure_cleared":
                self._recorder_failed = None

    def note_invalid(self, sensor: str, what: str = "") -> None:
        """A reading of ``sensor`` was refused before it reached the stream (non-finite)."""
        if sensor not in SENSORS:
            raise ValueError(f"sensor: {sensor!r} is not one of {', '.join(SENSORS)}")
        with self._lock:
            _note(self._kinds[sensor], "invalid", 1, self._now)

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

    def loop_stuck(self, silent_for: float) -> Transition | None:
        """The loop has not stepped for ``silent_for`` s (the watchdog's thread): the
        ``loop_watchdog`` failsafe triggers now, at the last check's time; None when it is
        active already."""
        cause = f"the control loop has not stepped for {silent_for:.2f} s"
        with self._lock:
            self._loop_stuck = cause
            self._cause["loop_watchdog"] = cause
            if "loop_watchdog" in self._active:
                return None
            self._active["loop_watchdog"] = self._now
            tr = Transition("loop_watchdog", True, self._now, self.cfg.loop_watchdog.action, cause)
        log.error("failsafe loop_watchdog triggered: %s", cause)
        return tr

    def loop_resumed(self) -> None:
        """The loop steps again: ``loop_watchdog`` clears at the next check."""
        with self._lock:
            self._loop_stuck = None

    # ------------------------------------------------------------------ evaluation
    def check(self, now: float) -> list[Transition]:
        """Evaluate every failsafe at ``now``; the ones that triggered or cleared."""
        out: list[Transition] = []
        with self._lock:
            self._now = float(now)
            causes = self._causes(now)
            for name in failsafe_names():
                rule: FailsafeRule = self.cfg.rule(name)
                cause = causes.get(name)
                if cause is not None:
                    self._cause[name] = cause
                was = name in self._active
                if cause is not None and not was:
                    self._active[name] = now
                    out.append(Transition(name, True, now, rule.action, cause))
                elif cause is None and was:
                    del self._active[name]
                    action = rule.escalate if name in self._escalated else rule.action
                    self._escalated.discard(name)
                    out.append(Transition(name, False, now, action, self._cause.get(name, "")))
                elif (cause is not None and rule.escalates and name not in self._escalated
                      and now - self._active[name] >= rule.escalate_after):
                    self._escalated.add(name)
                    out.append(Transition(name, True, now, rule.escalate,
                                          f"{cause}, {now - self._active[name]:.1f} s after it triggered",
                                          escalated=True))
        for tr in out:
            how = "escalated" if tr.escalated else "triggered" if tr.active else "cleared"
            log.log(logging.ERROR if tr.active else logging.INFO, "failsafe %s %s: %s", tr.name, how, tr.cause)
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
                causes[s] = f"{s.upper()} without a valid reading for {quiet:.1f} s ({fault_label(self._kinds[s])})"
        faults = []
        for source, codes in sorted(self._motor.items()):
            for code, (since, message) in sorted(codes.items()):
                if now - since >= cfg.motor.timeout:
                    faults.append(f"{source}: {message}")
        if faults:
            causes["motor"] = "motor controller fault: " + "; ".join(faults)
        window = cfg.planner_late.timeout
        late = self._late
        while late and now - late[0] > window:
            late.popleft()
        if len(late) >= cfg.late_plans:
            causes["planner_late"] = f"{len(late)} late plans in the last {window:g} s"
        off = [f"{axis} {err:+.2f} {unit} off its reference and the slowest expected response "
               f"for {now - since:.0f} s"
               for axis, _f, _b, unit in TRACKED if axis in self._off_track
               for since, err in (self._off_track[axis],) if now - since >= cfg.tracking.timeout]
        if self._driving:
            off += [what for _fin, (_since, what) in sorted(self._slow_fins.items())]
        if off:
            causes["tracking"] = "not tracking: " + ", ".join(off)
        failed = self._recorder_failed
        if failed is not None and now - failed[0] >= cfg.recording.timeout:
            causes["recording"] = f"the recording stopped: {failed[1]}"
        if self._loop_stuck is not None:
            causes["loop_watchdog"] = self._loop_stuck
        beyond = self._beyond
        if "depth_limit" in beyond and now - beyond["depth_limit"][0] >= cfg.depth_limit.timeout:
            since, depth = beyond["depth_limit"]
            causes["depth_limit"] = f"depth {depth:.2f} m deeper than the limit {cfg.max_depth:g} m for {now - since:.1f} s"
        if "altitude" in beyond and now - beyond["altitude"][0] >= cfg.altitude.timeout:
            since, alt = beyond["altitude"]
            causes["altitude"] = (f"altitude {alt:.2f} m above the floor, below the minimum {cfg.min_altitude:g} m, "
                                  f"for {now - since:.1f} s")
        for entry in REGISTERED.values():
            fs = entry.failsafe
            if fs is None:
                continue
            timeout = cfg.rule(fs.name).timeout
            tripped, seen = self._tripped.get(fs.name), self._sensor_seen.get(entry.name)
            if tripped is not None and now - tripped[0] >= timeout:
                causes[fs.name] = f"{tripped[1]} for {now - tripped[0]:.1f} s" if timeout else tripped[1]
            elif fs.stale_after and seen is not None and now - seen >= fs.stale_after + timeout:
                causes[fs.name] = f"{entry.label}: no reading for {now - seen:.1f} s"
        est, timeout = self._estimate, cfg.estimate.timeout
        if "estimate" in beyond and now - beyond["estimate"][0] >= timeout:
            since, rad = beyond["estimate"]
            causes["estimate"] = (f"the attitude estimate {rad:.2f} rad off the accelerometer's gravity "
                                  f"(bound {cfg.estimate_innovation:g} rad) for {now - since:.1f} s")
        elif est is not None and self._last_valid["imu"] - est[0] > timeout:  # readings come, no estimate
            causes["estimate"] = (f"no state estimate for {self._last_valid['imu'] - est[0]:.1f} s "
                                  "of IMU readings")
        used = self._energy / 3600.0
        for name, threshold, reserve in BATTERY:
            why = []
            if name in beyond and now - beyond[name][0] >= getattr(cfg, name).timeout:
                since, volts = beyond[name]
                why.append(f"the lowest drive supply {volts:.1f} V below {getattr(cfg, threshold):g} V "
                           f"for {now - since:.0f} s")
            cap, left = cfg.battery_capacity, getattr(cfg, reserve)
            if cap > 0 and used >= (1.0 - left) * cap:
                why.append(f"{used:.1f} Wh of {cap:g} Wh used, less than {left:.0%} left")
            if why:
                causes[name] = "battery: " + "; ".join(why)
        return causes

    # ------------------------------------------------------------------ reading
    def sensor_silence(self, sensor: str, now: float) -> tuple[float, str]:
        """(seconds since ``sensor``'s last valid reading at ``now``, what happened since:
        :func:`fault_label`, "" when nothing was reported)."""
        if sensor not in SENSORS:
            raise ValueError(f"sensor: {sensor!r} is not one of {', '.join(SENSORS)}")
        with self._lock:
            kinds = self._kinds[sensor]
            return max(0.0, now - self._last_valid[sensor]), fault_label(kinds) if kinds else ""

    def envelope(self) -> tuple[tuple[float, float] | None, tuple[float, float] | None]:
        """The last valid depth and DVL altitude, each (time, m), None before the first."""
        with self._lock:
            return self._depth, self._altitude

    def battery(self) -> tuple[tuple[float, float] | None, float]:
        """(the last lowest drive supply voltage as (time, V), None before the first; the
        energy the drives drew since the start, Wh)."""
        with self._lock:
            return self._volts, self._energy / 3600.0

    def estimate(self) -> tuple[tuple[float, float] | None, float | None]:
        """(the last innovation taken at rest as (time, rad), None before the first; the last
        body state's time, None before the first)."""
        with self._lock:
            return self._innovation, None if self._estimate is None else self._estimate[0]

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

    def restart_expected(self) -> None:
        """Every axis's expected response starts again from the next measured value, and no
        axis is off any more: a deliberate change of what the fins do (the seeker putting its
        best back after a candidate that lost the track) is a new command to judge the robot
        against. A robot still off its track after it is found so after ``timeout`` again."""
        with self._lock:
            for env in self._expected.values():
                env.stop()
            self._off_track.clear()

    def off_track(self, now: float) -> tuple[float, str]:
        """(how long, at ``now``, the tracked axis off its expected response the longest has
        been off, s (0 when none is); that axis's error as "axis error unit")."""
        with self._lock:
            worst = (0.0, "")
            for axis, _f, _b, unit in TRACKED:
                if axis in self._off_track:
                    since, err = self._off_track[axis]
                    if now - since >= worst[0]:
                        worst = (max(0.0, now - since), f"{axis} {err:+.2f} {unit}")
            return worst

    def slow_fins(self) -> list[str]:
        """What was reported of each fin reported slow and not recovered since (paper fin order)."""
        with self._lock:
            return [what for _fin, (_since, what) in sorted(self._slow_fins.items())]

    def fin_scale(self) -> str:
        """What the loop reported of the fins making more than the fin model's force, while the
        body layer follows it ("" when they make the model's)."""
        with self._lock:
            return self._fin_scale

    def motor_faults(self) -> list[str]:
        """The motor controller faults reported and not cleared ("source: what it reported")."""
        with self._lock:
            return [f"{src}: {codes[code][1]}" for src, codes in sorted(self._motor.items()) for code in sorted(codes)]

    def active(self) -> tuple[str, ...]:
        with self._lock:
            return tuple(n for n in failsafe_names() if n in self._active)

    def is_active(self, name: str) -> bool:
        with self._lock:
            return name in self._active

    def states(self) -> list[FailsafeState]:
        with self._lock:
            out = []
            for name in failsafe_names():
                rule: FailsafeRule = self.cfg.rule(name)
                out.append(FailsafeState(
                    name=name, action=rule.escalate if name in self._escalated else rule.action,
                    timeout=rule.timeout,
                    active=name in self._active, since=self._active.get(name),
                    cause=self._cause.get(name, ""),
                ))
            return out
