"""The simulated U-CAT behind its device emulators: :class:`SimRig`.

It joins the plant (``backend/sim``) to the emulators (``backend/devices``), so it sits
above both, beside ``backend/rig.py``, which builds the robots: the plant and the drivers
never import each other. The page gets the rig's fault tables (:data:`EMULATOR_FAULTS`,
:data:`DEFAULT_EMCY`) through the supervisor (``RigControl.fault_tables``).

The rig is the robot's side of the wire in simulation. A thread steps the plant
(``backend.sim``) in real time, or ``pace`` times faster, and its sensor models feed the
emulators, which speak the devices' protocols to whatever drivers connect:

* four EPOS2 nodes (``epos2_emulator``) on a python-can ``virtual`` bus, whose servos are
  the plant's fins (:class:`PlantFinServo`: a profile-position set-point becomes
  ``Plant.command_fin``, position and velocity actual are the fin's angle and rate);
  the thread ticks them after each plant step, so their TPDOs carry the plant's state;
* the 3DM-CX5 (``imu_emulator``) on a pty, streaming the plant's latest IMU sample;
* the DVL A50 (``dvl_emulator``) on 127.0.0.1, reporting the plant's latest DVL sample
  (``valid=False`` becomes lost bottom lock) and its position;
* the pressure ADC (``pressure_emulator``) on a pty, sending the loop current of the
  plant's latest depth sample through the driver's transducer scaling, for a transducer
  ``rig.pressure_mount_depth`` below the robot's depth reference (under water while the
  robot floats at the surface, as on the robot; the drivers start zeroed for it).

:meth:`SimRig.start` returns the :class:`DevicesConfig` whose endpoints reach the
emulators. :meth:`SimRig.inject` starts a fault in one emulator (the list is in its
docstring); the drivers then report it as they would report the real device's fault.
"""

from __future__ import annotations

import logging
import math
import threading
import time
import uuid
from typing import Any, Callable

from ucat_console.backend.devices import cia402
from ucat_console.backend.devices.config import DevicesConfig
from ucat_console.backend.devices.dvl_emulator import DvlEmulator, DvlTruth
from ucat_console.backend.devices.epos2_emulator import (
    EmulatedNodes,
    Epos2EmulatorConfig,
    start_emulated_nodes,
)
from ucat_console.backend.devices.faults import Fault, as_fault
from ucat_console.backend.devices.imu_emulator import ImuEmulator
from ucat_console.backend.devices.pressure_emulator import PressureEmulator
from ucat_console.robot.readings import DepthReading, DvlVelocity, ImuReading
from ucat_console.backend.sim_robot_io import SimRobotIO
from ucat_console.robot.interface import RobotTruth
from ucat_console.robot.units import GRAVITY
from ucat_console.backend.sim.params import PlantConfig
from ucat_console.backend.sim.plant import F_CURRENT
from ucat_console.telemetry.events import Event, EventSink, ignore_events

log = logging.getLogger(__name__)

SOURCE = "rig"
#: devices that take faults, and the faults each takes
EMULATOR_FAULTS: dict[str, tuple[str, ...]] = {
    "epos2": ("emcy", "heartbeat_loss", "silence", "slow", "low_voltage"),
    "imu": tuple(f.value for f in Fault),
    "dvl": tuple(f.value for f in Fault),
    "pressure": tuple(f.value for f in Fault),
}
#: what the ``implausible`` fault of each sensor takes (the emulator's ``set_implausible``)
IMPLAUSIBLE: dict[str, tuple[str, ...]] = {
    "imu": ("accel_g", "gyro", "quaternion"), "dvl": ("velocity",), "pressure": ("current_ma", "jump_m"),
}
#: EMCY injected when no code is given: overcurrent
DEFAULT_EMCY = 0x2310
_SLOWEST_PROFILE = 1e-6  # rad/s: a set-point of "no speed" holds the fin where it is


