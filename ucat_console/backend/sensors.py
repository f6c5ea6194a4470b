"""The auxiliary sensors: one live registry, read by the stream, the recorder, the failsafes
and the page's status bar.

An auxiliary sensor is one whose reading does not enter the estimator or the loop's compiled
core (the leak detector; the IMU, the DVL, the pressure sensor and the fin drives are the
robot's, ``robot.interface.RobotIO``, and stay wired by hand). Its :class:`Sensor` entry says

* its name and its reading: a frozen dataclass with a time ``t`` and fields annotated with
  :class:`~ucat_console.robot.fields.Doc` (meaning, unit). Registering it adds the channel
  ``sensors/<name>`` carrying that type to the telemetry's channels, so the stream checks
  it, the recorder writes it with a schema derived from the dataclass and the session reader
  reads it back, as any other channel;
* how it is read: ``open(context) -> Source | None``, given the devices' configuration,
  whether the robot is simulated, the robot itself (a robot may hand out a source of its
  own) and an event sink; None when this robot has no such sensor. The supervisor's
  :class:`SensorPoller` calls each source's ``read(t)`` every ``period_s`` in a thread of
  its own and publishes what it returns (None: nothing this time), stamped with the loop's
  time;
* its light: a label and ``light(status) -> (state, reason)``, ``state`` one of ``ok``,
  ``warn``, ``bad`` (the status bar's), from the latest reading, its age, where the sensor
  is and its failsafe's rule; the bar shows it red while its failsafe is active, and grey
  with ``absent`` as the reason on a robot without it;
* its failsafe (optional): a rule name, its default :class:`FailsafeRule` (what the
  configuration's ``[[failsafe.sensors]]`` may replace) and what trips it: ``trips(reading)
  -> cause | None`` held for the rule's timeout, or no reading for ``stale_after`` s.

Everything that names a sensor reads the registry when it needs the set, never a copy made
at import: a sensor registered (``register(Sensor(...))`` from your own module) before the
console starts is streamed, recorded, shown and watched. docs/extending.md, "A new sensor",
walks through one.
"""

from __future__ import annotations

import logging
import math
import re
import threading
import time
from dataclasses import dataclass, fields, is_dataclass
from typing import TYPE_CHECKING, Any, Callable

from ucat_console.backend.devices.leak import LeakEmulator, LeakInput, LeakReading
from ucat_console.backend.failsafe_rule import FIXED_FAILSAFES, FailsafeRule
from ucat_console.robot.interface import RobotIO
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.events import EventSink

if TYPE_CHECKING:
    from ucat_console.backend.devices.config import DevicesConfig

log = logging.getLogger(__name__)

_NAME = re.compile(r"^[a-z][a-z0-9_]*$")


def _nothing() -> None:
    pass


@dataclass(frozen=True)
class Source:
    """An open sensor, what the poller reads: ``read(t)`` returns the reading at the loop's
    time ``t`` (an instance of the sensor's reading type) or None; ``where`` names the device
    for its light (a path, an address); ``emulator`` is the emulated device behind it on a
    simulated robot (fault injection), else None."""

    read: Callable[[float], Any]
    period_s: float
    where: str = ""
    close: Callable[[], None] = _nothing
    emulator: Any = None

    def __post_init__(self) -> None:
        if not callable(self.read):
            raise ValueError(f"source: read must be callable, got {self.read!r}")
        if not (isinstance(self.period_s, (int, float)) and 0.001 <= self.period_s <= 60.0):
            raise ValueError(f"source: period_s {self.period_s!r} outside [0.001, 60] s")


@dataclass(frozen=True)
class OpenContext:
    """What a sensor is opened with: the devices' configuration, whether the robot is
    simulated, the robot, a sink for the sensor's events and the loop's clock."""

    devices: DevicesConfig
    simulated: bool
    robot: RobotIO | None
    on_event: EventSink
    clock: Callable[[], float]


@dataclass(frozen=True)
class SensorStatus:
    """What a sensor's light judges: its latest reading (None before the first), how old it
    is (s, inf before the first), where the sensor is and its failsafe's rule (None: none)."""

    reading: Any
    age: float
    where: str
    rule: FailsafeRule | None


