"""The closed loop's robot reached through the device drivers: :class:`DeviceRobotIO`.

It implements ``robot.interface.RobotIO`` with the drivers only: :class:`FinDrives` for the
four EPOS2 nodes, :class:`ImuDriver`, :class:`DvlClient` and :class:`PressureDriver`. It
does not know whether the other ends are the robot's devices or the emulators of the
simulated rig; the configuration's endpoints decide.

Time. The drivers stamp readings and events on the wall clock (``time.monotonic``); the
loop runs in its own time, which a paced clock ties to the wall clock at ``pace``
simulated seconds per second. The loop's paced clock anchors the mapping
(:meth:`DeviceRobotIO.resync`: loop time ``t`` is now), at its start and after a stall it
skipped; without one, the first :meth:`DeviceRobotIO.advance_to` call does. Later calls
wait until the device clock reaches ``t`` (so a loop without a paced clock is paced by the
devices), and the mapping is re-anchored when the device clock runs ahead of the loop by
more than ``resync_s`` (the loop was paused). Readings leave :meth:`advance_to` in loop
time and in time order (a reading may carry a stamp a little after ``t``: the devices do
not wait for the loop), each sensor's stamps strictly increasing; what queued up before the
loop started (or while it was paused, or stalled) is reduced to the latest reading of each
kind, stamped ``t``.

Events. Every driver fault is an :class:`Event` (source ``epos2.<node>``, ``imu``, ``dvl``,
``pressure``) stamped in loop time and handed to each sink added with
:meth:`DeviceRobotIO.add_event_sink` (the supervisor connects its telemetry stream); the
latest events are kept so a sink added after start-up sees them too. Besides the
drivers' own events, a run of ``dvl_invalid_after`` velocity reports without bottom lock
is reported as ``bottom_lock_lost`` (and ``recovered``), since a single invalid report is
normal missing data.

Plausibility. The readings :meth:`advance_to` hands the loop have passed the plausibility
checks (``plausibility``, configured by ``config.plausibility``): an implausible one is
dropped, counted and reported as an Event ``implausible`` of its sensor (stamped in loop
time).

Telemetry. The drives' electrical input (each EPOS2's averaged motor current and supply
voltage, read every ``epos2.electrical_period_ms``), with each fin's last encoder rate and the
drives' motor (``epos2.motor``), becomes an
:class:`~ucat_console.telemetry.messages.ElectricalPower` message (``drive_power``: the battery
power each drive draws) stamped in loop time, handed
to each sink added with :meth:`DeviceRobotIO.add_telemetry_sink` as ``(channel, message)``
(the supervisor publishes it on its stream, channel ``power/electrical``).
"""

from __future__ import annotations

import collections
import dataclasses
import logging
import math
import threading
import time
from typing import Any, Callable

from ucat_console.backend.devices.canbus import CanBusError
from ucat_console.backend.devices.config import DevicesConfig
from ucat_console.backend.devices.dvl import DvlClient
from ucat_console.backend.devices.epos2 import Epos2NoAnswer
from ucat_console.backend.devices.fin_drives import FinDrives
from ucat_console.backend.devices.imu import ImuDriver
from ucat_console.backend.devices.plausibility import Plausibility
from ucat_console.backend.devices.pressure import PressureDriver
from ucat_console.robot.readings import DvlPosition, DvlVelocity, FinFeedback
from ucat_console.backend.devices.reporting import EventReporter
from ucat_console.backend.devices.serial_link import SERIAL_ERRORS, open_serial
from ucat_console.backend.drive_power import electrical_power
from ucat_console.robot.interface import RobotIO, RobotTruth
from ucat_console.robot.fins import N_FINS
from ucat_console.robot.readings import DriveElectrical, Reading
from ucat_console.telemetry.channels import POWER_ELECTRICAL
from ucat_console.telemetry.events import Event, EventSink

TelemetrySink = Callable[[str, Any], None]