class PlantFinServo:
    """One plant fin as an EPOS2 emulator's servo (the ``epos2_emulator.Servo`` protocol)."""

    def __init__(self, rig: SimRig, fin: int) -> None:
        self._rig = rig
        self.fin = fin

    @property
    def deceleration(self) -> float:
        """The plant servo's braking (rad/s2), for the emulator's stopping distance."""
        return self._rig.plant.cfg.servo.acceleration

    def command(self, target_rad: float, profile_velocity_rad_s: float) -> None:
        v = abs(profile_velocity_rad_s)
        if not math.isfinite(v) or v < _SLOWEST_PROFILE:
            v = _SLOWEST_PROFILE
        with self._rig.plant_lock:
            self._rig.plant.command_fin(self.fin, target_rad, v)

    def state(self) -> tuple[float, float]:
        with self._rig.plant_lock:
            p = self._rig.plant
            return p.fin_angles()[self.fin], p.fin_rates()[self.fin]

    def current(self) -> float:
        """The fin drive's motor current (A) in the plant's last step (``robot.motor``): what
        the emulated drive reports."""
        with self._rig.plant_lock:
            return float(self._rig.plant.state_arrays()[1][self.fin, F_CURRENT])

    def step(self, dt: float) -> None:
        """Nothing: the rig's thread steps the whole plant."""


