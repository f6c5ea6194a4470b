# Over 600 lines: one emulated EPOS2 node: its object dictionary's behaviour, CiA 402 state machine, PDO timing and servo share its state.
"""EPOS2 emulator: CANopen CiA 402 nodes that speak the EPOS2's frames on a CAN bus.

Each emulated node is a ``canopen.LocalNode`` built from ``epos2.eds`` on its own
``canopen.Network`` (its own python-can bus on the same channel as the driver, normally the
in-process ``virtual`` interface). It implements what the driver relies on:

* NMT: boot-up after reset node / reset communication (communication objects back to their
  EDS defaults), pre-operational, operational; heartbeat producer (0x1017) and a heartbeat
  consumer (0x1016) that faults with EMCY 0x8130 when the master's heartbeat stops.
* SDO (canopen's server) and RPDOs; a LocalNode's RPDO frames reach only the ``rpdo[n]``
  callbacks in canopen 2.4, so this module writes their contents into the object dictionary
  itself (through the same write path as SDO). TPDOs are transmitted from here: every event
  timer period (0x18xx sub 5) and, for a TPDO carrying the statusword, whenever it changes.
* The CiA 402 state machine driven by controlword writes, profile position mode with
  set-point acknowledge (bit 12) and target reached (bit 10), halt, relative moves, quick
  stop, fault and fault reset (rising edge of bit 7).
* Motion through a pluggable servo (:class:`Servo`); :class:`TrapezoidalServo` is the
  standalone default (acceleration limit, maximum rate, encoder quantisation).
* The drive's electrical input (maxon's objects): the motor current 0x6078 and its average
  0x2027 (mA) and the supply voltage 0x2200 sub 1 (0.1 V). A servo with ``current()``
  gives the motor current itself (the simulated rig's: the plant's drive model,
  ``robot.motor``); otherwise the motor draws its no-load current while the power stage is
  on. The average is a first-order filter of the current over the ticks (time constant
  ``current_average_s``).
* Fault injection: :meth:`Epos2Emulator.inject_emcy`, ``stop_heartbeat``/``resume_heartbeat``,
  ``silence``/``unsilence``, ``slow_replies`` and ``set_supply_voltage`` (a sagging pack).

Time advances through :meth:`Epos2Emulator.tick` (the headless simulator and tests call it
with their own clock) or through a thread that calls it (:meth:`EmulatedNodes.start_thread`).
The heartbeat is sent by the tick too, when due, and every frame is stamped with the time the
drive sent it (``_GatedNetwork``): a tick held back by a busy machine looks to the driver like
a reader held back, not like a drive that went silent.

Over 500 lines: :class:`Epos2Emulator` is one node's object dictionary hooks, NMT, CiA 402
state machine, profile position, PDOs and fault injection, all on the node's one state;
the servo it moves is the plant's model (``robot.servo``).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any, Protocol

import can
import canopen
from canopen.sdo import SdoAbortedError

from ucat_console.backend.devices import cia402
from ucat_console.backend.devices.canbus import open_bus
from ucat_console.backend.devices.epos2 import EDS_PATH
from ucat_console.robot.servo import servo_step
from ucat_console.robot.units import DriveUnits
from ucat_console.typedconf import Config, param

logger = logging.getLogger(__name__)

_INT32_MIN, _INT32_MAX = -(2**31), 2**31 - 1
_ABORT_VALUE_RANGE = 0x06090030  # value range of parameter exceeded
_ABORT_VALUE_TOO_LOW = 0x06090032
_SUPPORTED_MODES = (cia402.MODE_PROFILE_POSITION, cia402.MODE_PROFILE_VELOCITY, cia402.MODE_HOMING)

#: statusword of each state, before the mode-specific bits 10 and 12
_STATUS_BASE = {
    cia402.NOT_READY: 0x0000,
    cia402.SWITCH_ON_DISABLED: 0x0040,
    cia402.READY_TO_SWITCH_ON: 0x0021,
    cia402.SWITCHED_ON: 0x0023 | cia402.SW_VOLTAGE_ENABLED,
    cia402.OPERATION_ENABLED: 0x0027 | cia402.SW_VOLTAGE_ENABLED,
    cia402.QUICK_STOP_ACTIVE: 0x0007 | cia402.SW_VOLTAGE_ENABLED,
    cia402.FAULT_REACTION_ACTIVE: 0x000F | cia402.SW_VOLTAGE_ENABLED,
    cia402.FAULT: 0x0008,
}


class Servo(Protocol):
    """A fin servo in profile-position mode, in fin units (rad, rad/s).

    Optional extras the emulator uses when present: ``set_acceleration(acc, dec)`` (rad/s2,
    from 0x6083/0x6084/0x6085) and ``current() -> float`` (A, the motor current, for 0x6078
    and 0x2027).
    """

    def command(self, target_rad: float, profile_velocity_rad_s: float) -> None: ...

    def state(self) -> tuple[float, float]: ...

    def step(self, dt: float) -> None: ...


class TrapezoidalServo:
    """Trapezoidal velocity profile towards the target, as the EPOS2 runs profile position:
    the plant's servo model (``robot.servo.servo_step``), stepped here.

    Accelerates at ``acceleration`` up to the commanded profile velocity (capped at
    ``max_rate``) and brakes at ``deceleration`` so as to stop on the target. Position is
    reported quantised to ``resolution_rad`` (one encoder quadcount at the fin); ``step``
    integrates in sub-steps of at most ``max_substep`` seconds.
    """

    def __init__(
        self,
        acceleration: float = 64.0,
        max_rate: float = 20.0,
        resolution_rad: float = 0.0,
        position: float = 0.0,
        deceleration: float | None = None,
        max_substep: float = 1e-3,
    ) -> None:
        if not acceleration > 0.0:
            raise ValueError(f"acceleration: must be > 0, got {acceleration!r}")
        if not max_rate > 0.0:
            raise ValueError(f"max_rate: must be > 0, got {max_rate!r}")
        self.acceleration = float(acceleration)
        self.deceleration = float(deceleration if deceleration is not None else acceleration)
        self.max_rate = float(max_rate)
        self.resolution_rad = float(resolution_rad)
        self.max_substep = float(max_substep)
        self._x = float(position)
        self._v = 0.0
        self._target = float(position)
        self._vmax = self.max_rate

    def set_acceleration(self, acceleration: float, deceleration: float) -> None:
        if acceleration > 0.0:
            self.acceleration = float(acceleration)
        if deceleration > 0.0:
            self.deceleration = float(deceleration)

    def command(self, target_rad: float, profile_velocity_rad_s: float) -> None:
        self._target = float(target_rad)
        self._vmax = min(abs(float(profile_velocity_rad_s)), self.max_rate)

    def state(self) -> tuple[float, float]:
        x = self._x
        if self.resolution_rad > 0.0:
            x = round(x / self.resolution_rad) * self.resolution_rad
        return x, self._v

    @property
    def target(self) -> float:
        return self._target

    def step(self, dt: float) -> None:
        remaining = float(dt)
        while remaining > 1e-12:
            h = min(remaining, self.max_substep)
            self._substep(h)
            remaining -= h

    def _substep(self, h: float) -> None:
        self._x, self._v, _ = servo_step(self._x, self._v, self._target, self._vmax,
                                         self.acceleration, self.max_rate, h, self.deceleration)


@dataclass(frozen=True)
class Epos2EmulatorConfig(Config):
    """Emulated EPOS2 nodes (simulation and tests)."""

    units: DriveUnits = DriveUnits()
    max_rate: float = param(
        20.0, lo=0.0, hi=1000.0, lo_open=True, unit="rad/s",
        doc="fastest fin rate of the default trapezoidal servo",
    )
    servo_acceleration: float = param(
        64.0, lo=0.0, hi=100_000.0, lo_open=True, unit="rad/s2",
        doc="acceleration of the default servo until the master writes 0x6083/0x6084",
    )
    position_window: int = param(
        2, lo=0, hi=1_000_000, unit="qc", doc="target reached within this many quadcounts"
    )
    velocity_window: float = param(
        0.05, lo=0.0, hi=100.0, unit="rad/s", doc="target reached below this fin rate"
    )
    tick_period: float = param(
        0.002, lo=1e-4, hi=0.1, unit="s", doc="period of the emulator thread (real-time mode)"
    )
    supply_voltage: float = param(
        24.0, lo=0.0, hi=70.0, lo_open=True, unit="V",
        doc="supply voltage at the power stage the node reports (0x2200 sub 1)",
    )
    no_load_current: float = param(
        0.05, lo=0.0, hi=10.0, unit="A", doc="motor current while the power stage is on and the shaft idle"
    )
    current_average_s: float = param(
        0.01, lo=1e-4, hi=10.0, unit="s", doc="time constant of the averaged current (0x2027)"
    )


#: states with the power stage on (the motor draws current)
_POWERED = (cia402.OPERATION_ENABLED, cia402.QUICK_STOP_ACTIVE, cia402.FAULT_REACTION_ACTIVE)


def _milliamps(amps: float) -> int:
    """A current as the INT16 mA of 0x6078 and 0x2027 (saturated)."""
    return max(-32768, min(32767, int(round(amps / cia402.CURRENT_UNIT))))


class _GatedNetwork(canopen.Network):
    """A canopen network whose traffic can be cut (``silenced``) or slowed (SDO replies),
    and whose frames are stamped with the emulated device's time.

    The device's time (:attr:`time`) is the emulator's last tick: a frame it sends carries
    that time (``can.Message.timestamp``, kept by the ``virtual`` bus), and a periodic frame
    (the heartbeat, canopen's ``send_periodic``) is sent by the tick when due, stamped with
    the time it was due (:meth:`send_due`). So a tick held back by a busy machine sends what
    the drive would have sent, stamped when it would have sent it, in order: the driver
    sees a device on time and a reader that was late, as on the robot when the console's
    computer is busy.
    """

    def __init__(self, bus: Any, sdo_reply_cob_id: int, clock: Callable[[], float]) -> None:
        super().__init__(bus)
        self.silenced = False
        self.reply_delay = 0.0
        self._sdo_reply_cob_id = sdo_reply_cob_id
        self._clock = clock
        #: the emulated device's present (its last tick, on ``clock``); None before the first
        self.time: float | None = None
        self._periodic: list[_PeriodicFrame] = []
        self._periodic_lock = threading.Lock()

    def notify(self, can_id: int, data: bytearray, timestamp: float) -> None:
        if self.silenced:
            return
        super().notify(can_id, data, timestamp)

    def send_message(self, can_id: int, data: Any, remote: bool = False, at: float | None = None) -> None:
        """Send a frame stamped ``at`` (default: the device's present) on ``clock``."""
        if self.silenced:
            return
        if can_id == self._sdo_reply_cob_id and self.reply_delay > 0.0:
            time.sleep(self.reply_delay)
            if self.silenced:
                return
        if self.bus is None:
            raise RuntimeError("Not connected to CAN bus")
        now = self._clock()
        t = at if at is not None else (self.time if self.time is not None else now)
        msg = can.Message(is_extended_id=can_id > 0x7FF, arbitration_id=can_id, data=data,
                          is_remote_frame=remote, timestamp=time.time() - (now - min(t, now)))
        with self.send_lock:
            self.bus.send(msg)
        self.check()

    def send_periodic(self, can_id: int, data: Any, period: float,
                      remote: bool = False) -> _PeriodicFrame:
        """A frame sent every ``period`` s by :meth:`send_due` (canopen's heartbeat)."""
        frame = _PeriodicFrame(self, can_id, data, period, remote)
        with self._periodic_lock:
            self._periodic.append(frame)
        return frame

    def _forget(self, frame: _PeriodicFrame) -> None:
        with self._periodic_lock:
            if frame in self._periodic:
                self._periodic.remove(frame)

    def send_due(self, now: float) -> None:
        """Send each periodic frame due by ``now``, once, stamped with its latest due time."""
        with self._periodic_lock:
            frames = list(self._periodic)
        for frame in frames:
            frame.send_due(now)


class _PeriodicFrame:
    """One periodic frame of a :class:`_GatedNetwork` (the interface of canopen's
    ``PeriodicMessageTask``: ``stop`` and ``update``). Due at once, then every period."""

    def __init__(self, network: _GatedNetwork, can_id: int, data: Any, period: float, remote: bool) -> None:
        self._network = network
        self.can_id = can_id
        self.data = bytes(data or b"")
        self.period = float(period)
        self.remote = remote
        self.due: float | None = None  # None: due at the next tick

    def stop(self) -> None:
        self._network._forget(self)

    def update(self, data: Any) -> None:
        self.data = bytes(data)

    def send_due(self, now: float) -> None:
        due = now if self.due is None else self.due
        if due > now:
            return
        if self.period > 0.0:  # the latest time it fell due: missed ones are not sent twice
            due += math.floor((now - due) / self.period) * self.period
        self._network.send_message(self.can_id, self.data, self.remote, at=due)
        self.due = due + self.period


class Epos2Emulator:
    """One emulated EPOS2 node on ``channel``."""

    NOTIFIER_CYCLE = 0.1  # s; bounds how long closing the emulator's network takes

    def __init__(
        self,
        channel: str,
        node_id: int,
        servo: Servo | None = None,
        config: Epos2EmulatorConfig | None = None,
        *,
        interface: str = "virtual",
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if not 1 <= node_id <= 127:
            raise ValueError(f"node_id: {node_id!r} is out of range; allowed: [1, 127]")
        self.node_id = node_id
        self.config = config or Epos2EmulatorConfig()
        self.units = self.config.units
        #: the supply voltage it measures (V): the configuration's, unless a fault set another
        self.supply_voltage = self.config.supply_voltage
        self._clock = clock
        self.servo: Servo = servo or TrapezoidalServo(
            acceleration=self.config.servo_acceleration,
            max_rate=self.config.max_rate,
            resolution_rad=self.units.resolution_rad,
        )
        self._lock = threading.RLock()
        self._state = cia402.NOT_READY
        self._controlword = 0
        self._mode = 0
        self._target_qc = 0
        self._profile_rpm = 0
        self._setpoint_ack = False
        self._target_reached = True
        self._halted = False
        self._error_register = 0
        self._last_tick: float | None = None
        self._last_status_sent: int | None = None
        self._tpdo_due: dict[int, float] = {}
        self._tpdo_period: dict[int, float] = {}
        self._heartbeat_stopped = False
        self._consumer_cob_id: int | None = None
        self._consumer_timeout = 0.0
        self._consumer_last: float | None = None
        self._current_average = 0.0  # A, 0x2027
        #: controlwords received, oldest first (for tests and logs)
        self.controlword_log: list[int] = []

        bus = open_bus(interface, channel, key="interface", stamped=True)
        self.network = _GatedNetwork(bus, 0x580 + node_id, clock)
        self.network.NOTIFIER_CYCLE = self.NOTIFIER_CYCLE
        od = canopen.import_od(str(EDS_PATH), node_id)
        self.node: canopen.LocalNode = self.network.create_node(node_id, od)
        self.node.add_read_callback(self._on_read)
        self.node.add_write_callback(self._on_write)
        for pdo_map in self.node.rpdo.map.values():
            pdo_map.add_callback(self._on_rpdo)
        self.network.subscribe(0, self._on_nmt)  # after the NMT slave's own handler
        self.network.connect()
        self._boot(reset_application=True)

    # ----------------------------------------------------------------------------- lifecycle
    def close(self) -> None:
        """Stop the heartbeat and leave the bus."""
        try:
            self.node.nmt.stop_heartbeat()
        finally:
            self.network.disconnect()

    def __enter__(self) -> Epos2Emulator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _boot(self, reset_application: bool) -> None:
        """Power-on / reset: boot-up message, pre-operational, communication defaults."""
        with self._lock:
            store = self.node.data_store
            for index in list(store):
                if reset_application or 0x1000 <= index <= 0x1FFF:
                    del store[index]
            if reset_application:
                self._state = cia402.SWITCH_ON_DISABLED  # NOT READY passes automatically
                self._controlword = 0
                self._mode = 0
                self._setpoint_ack = False
                self._halted = False
                self._error_register = 0
                self._stop_motion()
            self._set_consumer(0)
            self._last_status_sent = None
            self._tpdo_due.clear()
            self.node.nmt.send_command(cia402.NMT_RESET_COMMUNICATION)  # sends boot-up
            self.node.nmt.send_command(cia402.NMT_PRE_OPERATIONAL)  # heartbeat per 0x1017
            if self._heartbeat_stopped:
                self.node.nmt.stop_heartbeat()
            self._load_pdos()

    def _load_pdos(self) -> None:
        with self._lock:
            self.node.tpdo.read()
            self.node.rpdo.read()
            self._tpdo_period = {}
            for n, pdo_map in self.node.tpdo.map.items():
                if pdo_map.enabled and pdo_map.event_timer:
                    self._tpdo_period[n] = pdo_map.event_timer / 1000.0
            self._tpdo_due.clear()

    # ----------------------------------------------------------------------------- NMT
    def _on_nmt(self, can_id: int, data: bytearray, timestamp: float) -> None:
        if len(data) < 2:
            return
        command, target = data[0], data[1]
        if target not in (0, self.node_id):
            return
        try:
            if command in (cia402.NMT_RESET_NODE, cia402.NMT_RESET_COMMUNICATION):
                self._boot(reset_application=command == cia402.NMT_RESET_NODE)
            elif command == cia402.NMT_START:
                self._load_pdos()
                self._last_status_sent = None
        except Exception:
            logger.exception("EPOS2 emulator node %d: NMT command 0x%02X failed",
                             self.node_id, command)

    @property
    def nmt_state(self) -> str:
        return self.node.nmt.state

    def _operational(self) -> bool:
        return self.node.nmt.state == "OPERATIONAL"

    # ----------------------------------------------------------------------------- OD access
    def _on_read(self, index: int, subindex: int, od: Any) -> int | None:
        with self._lock:
            if index == cia402.STATUSWORD:
                return self._statusword()
            if index == cia402.MODES_OF_OPERATION_DISPLAY:
                return self._mode
            if index == cia402.POSITION_ACTUAL:
                return self._position_qc()
            if index == cia402.VELOCITY_ACTUAL:
                return self._velocity_rpm()
            if index == cia402.CURRENT_ACTUAL:
                return _milliamps(self.motor_current())
            if index == cia402.CURRENT_ACTUAL_AVERAGED:
                return _milliamps(self._current_average)
            if index == cia402.POWER_SUPPLY and subindex == cia402.POWER_SUPPLY_VOLTAGE_SUB:
                return int(round(self.supply_voltage / cia402.POWER_SUPPLY_VOLTAGE_UNIT))
            if index == cia402.ERROR_REGISTER:
                return self._error_register
            if index == cia402.CONTROLWORD:
                return self._controlword
        return None

    def _stored(self, index: int, subindex: int = 0) -> int:
        obj = self.node.object_dictionary[index]
        if subindex or not isinstance(obj, canopen.objectdictionary.ODVariable):
            obj = obj[subindex]
        return obj.decode_raw(self.node.get_data(index, subindex))

    def _on_write(self, index: int, subindex: int, od: Any, data: bytes) -> None:
        value = od.decode_raw(data)
        with self._lock:
            if index == cia402.CONTROLWORD:
                self._apply_controlword(value)
            elif index == cia402.MODES_OF_OPERATION:
                if value not in _SUPPORTED_MODES:
                    raise SdoAbortedError(_ABORT_VALUE_RANGE)
                self._mode = value
            elif index in (cia402.PROFILE_ACCELERATION, cia402.PROFILE_DECELERATION,
                           cia402.QUICK_STOP_DECELERATION):
                if value == 0:
                    raise SdoAbortedError(_ABORT_VALUE_TOO_LOW)
            elif index == cia402.CONSUMER_HEARTBEAT_TIME and subindex == 1:
                self._set_consumer(value)
        if index == cia402.CONTROLWORD:
            self._publish_status()

    def _on_rpdo(self, pdo_map: Any) -> None:
        """Apply a received RPDO to the object dictionary (canopen leaves that to us)."""
        if not self._operational():
            return
        try:
            if len(pdo_map.data) * 8 < pdo_map.length:
                logger.warning("EPOS2 emulator node %d: %s too short (%d bytes)",
                               self.node_id, pdo_map.name, len(pdo_map.data))
                self.node.emcy.send(cia402.EMCY_PDO_LENGTH,
                                    cia402.error_register_for(cia402.EMCY_PDO_LENGTH))
                return
            for var in pdo_map.map:
                if var.length:
                    self.node.set_data(var.index, var.subindex, bytes(var.get_data()),
                                       check_writable=True)
        except SdoAbortedError as e:
            logger.warning("EPOS2 emulator node %d: RPDO rejected: %s", self.node_id, e)
        except Exception:
            logger.exception("EPOS2 emulator node %d: RPDO handling failed", self.node_id)

    # ----------------------------------------------------------------------------- CiA 402
    def _apply_controlword(self, cw: int) -> None:
        prev = self._controlword
        self._controlword = cw
        self.controlword_log.append(cw)
        state = self._state
        if state in (cia402.FAULT, cia402.FAULT_REACTION_ACTIVE):
            if cw & cia402.CW_FAULT_RESET and not prev & cia402.CW_FAULT_RESET:
                self._state = cia402.SWITCH_ON_DISABLED
                self._error_register = 0
                self.node.emcy.reset()
            return
        new = state
        if cw & 0x82 == 0x00:  # disable voltage
            if state in (cia402.READY_TO_SWITCH_ON, cia402.SWITCHED_ON,
                         cia402.OPERATION_ENABLED, cia402.QUICK_STOP_ACTIVE):
                new = cia402.SWITCH_ON_DISABLED
        elif cw & 0x86 == 0x02:  # quick stop
            if state == cia402.OPERATION_ENABLED:
                new = cia402.QUICK_STOP_ACTIVE
            elif state in (cia402.READY_TO_SWITCH_ON, cia402.SWITCHED_ON):
                new = cia402.SWITCH_ON_DISABLED
        elif cw & 0x87 == 0x06:  # shutdown
            if state in (cia402.SWITCH_ON_DISABLED, cia402.SWITCHED_ON,
                         cia402.OPERATION_ENABLED):
                new = cia402.READY_TO_SWITCH_ON
        elif cw & 0x8F == 0x07:  # switch on / disable operation
            if state in (cia402.READY_TO_SWITCH_ON, cia402.OPERATION_ENABLED):
                new = cia402.SWITCHED_ON
        elif cw & 0x8F == 0x0F:  # enable operation
            if state in (cia402.SWITCHED_ON, cia402.QUICK_STOP_ACTIVE):
                new = cia402.OPERATION_ENABLED
            elif state == cia402.READY_TO_SWITCH_ON:
                new = cia402.SWITCHED_ON
        if new != state:
            logger.debug("EPOS2 emulator node %d: %s -> %s (controlword 0x%04X)",
                         self.node_id, state, new, cw)
            self._state = new
            if new == cia402.QUICK_STOP_ACTIVE:
                self._stop_motion(quick=True)
            elif state in (cia402.OPERATION_ENABLED, cia402.QUICK_STOP_ACTIVE) or \
                    new == cia402.OPERATION_ENABLED:
                self._stop_motion()  # power stage off, or hold position on enabling
            self._setpoint_ack = False
            self._halted = False
        if self._state == cia402.OPERATION_ENABLED and self._mode == cia402.MODE_PROFILE_POSITION:
            self._profile_position(cw, prev)

    def _profile_position(self, cw: int, prev: int) -> None:
        if cw & cia402.CW_NEW_SETPOINT and not prev & cia402.CW_NEW_SETPOINT:
            target = self._stored(cia402.TARGET_POSITION)
            if cw & cia402.CW_RELATIVE:
                target += self._target_qc
            self._target_qc = max(_INT32_MIN, min(_INT32_MAX, target))
            self._profile_rpm = self._stored(cia402.PROFILE_VELOCITY)
            self._apply_profile_acceleration()
            self._setpoint_ack = True
            if not cw & cia402.CW_HALT:
                self._move_to_target()
        if not cw & cia402.CW_NEW_SETPOINT:
            self._setpoint_ack = False
        if cw & cia402.CW_HALT and not self._halted:
            self._halted = True
            self._stop_motion()
        elif not cw & cia402.CW_HALT and self._halted:
            self._halted = False
            self._move_to_target()
        self._update_target_reached()

    def _move_to_target(self) -> None:
        self.servo.command(self.units.to_rad(self._target_qc),
                           self.units.to_rad_s(self._profile_rpm))

    def _apply_profile_acceleration(self, quick: bool = False) -> None:
        setter = getattr(self.servo, "set_acceleration", None)
        if not callable(setter):
            return
        acc = self.units.to_rad_s(self._stored(cia402.PROFILE_ACCELERATION))
        dec_index = cia402.QUICK_STOP_DECELERATION if quick else cia402.PROFILE_DECELERATION
        setter(acc, self.units.to_rad_s(self._stored(dec_index)))

    def _stop_motion(self, quick: bool = False) -> None:
        """Brake to rest on the current deceleration ramp and hold there."""
        if quick:
            self._apply_profile_acceleration(quick=True)
        x, v = self.servo.state()
        dec = getattr(self.servo, "deceleration", None)
        stop = x
        if dec and v:
            stop = x + math.copysign(v * v / (2.0 * float(dec)), v)
        self._target_qc = self.units.to_quadcounts(stop)
        self.servo.command(stop, max(abs(v), 1e-6))
        self._update_target_reached()

    def _statusword(self) -> int:
        sw = _STATUS_BASE[self._state]
        if self._state == cia402.OPERATION_ENABLED and self._mode == cia402.MODE_PROFILE_POSITION:
            if self._setpoint_ack:
                sw |= cia402.SW_SETPOINT_ACK
            if self._target_reached:
                sw |= cia402.SW_TARGET_REACHED
        elif self._state == cia402.QUICK_STOP_ACTIVE and self._target_reached:
            sw |= cia402.SW_TARGET_REACHED
        return sw

    def _position_qc(self) -> int:
        x, _ = self.servo.state()
        return max(_INT32_MIN, min(_INT32_MAX, self.units.to_quadcounts(x)))

    def _velocity_rpm(self) -> int:
        _, v = self.servo.state()
        return max(_INT32_MIN, min(_INT32_MAX, int(round(self.units.to_rpm(v)))))

    def _update_target_reached(self) -> None:
        x, v = self.servo.state()
        still = abs(v) <= self.config.velocity_window
        if self._halted or self._state == cia402.QUICK_STOP_ACTIVE:
            self._target_reached = still
        else:
            near = abs(self.units.to_quadcounts(x) - self._target_qc) <= self.config.position_window
            self._target_reached = near and still

    # ------------------------------------------------------------------------- heartbeat consumer
    def _set_consumer(self, value: int) -> None:
        if self._consumer_cob_id is not None:
            try:
                self.network.unsubscribe(self._consumer_cob_id, self._on_master_heartbeat)
            except (KeyError, ValueError):
                pass
        producer, time_ms = (value >> 16) & 0x7F, value & 0xFFFF
        self._consumer_last = None
        if producer and time_ms:
            self._consumer_cob_id = 0x700 + producer
            self._consumer_timeout = time_ms / 1000.0
            self.network.subscribe(self._consumer_cob_id, self._on_master_heartbeat)
        else:
            self._consumer_cob_id = None
            self._consumer_timeout = 0.0

    def _on_master_heartbeat(self, can_id: int, data: bytearray, timestamp: float) -> None:
        with self._lock:
            self._consumer_last = self._clock()

    def _check_consumer(self) -> None:
        if self._consumer_last is None or self._consumer_timeout <= 0.0:
            return
        if self._clock() - self._consumer_last > self._consumer_timeout:
            self._consumer_last = None  # re-armed by the next heartbeat
            logger.warning("EPOS2 emulator node %d: master heartbeat lost", self.node_id)
            self._enter_fault(cia402.EMCY_LIFE_GUARD, None)

    # ----------------------------------------------------------------------------- time
    def beat(self, now: float) -> None:
        """Send the heartbeat if it is due by ``now`` (stamped with the time it was due)."""
        self.network.send_due(now)

    def motor_current(self) -> float:
        """The motor current (A) now: the servo's own, or the no-load current; 0 with the
        power stage off."""
        if self._state not in _POWERED:
            return 0.0
        current = getattr(self.servo, "current", None)
        if callable(current):
            return float(current())
        return self.config.no_load_current

    def tick(self, now: float) -> None:
        """Advance the node to ``now`` (seconds): its heartbeat if due, the servo, the TPDOs
        that are due; frames sent from now on are stamped ``now``."""
        self.beat(now)
        self.network.time = now
        with self._lock:
            dt = 0.0 if self._last_tick is None else max(0.0, now - self._last_tick)
            self._last_tick = now
            if dt > 0.0:
                self.servo.step(dt)
                gain = 1.0 - math.exp(-dt / self.config.current_average_s)
                self._current_average += gain * (self.motor_current() - self._current_average)
            self._update_target_reached()
            self._check_consumer()
            if not self._operational():
                return
            for n, period in self._tpdo_period.items():
                due = self._tpdo_due.get(n)
                if due is None or now >= due:
                    self._transmit_tpdo(n)
                    nxt = now + period if due is None else due + period
                    self._tpdo_due[n] = nxt if nxt > now else now + period
            self._publish_status()

    def _transmit_tpdo(self, n: int) -> None:
        pdo_map = self.node.tpdo.map[n]
        for var in pdo_map.map:
            if var.length:
                var.set_data(self.node.get_data(var.index, var.subindex))
        pdo_map.transmit()
        if any(var.index == cia402.STATUSWORD for var in pdo_map.map):
            self._last_status_sent = self._statusword()

    def _publish_status(self) -> None:
        """Send each TPDO with the statusword when it changed (asynchronous, on change)."""
        with self._lock:
            if not self._operational() or self._statusword() == self._last_status_sent:
                return
            for n, pdo_map in self.node.tpdo.map.items():
                if pdo_map.enabled and any(v.index == cia402.STATUSWORD for v in pdo_map.map):
                    self._transmit_tpdo(n)

    # ----------------------------------------------------------------------------- faults
    def _enter_fault(self, code: int, register: int | None) -> None:
        reg = cia402.error_register_for(code) if register is None else register
        with self._lock:
            self._state = cia402.FAULT
            self._setpoint_ack = False
            self._error_register = reg
            self._stop_motion()
            self.node.emcy.send(code, reg)
        self._publish_status()

    def inject_emcy(self, code: int, register: int | None = None) -> None:
        """Enter the fault state and send EMCY ``code`` (error register from the code if None)."""
        if not 0 <= code <= 0xFFFF:
            raise ValueError(f"code: 0x{code:X} is not a 16-bit EMCY error code")
        self._enter_fault(code, register)

    def stop_heartbeat(self) -> None:
        with self._lock:
            self._heartbeat_stopped = True
            self.node.nmt.stop_heartbeat()

    def resume_heartbeat(self) -> None:
        with self._lock:
            self._heartbeat_stopped = False
            self._restart_heartbeat()

    def _restart_heartbeat(self) -> None:
        period_ms = self._stored(cia402.PRODUCER_HEARTBEAT_TIME)
        if period_ms and not self.network.silenced and not self._heartbeat_stopped:
            self.node.nmt.start_heartbeat(period_ms)

    def silence(self) -> None:
        """The node stops answering and sending anything (device gone)."""
        with self._lock:
            self.network.silenced = True
            self.node.nmt.stop_heartbeat()

    def unsilence(self) -> None:
        with self._lock:
            self.network.silenced = False
            self._restart_heartbeat()

    def set_supply_voltage(self, volts: float | None) -> None:
        """Measure ``volts`` at the power stage from now on (None: the configuration's)."""
        if volts is not None and not 0.0 <= volts <= 100.0:
            raise ValueError(f"volts: {volts!r} is out of range; allowed: [0, 100] V")
        self.supply_voltage = self.config.supply_voltage if volts is None else float(volts)

    def slow_replies(self, delay_s: float) -> None:
        """Delay every SDO reply by ``delay_s`` seconds (0 restores normal replies)."""
        if not delay_s >= 0.0:
            raise ValueError(f"delay_s: must be >= 0, got {delay_s!r}")
        self.network.reply_delay = float(delay_s)

    # ----------------------------------------------------------------------------- inspection
    @property
    def state(self) -> str:
        with self._lock:
            return self._state

    @property
    def statusword(self) -> int:
        with self._lock:
            return self._statusword()

    @property
    def target_quadcounts(self) -> int:
        with self._lock:
            return self._target_qc

    @property
    def position_quadcounts(self) -> int:
        with self._lock:
            return self._position_qc()

    def value(self, index: int, subindex: int = 0) -> int:
        """An object's current value as the node holds it (what an SDO upload would give)."""
        with self._lock:
            live = self._on_read(index, subindex, None)
            return live if live is not None else self._stored(index, subindex)


class EmulatedNodes:
    """Several emulated EPOS2 nodes on one channel, ticked together."""

    def __init__(self, emulators: dict[int, Epos2Emulator], tick_period: float,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.nodes = dict(emulators)
        self._tick_period = tick_period
        self._clock = clock
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        #: the time the nodes have been ticked to (on ``clock``): every frame they were due
        #: to send by then has been sent
        self.time = -math.inf

    def __getitem__(self, node_id: int) -> Epos2Emulator:
        return self.nodes[node_id]

    def tick(self, now: float) -> None:
        """Every node to ``now``: their heartbeats first, so that no frame stamped ``now``
        goes out before a heartbeat due earlier (a reader takes them in that order)."""
        for emulator in self.nodes.values():
            emulator.beat(now)
        for emulator in self.nodes.values():
            emulator.tick(now)
        self.time = now

    def start_thread(self) -> None:
        """Tick every node from a thread on the wall clock (real-time mode)."""
        if self._thread is not None:
            return
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="epos2-emulator", daemon=True)
        self._thread.start()

    def stop_thread(self) -> None:
        if self._thread is None:
            return
        self._stop.set()
        self._thread.join(timeout=2.0)
        self._thread = None

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                self.tick(self._clock())
            except Exception:
                logger.exception("EPOS2 emulator tick failed")
            self._stop.wait(self._tick_period)

    def close(self) -> None:
        self.stop_thread()
        for emulator in self.nodes.values():
            try:
                emulator.close()
            except Exception:
                logger.exception("closing EPOS2 emulator node %d failed", emulator.node_id)

    def __enter__(self) -> EmulatedNodes:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def start_emulated_nodes(
    channel: str,
    node_ids: Iterable[int],
    servo_factory: Callable[[int], Servo] | None = None,
    *,
    config: Epos2EmulatorConfig | None = None,
    interface: str = "virtual",
    run_thread: bool = True,
    clock: Callable[[], float] = time.monotonic,
) -> EmulatedNodes:
    """Start one emulated EPOS2 per node id on ``channel`` (python-can ``virtual`` by default).

    ``servo_factory(node_id)`` supplies each node's servo (default: :class:`TrapezoidalServo`).
    With ``run_thread`` the nodes are ticked in real time by a thread; otherwise the caller
    calls :meth:`EmulatedNodes.tick`.
    """
    cfg = config or Epos2EmulatorConfig()
    # the compiled servo step is loaded here, not by the first tick: loading it takes seconds
    # on a busy machine, and a tick holds its node's lock while the node must answer NMT
    servo_step(0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1e-3, 1.0)
    emulators: dict[int, Epos2Emulator] = {}
    try:
        for node_id in node_ids:
            servo = servo_factory(node_id) if servo_factory is not None else None
            emulators[node_id] = Epos2Emulator(channel, node_id, servo, cfg,
                                               interface=interface, clock=clock)
    except Exception:
        for emulator in emulators.values():
            emulator.close()
        raise
    group = EmulatedNodes(emulators, cfg.tick_period, clock)
    if run_thread:
        group.start_thread()
    return group