@dataclass(frozen=True)
class SensorFailsafe:
    """A sensor's failsafe: its name (a ``[[failsafe.sensors]]`` entry's), its default rule,
    and what trips it: ``trips(reading)`` a cause (None: fine) held for the rule's timeout,
    or no reading for ``stale_after`` s (0: never)."""

    name: str
    rule: FailsafeRule
    trips: Callable[[Any], str | None] | None = None
    stale_after: float = 0.0

    def __post_init__(self) -> None:
        if not isinstance(self.rule, FailsafeRule):
            raise ValueError(f"failsafe {self.name!r}: rule must be a FailsafeRule, got {self.rule!r}")
        if not (isinstance(self.stale_after, (int, float)) and 0.0 <= self.stale_after <= 3600.0):
            raise ValueError(f"failsafe {self.name!r}: stale_after {self.stale_after!r} outside [0, 3600] s")
        if self.trips is None and not self.stale_after:
            raise ValueError(f"failsafe {self.name!r}: give trips, stale_after or both")


@dataclass(frozen=True)
class Sensor:
    """One auxiliary sensor (module docstring)."""

    name: str
    doc: str
    reading: type
    open: Callable[[OpenContext], Source | None]
    label: str
    light: Callable[[SensorStatus], tuple[str, str]]
    failsafe: SensorFailsafe | None = None
    absent: str = "not on this robot"

    @property
    def channel(self) -> str:
        """Its telemetry channel."""
        return f"sensors/{self.name}"


SENSORS: dict[str, Sensor] = {}


def register(sensor: Sensor) -> Sensor:
    """Add ``sensor`` to the registry and its channel to the telemetry's (ValueError naming
    what is wrong: a taken name, channel or failsafe, a reading type without ``t``)."""
    if not isinstance(sensor, Sensor):
        raise ValueError(f"sensor: expected a Sensor, got {type(sensor).__name__}")
    if not isinstance(sensor.name, str) or not _NAME.match(sensor.name):
        raise ValueError(f"sensor: name {sensor.name!r} must be lower case letters, digits and _")
    if sensor.name in SENSORS:
        raise ValueError(f"sensor: {sensor.name!r} is already registered")
    if not (is_dataclass(sensor.reading) and "t" in {f.name for f in fields(sensor.reading)}):
        raise ValueError(f"sensor {sensor.name!r}: its reading must be a dataclass with a time field t")
    fs = sensor.failsafe
    if fs is not None:
        if fs.name in FIXED_FAILSAFES or fs.name in sensor_failsafe_names():
            raise ValueError(f"sensor {sensor.name!r}: failsafe {fs.name!r} is already one of the failsafes")
        if not _NAME.match(fs.name):
            raise ValueError(f"sensor {sensor.name!r}: failsafe name {fs.name!r} must be lower case letters, "
                             "digits and _")
    ch.add_channel(sensor.channel, sensor.reading)  # ValueError if taken
    SENSORS[sensor.name] = sensor
    return sensor


def unregister(name: str) -> None:
    """Take ``name`` out of the registry and its channel out of the telemetry's."""
    entry = sensor(name)
    del SENSORS[name]
    ch.remove_channel(entry.channel)


def sensor(name: str) -> Sensor:
    """The registered sensor ``name``, else ValueError naming the sensors there are."""
    try:
        return SENSORS[name]
    except (KeyError, TypeError):
        raise ValueError(f"sensor: {name!r} is not one of {', '.join(SENSORS) or 'none'}") from None


def sensor_names() -> tuple[str, ...]:
    """The registered sensors' names, in the order registered (read live)."""
    return tuple(SENSORS)


def sensor_failsafe_names() -> tuple[str, ...]:
    """The registered sensors' failsafes, in the order registered (read live)."""
    return tuple(s.failsafe.name for s in SENSORS.values() if s.failsafe is not None)


def sensor_failsafe(name: str) -> SensorFailsafe:
    """The registered sensor failsafe ``name``, else ValueError naming the ones there are."""
    for s in SENSORS.values():
        if s.failsafe is not None and s.failsafe.name == name:
            return s.failsafe
    raise ValueError(f"failsafe: {name!r} is not one of the sensors' failsafes "
                     f"({', '.join(sensor_failsafe_names()) or 'none'})")