class SimRig:
    """The plant stepped in real time (or at ``config.rig.pace``) behind the emulators."""

    def __init__(
        self,
        config: DevicesConfig,
        plant: PlantConfig | None = None,
        *,
        on_event: EventSink = ignore_events,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.config = config
        s = config.start
        self._sim = SimRobotIO(
            plant, depth=s.depth, yaw=s.yaw, velocity=s.velocity, seed=None if s.seed < 0 else s.seed
        )
        self.plant = self._sim.plant
        #: held around every use of the plant (the servos are called from CAN threads)
        self.plant_lock = threading.Lock()
        self._clock = clock
        self.on_event = on_event
        self.pace = config.rig.pace
        self._imu: ImuReading | None = None
        self._dvl: DvlVelocity | None = None
        self._depth: DepthReading | None = None
        self._pose: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._timers: list[threading.Timer] = []
        self._t0 = 0.0
        self.fin_of_node = {node: fin for fin, node in enumerate(config.epos2.node_ids)}
        self.nodes: EmulatedNodes | None = None
        self.imu: ImuEmulator | None = None
        self.dvl: DvlEmulator | None = None
        self.pressure: PressureEmulator | None = None
        self.failed: BaseException | None = None

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> DevicesConfig:
        """Start the emulators and the plant; the device configuration that reaches them."""
        cfg, rig = self.config, self.config.rig
        channel = rig.can_channel or f"ucat-sim-{uuid.uuid4().hex[:10]}"
        try:
            emu_cfg = Epos2EmulatorConfig(
                units=cfg.epos2.units, max_rate=self.plant.cfg.servo.max_rate,
                servo_acceleration=self.plant.cfg.servo.acceleration, tick_period=rig.tick_period_s,
                supply_voltage=self.plant.cfg.motor.supply_voltage,
            )
            self.nodes = start_emulated_nodes(
                channel, cfg.epos2.node_ids, lambda node: PlantFinServo(self, self.fin_of_node[node]),
                config=emu_cfg, interface="virtual", run_thread=False,
            )
            self._t0 = self._clock()
            self._step()
            self._thread = threading.Thread(target=self._run, name="sim-rig", daemon=True)
            self._thread.start()
            self.imu = ImuEmulator(self._imu_sample, rig.imu).start()
            self.dvl = DvlEmulator(self._dvl_sample, rig.dvl).start()
            mount_pa = rig.pressure_mount_depth * cfg.pressure.rho * GRAVITY
            emulated = rig.pressure.replace(surface_offset_pa=rig.pressure.surface_offset_pa + mount_pa)
            self.pressure = PressureEmulator(self._depth_sample, emulated, transducer=cfg.pressure).start()
        except BaseException:
            self.stop()
            raise
        host, port = self.dvl.address
        log.info("simulated rig: CAN %r, IMU %s, DVL %s:%d, pressure %s",
                 channel, self.imu.port, host, port, self.pressure.port)
        # the emulated drives run the plant's motors: the console reads their current with them
        return cfg.replace(
            epos2=cfg.epos2.replace(interface="virtual", channel=channel, motor=self.plant.cfg.motor,
                                    sdo_timeout=max(cfg.epos2.sdo_timeout, cfg.rig.sdo_timeout_s)),
            imu=cfg.imu.replace(port=self.imu.port),
            dvl=cfg.dvl.replace(host=host, port=port),
            pressure=cfg.pressure.replace(port=self.pressure.port,
                                          surface_pressure_pa=cfg.pressure.surface_pressure_pa + mount_pa),
        )

    def stop(self) -> None:
        """Stop the plant and every emulator (safe to call more than once)."""
        self._stop.set()
        for timer in self._timers:
            timer.cancel()
        self._timers.clear()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        for name in ("imu", "dvl", "pressure"):
            emulator = getattr(self, name)
            if emulator is not None:
                try:
                    emulator.stop()
                except Exception:
                    log.exception("stopping the %s emulator failed", name)
                setattr(self, name, None)
        if self.nodes is not None:
            self.nodes.close()
            self.nodes = None

    def __enter__(self) -> SimRig:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def time(self) -> float:
        """The plant's simulated time (s)."""
        with self.plant_lock:
            return self.plant.time

    def device_time(self, device: str) -> float:
        """The time (on the rig's clock) emulator ``device`` (``"epos2"``: the drives, or
        ``"imu"``, ``"dvl"``, ``"pressure"``) has run to: everything it was due to send by
        then has been sent. The drivers judge the emulators' silence against it: an
        emulator held back by a busy machine is late, not silent."""
        if device not in EMULATOR_FAULTS:
            raise ValueError(f"device: {device!r} is not one of {', '.join(EMULATOR_FAULTS)}")
        emulator = self.nodes if device == "epos2" else getattr(self, device)
        return emulator.time if emulator is not None else -math.inf

    def truth(self) -> RobotTruth:
        """The plant's true state now (``t``: plant time)."""
        with self.plant_lock:
            return self._sim.truth()

    # ------------------------------------------------------------------ the plant
    def _run(self) -> None:
        period = self.config.rig.tick_period_s
        next_tick = self._clock()
        while not self._stop.is_set():
            try:
                self._step()
            except Exception as e:
                log.exception("simulated rig stopped")
                self.failed = e
                self._event("plant_failed", f"the simulated plant stopped: {e}", "fatal", {})
                return
            next_tick += period
            now = self._clock()
            if next_tick < now:  # behind: do not try to catch up in a burst
                next_tick = now
            self._stop.wait(next_tick - now)

    def _step(self) -> None:
        now = self._clock()
        t = self.pace * (now - self._t0)
        with self.plant_lock:
            readings = self.plant.advance_and_sample(t)  # what the emulators send: the drivers' robot checks it
            pose = self.plant.pose()[0], self.plant.euler()
        for r in readings:
            tp = type(r)
            if tp is ImuReading:
                self._imu = r
            elif tp is DvlVelocity:
                self._dvl = r
            elif tp is DepthReading:
                self._depth = r
        self._pose = pose
        if self.nodes is not None:
            self.nodes.tick(now)

    # ------------------------------------------------------------------ emulator sources
    def _imu_sample(self, t: float) -> ImuReading | None:
        return self._imu

    def _dvl_sample(self, t: float) -> DvlTruth | None:
        v, pose = self._dvl, self._pose
        if v is None or pose is None:
            return None
        (x, y, z), (roll, pitch, yaw) = pose
        altitude = v.altitude if math.isfinite(v.altitude) else -1.0
        fom = v.fom if math.isfinite(v.fom) else 2.707
        if not v.valid:
            return DvlTruth(vx=0.0, vy=0.0, vz=0.0, altitude=altitude, bottom_lock=False, fom=fom,
                            x=x, y=y, z=z, roll=roll, pitch=pitch, yaw=yaw)
        return DvlTruth(vx=v.vx, vy=v.vy, vz=v.vz, altitude=altitude, bottom_lock=True, fom=fom,
                        x=x, y=y, z=z, roll=roll, pitch=pitch, yaw=yaw)

    def _depth_sample(self, t: float) -> float | None:
        d = self._depth
        return None if d is None else d.depth_m

    # ------------------------------------------------------------------ faults
    def inject(self, device: str, fault: str, **kw: Any) -> Event:
        """Start ``fault`` in ``device``'s emulator; returns (and reports) a ``fault_injected`` event.

        * ``imu``, ``dvl``, ``pressure``: ``silence``, ``corrupt``, ``invalid``,
          ``implausible``, ``slow`` (meaning per emulator: see its docstring); ``duration``
          (s) ends it by itself. ``implausible`` takes what to send (:data:`IMPLAUSIBLE`:
          ``pressure`` ``current_ma`` or ``jump_m``; ``imu`` ``accel_g``, ``gyro``,
          ``quaternion``; ``dvl`` ``velocity``), each emulator's default when none is given.
        * ``epos2`` (``fin`` 0-3, default 0, or ``node``): ``emcy`` (``code``, default
          0x2310 overcurrent; ``register``), ``heartbeat_loss``, ``silence`` (the node
          stops answering), ``slow`` (``delay_s`` on each SDO reply, default 2 s: beyond the
          drivers' SDO timeout on the rig, ``rig.sdo_timeout_s``), ``low_voltage`` (the
          drive measures ``volts`` supply, default 20 V: a sagging pack); each
          but ``emcy`` takes ``duration`` (s). An EMCY fault stays until the drive's fault
          is reset, as on the EPOS2.

        Unknown devices, faults or arguments raise ValueError naming them.
        """
        if device not in EMULATOR_FAULTS:
            raise ValueError(f"device: {device!r} is not one of {', '.join(EMULATOR_FAULTS)}")
        if fault not in EMULATOR_FAULTS[device]:
            raise ValueError(
                f"fault: {fault!r} is not a fault of {device}; allowed: {', '.join(EMULATOR_FAULTS[device])}"
            )
        if device == "epos2":
            data = self._inject_epos2(fault, dict(kw))
        else:
            _only(kw, ("duration", *IMPLAUSIBLE[device]) if fault == "implausible" else ("duration",))
            values = {k: v for k, v in kw.items() if k != "duration"}
            duration = _duration(kw.get("duration"))
            emulator = self._emulator(device)
            if fault == "implausible":
                emulator.set_implausible(**values)
            emulator.inject(as_fault(fault), duration)
            data = {"duration": duration, **values}
        data = {"device": device, "fault": fault, **data}
        return self._event("fault_injected", f"{device}: {fault} injected", "info", data)

    def clear(self, device: str, fault: str | None = None) -> None:
        """End one fault of ``device`` (or all of them); an EMCY fault is reset by the drive."""
        if device not in EMULATOR_FAULTS:
            raise ValueError(f"device: {device!r} is not one of {', '.join(EMULATOR_FAULTS)}")
        if fault is not None and fault not in EMULATOR_FAULTS[device]:
            raise ValueError(
                f"fault: {fault!r} is not a fault of {device}; allowed: {', '.join(EMULATOR_FAULTS[device])}"
            )
        if device == "epos2":
            nodes = self._nodes()
            for emulator in nodes.nodes.values():
                if fault in (None, "heartbeat_loss"):
                    emulator.resume_heartbeat()
                if fault in (None, "silence"):
                    emulator.unsilence()
                if fault in (None, "slow"):
                    emulator.slow_replies(0.0)
                if fault in (None, "low_voltage"):
                    emulator.set_supply_voltage(None)
        else:
            self._emulator(device).clear(None if fault is None else as_fault(fault))
        self._event("fault_cleared", f"{device}: {fault or 'all faults'} cleared", "info",
                    {"device": device, "fault": fault})

    def _inject_epos2(self, fault: str, kw: dict[str, Any]) -> dict[str, Any]:
        allowed = {"emcy": ("fin", "node", "code", "register"),
                   "heartbeat_loss": ("fin", "node", "duration"),
                   "silence": ("fin", "node", "duration"),
                   "slow": ("fin", "node", "delay_s", "duration"),
                   "low_voltage": ("fin", "node", "volts", "duration")}[fault]
        _only(kw, allowed)
        node = self._node_id(kw.get("fin"), kw.get("node"))
        emulator = self._nodes()[node]
        data: dict[str, Any] = {"node": node, "fin": self.fin_of_node[node]}
        if fault == "emcy":
            code = kw.get("code", DEFAULT_EMCY)
            if isinstance(code, bool) or not isinstance(code, int) or not 0 < code <= 0xFFFF:
                raise ValueError(f"code: {code!r} is not a non-zero 16-bit EMCY error code")
            register = kw.get("register")
            emulator.inject_emcy(code, register)
            return {**data, "code": code, "name": cia402.emcy_name(code)}
        duration = _duration(kw.get("duration"))
        if fault == "heartbeat_loss":
            emulator.stop_heartbeat()
            self._after(duration, emulator.resume_heartbeat)
        elif fault == "silence":
            emulator.silence()
            self._after(duration, emulator.unsilence)
        elif fault == "low_voltage":
            volts = kw.get("volts", 20.0)
            if isinstance(volts, bool) or not isinstance(volts, (int, float)) or not 0.0 <= volts <= 100.0:
                raise ValueError(f"volts: {volts!r} is out of range; allowed: [0, 100] V")
            emulator.set_supply_voltage(float(volts))
            self._after(duration, lambda: emulator.set_supply_voltage(None))
            data["volts"] = float(volts)
        else:
            delay = kw.get("delay_s", 2.0)
            if isinstance(delay, bool) or not isinstance(delay, (int, float)) or not 0.0 < delay <= 60.0:
                raise ValueError(f"delay_s: {delay!r} is out of range; allowed: (0, 60] s")
            emulator.slow_replies(float(delay))
            self._after(duration, lambda: emulator.slow_replies(0.0))
            data["delay_s"] = float(delay)
        return {**data, "duration": duration}

    def _node_id(self, fin: Any, node: Any) -> int:
        if fin is not None and node is not None:
            raise ValueError("fin/node: give one of them, not both")
        if node is not None:
            if node not in self.fin_of_node:
                raise ValueError(f"node: {node!r} is not one of the nodes {sorted(self.fin_of_node)}")
            return node
        fin = 0 if fin is None else fin
        nodes = self.config.epos2.node_ids
        if isinstance(fin, bool) or not isinstance(fin, int) or not 0 <= fin < len(nodes):
            raise ValueError(f"fin: {fin!r} is not a fin index 0..{len(nodes) - 1}")
        return nodes[fin]

    def _after(self, duration: float | None, action: Callable[[], None]) -> None:
        if duration is None:
            return
        timer = threading.Timer(duration, action)
        timer.daemon = True
        self._timers.append(timer)
        timer.start()

    def _nodes(self) -> EmulatedNodes:
        if self.nodes is None:
            raise RuntimeError("the simulated rig is not running")
        return self.nodes

    def _emulator(self, device: str) -> Any:
        emulator = getattr(self, device)
        if emulator is None:
            raise RuntimeError("the simulated rig is not running")
        return emulator

    def _event(self, code: str, message: str, level: str, data: dict[str, Any]) -> Event:
        event = Event(t=self._clock(), source=SOURCE, code=code, message=message, level=level, data=data)
        try:
            self.on_event(event)
        except Exception:
            log.exception("rig event sink failed on %s", code)
        return event


def _only(kw: dict[str, Any], allowed: tuple[str, ...]) -> None:
    for key in kw:
        if key not in allowed:
            raise ValueError(f"{key}: not an argument of this fault; allowed: {', '.join(allowed)}")


def _duration(value: Any) -> float | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0.0 < value <= 3600.0:
        raise ValueError(f"duration: {value!r} is out of range; allowed: (0, 3600] s or None")
    return float(value)