log = logging.getLogger(__name__)

#: events kept for sinks added late
EVENT_BACKLOG = 500
#: s; the smallest step between two readings of one sensor
_TICK = 1e-6


class DeviceTime:
    """Wall clock (s) <-> loop time (s): ``t_loop = t0 + pace * (wall - wall0)``."""

    def __init__(self, pace: float = 1.0) -> None:
        if not math.isfinite(pace) or pace <= 0.0:
            raise ValueError(f"pace: {pace!r} must be a positive number")
        self.pace = float(pace)
        self._anchor: tuple[float, float] | None = None  # (t0, wall0)

    @property
    def anchored(self) -> bool:
        return self._anchor is not None

    def anchor(self, t: float, wall: float) -> None:
        """Loop time ``t`` is wall-clock time ``wall``."""
        self._anchor = (float(t), float(wall))

    def to_loop(self, wall: float) -> float:
        anchor = self._anchor
        if anchor is None:
            return 0.0
        t0, wall0 = anchor
        return t0 + self.pace * (wall - wall0)

    def to_wall(self, t: float) -> float:
        anchor = self._anchor
        if anchor is None:
            raise RuntimeError("device time is not anchored yet")
        t0, wall0 = anchor
        return wall0 + (t - t0) / self.pace


class DeviceRobotIO(RobotIO):
    """Fin commands out and readings in through the device drivers.

    ``config`` gives every driver's endpoint and settings (``config.robot`` is not read
    here). ``pace`` is the loop's pace (simulated seconds per wall-clock second; 1 on the
    robot). ``truth``, when given, supplies the simulator's true state (the simulated rig
    passes its plant's); it is None on the robot. ``device_time(name)``: the time (on
    ``wall_clock``) the device ``name`` (``"epos2"``, ``"imu"``, ``"dvl"``, ``"pressure"``)
    has run to, when it runs in this process (the simulated rig's emulators), against which
    the drivers judge its silence (``canbus.HeardBus``, ``reporting.SilenceWatch``); None on
    the robot. Call :meth:`start` before the loop runs.
    """

    def __init__(
        self,
        config: DevicesConfig,
        *,
        pace: float = 1.0,
        truth: Callable[[], RobotTruth | None] | None = None,
        on_event: EventSink | None = None,
        wall_clock: Callable[[], float] = time.monotonic,
        device_time: Callable[[str], float] | None = None,
    ) -> None:
        self.config = config
        self.time = DeviceTime(pace)
        self._wall = wall_clock
        self._truth = truth
        self._lock = threading.Lock()
        self._pending: list[Reading] = []
        self._t = 0.0
        self._electrical_t = 0.0  # the time of the last power/electrical message (the drives' round)
        self._started_loop = False
        self._reset = False  # re-anchored (resync): the next readings are the latest of each kind
        self._last_t: dict[object, float] = {}
        self._closed = False
        self._wake = threading.Event()
        self._sinks: tuple[EventSink, ...] = (on_event,) if on_event is not None else ()
        self._telemetry_sinks: tuple[TelemetrySink, ...] = ()
        self._backlog: collections.deque[Event] = collections.deque(maxlen=EVENT_BACKLOG)
        self._dvl_invalid_run = 0
        self._fin_rates = [math.nan] * N_FINS  # each fin's last encoder rate (rad/s)
        self.last_dvl_position: DvlPosition | None = None
        #: the simulated rig behind the drivers (robot = sim-devices), for fault injection
        #: from the console; this class never uses it
        self.rig: object | None = None
        self._dvl_events = EventReporter("dvl", self._on_event, wall_clock)
        #: the plausibility checks of the readings (their events are in loop time already)
        self.checks = Plausibility(config.plausibility, self._on_loop_event)

        def time_of(name: str) -> Callable[[], float] | None:
            return None if device_time is None else (lambda: device_time(name))

        self.drives = FinDrives(config.epos2, self._on_reading, self._on_event, clock=wall_clock,
                                bus_time=time_of("epos2"), on_electrical=self._on_electrical)
        self.imu = ImuDriver(config.imu, self._on_reading, self._on_event, clock=wall_clock,
                             device_time=time_of("imu"))
        self.dvl = DvlClient(config.dvl, self._on_dvl_velocity, self._on_dvl_position, self._on_event,
                             clock=wall_clock, device_time=time_of("dvl"))
        self.pressure = PressureDriver(config.pressure, self._on_reading, self._on_event, clock=wall_clock,
                                       device_time=time_of("pressure"))
        self._running: list[Callable[[], None]] = []

    # ------------------------------------------------------------------ start-up
    def start(self) -> None:
        """Check the endpoints, then start every driver.

        Raises ValueError naming the configuration key when an endpoint is unusable: a
        serial device that is missing or cannot be opened (``imu.port``,
        ``pressure.port``), a DVL that cannot be reached (``dvl.host``), a CAN channel
        that cannot be opened (``epos2.channel``) or an EPOS2 node that never answers
        (``epos2.node_ids[i]``). Whatever was started is stopped again first; other
        start-up failures of the drives raise ``Epos2Error``.
        """
        cfg = self.config
        _check_serial("imu.port", cfg.imu.port, cfg.imu.baud)
        _check_serial("pressure.port", cfg.pressure.port, cfg.pressure.baud)
        try:
            self._start_dvl()
            self._start_drives()
            self.imu.start()
            self._running.append(self.imu.stop)
            self.pressure.start()
            self._running.append(self.pressure.stop)
        except BaseException:
            self._stop_drivers()
            raise
        if cfg.enable_at_start and not self.drives.enable_all():
            log.warning("not every EPOS2 reached operation enabled at start (see the events)")

    def _start_dvl(self) -> None:
        cfg = self.config.dvl
        self.dvl.start()
        self._running.append(self.dvl.stop)
        if not self.dvl.wait_connected(cfg.connect_timeout_s + 0.5):
            raise ValueError(
                f"dvl.host: cannot reach the DVL at {cfg.host}:{cfg.port} within "
                f"{cfg.connect_timeout_s + 0.5:g} s (dvl.host / dvl.port)"
            )

    def _start_drives(self) -> None:
        cfg = self.config.epos2
        try:
            self.drives.connect()
        except CanBusError as e:
            raise ValueError(f"epos2.channel: {e} (epos2.interface = {cfg.interface!r})") from None
        except Epos2NoAnswer:
            silent = [fin for fin, d in sorted(self.drives.drivers.items()) if not d.started] or [0]
            nodes = [cfg.node_ids[fin] for fin in silent]
            more = f" (nor did nodes {', '.join(map(str, nodes[1:]))})" if len(nodes) > 1 else ""
            raise ValueError(
                f"epos2.node_ids[{silent[0]}]: EPOS2 node {nodes[0]} did not answer within "
                f"{cfg.boot_timeout:g} s of reset communication{more}; check the node ids and "
                f"epos2.bitrate ({cfg.bitrate} bit/s) on {cfg.interface} {cfg.channel!r}"
            ) from None
        self._running.append(lambda: self.drives.close(disable=True))

    # ------------------------------------------------------------------ RobotIO
    def command_fin(self, fin: int, target_rad: float, profile_velocity_rad_s: float) -> None:
        if fin not in self.drives.drivers:
            raise ValueError(f"fin: {fin!r} is not a fin with a drive (fins: {sorted(self.drives.drivers)})")
        self.drives.command(fin, target_rad, profile_velocity_rad_s)

    def next_reading_time(self) -> float:
        return self._t + self.config.poll_period_s

    def resync(self, t: float) -> None:
        """Loop time ``t`` is now: the device clock is anchored there, and what the drivers
        queued before is reduced to the latest reading of each kind, stamped at the next
        :meth:`advance_to` (a stalled loop does not replay stale readings)."""
        if not math.isfinite(t):
            raise ValueError(f"t: expected a finite time, got {t!r}")
        self.time.anchor(t, self._wall())
        self._started_loop = True
        self._reset = True

    def advance_to(self, t: float) -> list[Reading]:
        if not math.isfinite(t):
            raise ValueError(f"t: expected a finite time, got {t!r}")
        clock = self.time
        now = self._wall()
        reset = not self._started_loop or self._reset
        self._reset = False
        if not self._started_loop:
            clock.anchor(t, now)
            self._started_loop = True
        else:
            ahead = clock.to_loop(now) - t
            if ahead > self.config.resync_s:
                log.info("device clock %.3f s ahead of the loop: re-aligned", ahead)
                clock.anchor(t, now)
                reset = True
            elif ahead < 0.0 and not self._closed:
                self._wake.wait(-ahead / clock.pace)
        with self._lock:
            batch, self._pending = self._pending, []
        self._t = t
        if reset:  # what queued up while the loop was not running: the latest of each kind, now
            batch = _latest_of_each_kind(batch)
        last = self._last_t
        out = []
        for r in batch:
            key = _kind(r)
            tl = t if reset else clock.to_loop(r.t)
            prev = last.get(key)
            if prev is not None and tl <= prev:  # keep each sensor's stamps increasing
                tl = prev + _TICK
            last[key] = tl
            out.append(dataclasses.replace(r, t=tl))
        out.sort(key=_reading_time)
        out = self.checks.filter(out)
        self.checks.report(t)
        return out

    def truth(self) -> RobotTruth | None:
        if self._truth is None:
            return None
        tr = self._truth()
        if tr is None:
            return None
        return dataclasses.replace(tr, t=self.time.to_loop(self._wall()) if self.time.anchored else self._t)

    def close(self) -> None:
        """Disable the drives, stop every driver (safe to call more than once)."""
        self._closed = True
        self._wake.set()
        self._stop_drivers()

    def _stop_drivers(self) -> None:
        while self._running:
            stop = self._running.pop()
            try:
                stop()
            except Exception:
                log.exception("stopping a driver failed")

    # ------------------------------------------------------------------ drives
    has_drives = True

    def enable_drives(self) -> bool:
        """Every EPOS2 to operation enabled (on arming); False (with events) on failure."""
        return self.drives.enable_all()

    def stop_drives(self) -> bool:
        """Quick stop on every EPOS2, then its power stage off (on disarming)."""
        stopped = self.drives.quick_stop_all()
        return self.drives.disable_all() and stopped

    def reset_drive_faults(self) -> bool:
        """Reset every EPOS2 in fault; each stays unpowered until the next arming."""
        return self.drives.reset_faults()

    def zero_depth(self) -> float:
        """Zero the depth at the surface (the pressure driver's calibration)."""
        p = self.pressure.zero()
        if p is None:
            raise ValueError("depth zeroing: too few pressure readings (see the pressure "
                             "sensor's events); the old zero stays")
        return p

    # ------------------------------------------------------------------ events
    def add_event_sink(self, sink: EventSink, replay: bool = True) -> Callable[[], None]:
        """Send every event to ``sink`` (with the kept ones first when ``replay``).

        Returns a function that removes the sink.
        """
        with self._lock:
            self._sinks = self._sinks + (sink,)
            past = list(self._backlog) if replay else []
        for event in past:
            _deliver(sink, event)

        def remove() -> None:
            with self._lock:
                self._sinks = tuple(s for s in self._sinks if s is not sink)

        return remove

    def add_telemetry_sink(self, sink: TelemetrySink) -> Callable[[], None]:
        """Send every telemetry message of the devices (``(channel, message)``) to ``sink``;
        returns the function that removes it."""
        with self._lock:
            self._telemetry_sinks = self._telemetry_sinks + (sink,)

        def remove() -> None:
            with self._lock:
                self._telemetry_sinks = tuple(s for s in self._telemetry_sinks if s is not sink)

        return remove

    def _on_electrical(self, readings: dict[int, DriveElectrical | None]) -> None:
        nan = math.nan
        current, voltage = [nan] * N_FINS, [nan] * N_FINS
        stamps = []
        for fin, r in readings.items():
            if r is not None and 0 <= fin < N_FINS:
                current[fin], voltage[fin] = r.current_a, r.voltage_v
                stamps.append(r.t)
        if not stamps:
            return  # no drive answered: each one's event says so
        wall = max(stamps)
        t = self.time.to_loop(wall) if self.time.anchored else self._t
        # a drive's TPDO3 that came before the clock was anchored maps to before the loop's
        # start: the channel's time never goes back (nor before 0)
        t = self._electrical_t = max(t, self._electrical_t)
        with self._lock:
            sinks = self._telemetry_sinks
            rates = list(self._fin_rates)
        msg = electrical_power(t, current, voltage, rates, self.config.epos2.motor)
        for sink in sinks:
            try:
                sink(POWER_ELECTRICAL, msg)
            except Exception:
                log.exception("telemetry sink failed on %s", POWER_ELECTRICAL)

    def publish_event(self, event: Event) -> None:
        """An event raised beside the drivers (the simulated rig), stamped on the wall clock."""
        self._on_event(event)

    def _on_event(self, event: Event) -> None:
        if self.time.anchored:
            event = dataclasses.replace(event, t=self.time.to_loop(event.t))
        else:
            event = dataclasses.replace(event, t=self._t)
        self._on_loop_event(event)

    def _on_loop_event(self, event: Event) -> None:
        """An event stamped in loop time, to every sink."""
        with self._lock:
            self._backlog.append(event)
            sinks = self._sinks
        for sink in sinks:
            _deliver(sink, event)

    # ------------------------------------------------------------------ readings
    def _on_reading(self, reading: Reading) -> None:
        with self._lock:
            self._pending.append(reading)
            if isinstance(reading, FinFeedback) and 0 <= reading.fin < N_FINS:
                self._fin_rates[reading.fin] = reading.velocity_rad_s

    def _on_dvl_velocity(self, v: DvlVelocity) -> None:
        if v.valid:
            self._dvl_invalid_run = 0
            self._dvl_events.condition("bottom_lock_lost", False, "DVL bottom lock back")
        else:
            self._dvl_invalid_run += 1
            if self._dvl_invalid_run >= self.config.dvl_invalid_after:
                self._dvl_events.condition(
                    "bottom_lock_lost", True,
                    f"{self._dvl_invalid_run} DVL velocity reports without bottom lock",
                    "warning", reports=self._dvl_invalid_run,
                )
        self._on_reading(v)

    def _on_dvl_position(self, p: DvlPosition) -> None:
        self.last_dvl_position = p


def _deliver(sink: EventSink, event: Event) -> None:
    try:
        sink(event)
    except Exception:
        log.exception("event sink failed on %s/%s", event.source, event.code)


def _reading_time(r: Reading) -> float:
    return r.t


def _kind(r: Reading) -> object:
    return (FinFeedback, r.fin) if type(r) is FinFeedback else type(r)


def _latest_of_each_kind(batch: list[Reading]) -> list[Reading]:
    latest: dict[object, Reading] = {}
    for r in batch:
        latest[_kind(r)] = r
    return list(latest.values())


def _check_serial(key: str, port: str, baud: int) -> None:
    """ValueError naming ``key`` unless ``port`` can be opened."""
    try:
        ser = open_serial(port, baud, 0.01)
    except SERIAL_ERRORS as e:
        raise ValueError(f"{key}: cannot open serial device {port!r}: {e}") from None
    try:
        ser.close()
    except SERIAL_ERRORS:
        pass