# ---------------------------------------------------------------------- the poller
class SensorPoller:
    """Opens every registered sensor and reads each every its ``period_s`` in a thread of its
    own (one for all), publishing what they return on their channels. A source that raises
    is logged once and read again at its next period."""

    def __init__(self, context: OpenContext, publish: Callable[[str, Any], None]) -> None:
        self._context = context
        self._publish = publish
        self._lock = threading.Lock()
        self._latest: dict[str, Any] = {}
        self._failing: set[str] = set()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        #: the sensors open on this robot (name -> entry, source), in registration order
        self.sources: dict[str, tuple[Sensor, Source]] = {}
        try:
            for entry in SENSORS.values():
                src = entry.open(context)
                if src is None:
                    continue  # not on this robot
                if not isinstance(src, Source):
                    raise ValueError(f"sensor {entry.name!r}: open returned {type(src).__name__}, not a Source")
                self.sources[entry.name] = (entry, src)
        except BaseException:
            self.close()
            raise

    def emulator(self, name: str) -> Any:
        """The emulated device behind sensor ``name``'s source (None: none, or not open)."""
        opened = self.sources.get(name)
        return opened[1].emulator if opened is not None else None

    def read_all(self, names: list[str] | None = None) -> None:
        """Read every source (those of ``names``) once and publish what they return."""
        t = self._context.clock()
        for name, (entry, src) in self.sources.items():
            if names is not None and name not in names:
                continue
            try:
                reading = src.read(t)
                if reading is not None and type(reading) is not entry.reading:
                    raise TypeError(f"read {type(reading).__name__}, expected {entry.reading.__name__}")
            except Exception:
                if name not in self._failing:
                    self._failing.add(name)
                    log.exception("sensor %s: reading failed", name)
                continue
            self._failing.discard(name)
            if reading is not None:
                with self._lock:
                    self._latest[name] = reading
                self._publish(entry.channel, reading)

    def latest(self, name: str) -> Any:
        """Sensor ``name``'s latest reading (None before the first)."""
        with self._lock:
            return self._latest.get(name)

    def statuses(self, now: float, rule: Callable[[str], FailsafeRule]) -> list[tuple[Sensor, SensorStatus | None]]:
        """Each registered sensor with its status (None: not on this robot), in registration
        order; ``rule(name)`` is a failsafe's rule in force."""
        out: list[tuple[Sensor, SensorStatus | None]] = []
        for entry in SENSORS.values():
            opened = self.sources.get(entry.name)
            if opened is None:
                out.append((entry, None))
                continue
            reading = self.latest(entry.name)
            age = math.inf if reading is None else max(0.0, now - reading.t)
            out.append((entry, SensorStatus(reading, age, opened[1].where,
                                            rule(entry.failsafe.name) if entry.failsafe is not None else None)))
        return out

    def start(self) -> None:
        """Read every source now, then each every its ``period_s`` in the poller's thread."""
        if not self.sources:
            return
        self.read_all()
        self._thread = threading.Thread(target=self._run, name="sensor-poller", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        periods = {name: src.period_s for name, (_e, src) in self.sources.items()}
        start = time.monotonic()
        due = {name: start + p for name, p in periods.items()}
        while not self._stop.wait(max(0.0, min(due.values()) - time.monotonic())):
            now = time.monotonic()
            names = [name for name, t in due.items() if t <= now]
            self.read_all(names)
            for name in names:  # on its period; after a late read, from now
                due[name] = max(due[name] + periods[name], now)

    def close(self) -> None:
        """Stop the thread and close every source."""
        self._stop.set()
        t, self._thread = self._thread, None
        if t is not None:
            t.join(timeout=2.0)
        for name, (_entry, src) in self.sources.items():
            try:
                src.close()
            except Exception:
                log.exception("sensor %s: closing failed", name)


# ---------------------------------------------------------------------- the leak detector
def _open_leak(ctx: OpenContext) -> Source | None:
    """The leak detector on ``devices.leak.path``; on a simulated robot without one, an
    emulated detector (its value file in a temporary folder)."""
    cfg = ctx.devices.leak
    emulator = LeakEmulator(cfg.active_high) if ctx.simulated and not cfg.path else None
    path = cfg.path or (str(emulator.path) if emulator is not None else "")
    if not path:
        return None
    inp = LeakInput(cfg, path, ctx.on_event, ctx.clock)
    return Source(inp.reading, cfg.period_s, path, emulator.close if emulator is not None else _nothing, emulator)


def _leak_light(s: SensorStatus) -> tuple[str, str]:
    r = s.reading
    if r is None:
        return "warn", "leak detector not read yet"
    if not r.readable:
        return "warn", f"leak detector {s.where} unreadable: a leak would not be seen"
    if r.water:
        after = f" (failsafe after {s.rule.timeout:g} s)" if s.rule is not None else ""
        return "warn", f"water at {s.where}{after}"
    return "ok", f"dry ({s.where})"


register(Sensor(
    "leak", "the leak detector: a digital input read by the console (devices.leak)", LeakReading, _open_leak,
    "Leak", _leak_light,
    # water in the hull: surface at once, under control, while the electronics work
    SensorFailsafe("leak", FailsafeRule("surface", 0.0), lambda r: "water at the leak detector" if r.water else None),
    absent="no leak detector (devices.leak.path)",
))
