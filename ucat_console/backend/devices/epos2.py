# Over 600 lines: one CANopen node's driver: its configuration, CiA 402 state machine, PDO mapping and fault handling share the node's state.
"""Maxon EPOS2 fin drives over CANopen (CiA 402), on python-can through ``canopen``: the
configuration and the driver of one node.

One :class:`Epos2Driver` per node, four of them in a ``fin_drives.FinDrives`` that owns the
one ``canopen.Network`` (and with it the one ``can.Notifier``; everything subscribes through
the network); ``epos2_probe`` brings one node up from the command line. The bus is whatever :func:`canbus.open_bus` opens from the configuration:
``socketcan`` on the robot, ``virtual`` against the emulator; nothing here depends on which.

Start-up per node (:meth:`Epos2Driver.start`): NMT reset communication, wait for the
boot-up message (pre-operational), configure by SDO (heartbeat producer 0x1017, optional
heartbeat consumer 0x1016, profile position mode 0x6060 = 1, profile acceleration,
deceleration and quick-stop deceleration, PDO mapping), NMT start. PDOs as configured:

* RPDO1 controlword; RPDO2 target position (quadcounts) + profile velocity (rpm);
* TPDO1 statusword + mode display, sent on change and every ``feedback_period_ms``;
* TPDO2 position actual + velocity actual every ``feedback_period_ms`` (event timer; the
  inhibit time keeps it to one frame per period where the drive also sends on change, and
  a drive that refuses the event timer is left sending on change), delivered as
  :class:`FinFeedback`;
* TPDO3 averaged motor current (0x2027, INT16 mA) + supply voltage (0x2200 sub 1, UINT16
  0.1 V) every ``electrical_period_ms`` (event timer and inhibit time as TPDO2), kept as
  the drive's electrical input (:meth:`Epos2Driver.read_electrical`), read by SDO instead
  while no fresh TPDO3 has come (a drive that refuses the mapping or the event timer).

A stroke (:meth:`Epos2Driver.command`) writes RPDO2, then controlword 0x003F; when the
statusword shows set-point acknowledge (bit 12) the driver clears bit 4 (0x000F). With
``setpoint_transport = "sdo"`` (or when the node refuses the RPDO mapping) the same
sequence runs by SDO. Heartbeats are supervised (lost after ``heartbeat_timeout_periods``
periods without one, counted from the last one's arrival up to the time the bus's reader has
heard (``check``'s ``heard_until``: see ``fin_drives``), checked five times per period, so
within three periods), EMCY frames are decoded,
and a node entering the fault state puts the other nodes in quick stop. Every fault reaches
``on_event`` as an :class:`Event` with ``source = "epos2.<node>"``; nothing raises out of a
bus callback.

canopen's CiA 402 profile. The statusword decoding and the standard controlword commands
come from ``canopen.profiles.p402.State402`` (through ``cia402``). The driver is not a
``canopen.profiles.p402.BaseNode402``, because that class does not fit the EPOS2 as it is
driven here:

* its state changes block the caller: the ``state`` setter writes a controlword and polls
  the statusword (``check_statusword`` -> ``wait_for_reception``) until fixed class
  timeouts (0.4 s per transition, 0.8 s in all) and raises ``RuntimeError`` on timeout,
  where the four drives are brought up, stopped and supervised from one thread with
  configured timeouts, and every failure must become an ``Event`` (never an exception
  out of a bus callback);
* ``setup_402_state_machine`` uploads the node's PDO configuration by SDO
  (``pdo.read()``) and only warns when the controlword or statusword is not mapped,
  where this driver writes its own mapping (RPDO2 target + profile velocity, TPDO2
  position + velocity on an event timer) and falls back to SDO set-points when a node
  refuses it;
* it has no profile-position set-point handshake (new set-point bit 4, set-point
  acknowledge bit 12, target reached bit 10), which is what every stroke runs on, and its
  ``reset_from_fault`` always runs into its own timeout (a FIXME in canopen 2.4);
* the emulator is a ``canopen.LocalNode``; the profile offers nothing for the drive side,
  so the emulator's state machine is written here anyway, against the same tables.

The module holds one node's driver (start-up, PDO set-up, the set-point handshake,
heartbeat and EMCY supervision, the safe-state commands), over 500 lines because these
share one node's state and lock; the group of four drives is ``fin_drives.py``.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import can
import canopen
from canopen.emcy import EmcyError
from canopen.sdo import SdoAbortedError, SdoCommunicationError

from ucat_console.backend.devices import cia402
from ucat_console.backend.devices.canbus import BITRATES, INTERFACES, arrival_time
from ucat_console.robot.readings import DriveElectrical, FinFeedback
from ucat_console.backend.devices.reporting import EventReporter
from ucat_console.robot.servo import FIN_ACCELERATION
from ucat_console.robot.motor import FinMotor
from ucat_console.robot.units import DriveUnits
from ucat_console.telemetry.events import EventSink
from ucat_console.typedconf import Config, param

logger = logging.getLogger(__name__)

#: the EPOS2 object dictionary (the emulator reads the same file)
EDS_PATH = Path(__file__).with_name("epos2.eds")

_UINT32_MAX = 2**32 - 1
_FEEDBACK_TPDO, _STATUS_TPDO, _ELECTRICAL_TPDO = 2, 1, 3
#: a TPDO3 older than this many electrical periods is not the drive's present input (SDO then)
_ELECTRICAL_STALE_PERIODS = 2.5
_CONTROL_RPDO, _SETPOINT_RPDO = 1, 2

FeedbackSink = Callable[[FinFeedback], None]
#: what a request to a node can fail with: no SDO reply, SDO refused, CAN send failed
_COMM_ERRORS = (SdoCommunicationError, SdoAbortedError, can.CanError)


def _failure_code(error: BaseException) -> str:
    """Event code for a failed request to a node."""
    if isinstance(error, SdoAbortedError):
        return "sdo_abort"
    if isinstance(error, can.CanError):
        return "bus_error"
    return "sdo_timeout"


@dataclass(frozen=True)
class Epos2Config(Config):
    """The four EPOS2 fin drives on one CAN bus."""

    interface: str = param(
        "socketcan", choices=INTERFACES,
        doc="python-can interface: socketcan on the robot, virtual against the emulator",
    )
    channel: str = param("can0", doc="CAN channel: socketcan device or virtual bus name")
    bitrate: int = param(
        1_000_000, choices=BITRATES, unit="bit/s", doc="CAN bit rate (EPOS2 default 1 Mbit/s)"
    )
    node_ids: tuple[int, int, int, int] = param(
        (1, 2, 3, 4),
        doc="CANopen node id (1-127) of fins 0..3: front-right, back-right, back-left, front-left",
    )
    units: DriveUnits = DriveUnits()
    profile_acceleration: float = param(
        FIN_ACCELERATION, lo=0.0, hi=100_000.0, lo_open=True, unit="rad/s2",
        doc="profile acceleration at the fin (0x6083)",
    )
    profile_deceleration: float = param(
        FIN_ACCELERATION, lo=0.0, hi=100_000.0, lo_open=True, unit="rad/s2",
        doc="profile deceleration at the fin (0x6084)",
    )
    quick_stop_deceleration: float = param(
        128.0, lo=0.0, hi=100_000.0, lo_open=True, unit="rad/s2",
        doc="quick-stop deceleration at the fin (0x6085)",
    )
    heartbeat_ms: int = param(
        100, lo=10, hi=10_000, unit="ms", doc="heartbeat period each EPOS2 produces (0x1017)"
    )
    heartbeat_timeout_periods: float = param(
        2.0, lo=1.5, hi=2.5,
        doc="a heartbeat is lost after this many periods without one (checked every fifth "
        "of a period, so loss is reported within three periods); also the EPOS2's consumer "
        "timeout for the console's heartbeat",
    )
    master_heartbeat_id: int = param(
        0, lo=0, hi=127,
        doc="0: off; else the console sends heartbeats as this node id and each EPOS2 "
        "consumes them (0x1016), faulting with EMCY 0x8130 when they stop",
    )
    feedback_period_ms: int = param(
        10, lo=1, hi=1000, unit="ms", doc="TPDO event timer: feedback every this many ms"
    )
    setpoint_transport: str = param(
        "rpdo", choices=("rpdo", "sdo"), doc="how strokes reach the drive (SDO is the fallback)"
    )
    sdo_timeout: float = param(0.3, lo=0.01, hi=5.0, unit="s", doc="wait for an SDO reply")
    boot_timeout: float = param(
        1.0, lo=0.05, hi=30.0, unit="s", doc="wait for boot-up after reset communication"
    )
    state_timeout: float = param(
        0.5, lo=0.01, hi=10.0, unit="s", doc="wait for each CiA 402 state change"
    )
    setpoint_ack_timeout: float = param(
        0.1, lo=0.005, hi=5.0, unit="s", doc="wait for set-point acknowledge (statusword bit 12)"
    )
    motor: FinMotor = FinMotor()  # the drives' motor, gearhead and bridge (battery power; robot.motor)
    electrical_period_ms: int = param(
        20, lo=0, hi=60_000, unit="ms",
        doc="each drive sends its averaged motor current (0x2027) and supply voltage (0x2200 sub 1) "
        "this often in TPDO3 (by SDO where it does not), handed on as a round (0: never)",
    )

    def _check(self) -> None:
        seen: dict[int, int] = {}
        for i, node in enumerate(self.node_ids):
            if isinstance(node, bool) or not isinstance(node, int) or not 1 <= node <= 127:
                raise ValueError(f"node_ids[{i}]: {node!r} is out of range; allowed: [1, 127]")
            if node in seen:
                raise ValueError(
                    f"node_ids[{i}]: node {node} is already used by fin {seen[node]}"
                )
            seen[node] = i
        if self.master_heartbeat_id in seen:
            raise ValueError(
                f"master_heartbeat_id: {self.master_heartbeat_id} is the node id of fin "
                f"{seen[self.master_heartbeat_id]}"
            )

    @property
    def heartbeat_timeout(self) -> float:
        """Seconds without a heartbeat after which a node counts as lost."""
        return self.heartbeat_ms * self.heartbeat_timeout_periods / 1000.0


class Epos2Error(RuntimeError):
    """Start-up or a blocking request failed (not raised from bus callbacks)."""


class Epos2NoAnswer(Epos2Error):
    """The node never answered (no boot-up after reset communication)."""


def check_node_id(node: Any, key: str) -> int:
    if isinstance(node, bool) or not isinstance(node, int) or not 1 <= node <= 127:
        raise ValueError(f"{key}: {node!r} is out of range; allowed: [1, 127]")
    return node


class Epos2Driver:
    """One EPOS2 node: start-up, CiA 402 states, strokes, feedback and supervision."""

    def __init__(
        self,
        network: canopen.Network,
        fin: int,
        node_id: int,
        config: Epos2Config,
        on_feedback: FeedbackSink,
        on_event: EventSink,
        *,
        clock: Callable[[], float] = time.monotonic,
        on_fault: Callable[[Epos2Driver], None] | None = None,
    ) -> None:
        self.fin = fin
        self.node_id = check_node_id(node_id, "node_id")
        self.config = config
        self.units = config.units
        self.source = f"epos2.{node_id}"
        self._on_feedback = on_feedback
        self._report = EventReporter(self.source, on_event, clock)
        self._on_fault = on_fault
        self._clock = clock

        self._lock = threading.RLock()
        self._status_changed = threading.Condition(self._lock)
        self._sdo_lock = threading.Lock()
        self._bootup = threading.Event()
        self._statusword: int | None = None
        self._controlword = 0
        self._started = False
        self._starting = False
        self._use_rpdo = config.setpoint_transport == "rpdo"
        self._last_heartbeat: float | None = None
        self._heartbeat_lost = False
        self._nmt_state: int | None = None
        self._pending_ack_since: float | None = None
        self._rejected = False
        self._last_feedback: FinFeedback | None = None

        od = canopen.import_od(str(EDS_PATH), node_id)
        self.node = canopen.RemoteNode(node_id, od)
        # before canopen's EMCY consumer, which stops the callback chain on a short frame
        network.subscribe(0x80 + node_id, self._check_emcy_frame)
        network.add_node(self.node)
        self.node.sdo.RESPONSE_TIMEOUT = config.sdo_timeout
        self.node.nmt.add_heartbeat_callback(self._on_heartbeat)
        self.node.emcy.add_callback(self._on_emcy)
        self._tp_status = self._tp_mode = self._tp_position = self._tp_velocity = None
        self._tp_current = self._tp_voltage = None
        self._electrical_pdo: DriveElectrical | None = None  # the last TPDO3's reading
        self._rp_control = self._rp_target = self._rp_velocity = None
        self.node.tpdo[_STATUS_TPDO].add_callback(self._on_status_pdo)
        self.node.tpdo[_FEEDBACK_TPDO].add_callback(self._on_feedback_pdo)
        self.node.tpdo[_ELECTRICAL_TPDO].add_callback(self._on_electrical_pdo)

    # ----------------------------------------------------------------------------- events
    def _emit(self, event_code: str, message: str, level: str = "error", **data: Any) -> None:
        self._report.emit(event_code, message, level, **data)

    # ----------------------------------------------------------------------------- start-up
    def start(self) -> None:
        """NMT reset communication, configure in pre-operational, NMT start.

        Raises Epos2NoAnswer when no boot-up arrives, Epos2Error for anything else.
        """
        cfg = self.config
        self._starting = True
        self._started = False
        self._use_rpdo = cfg.setpoint_transport == "rpdo"
        try:
            self._bootup.clear()
            with self._lock:
                self._statusword = None
            self._send_nmt(cia402.NMT_RESET_COMMUNICATION)
            if not self._bootup.wait(cfg.boot_timeout):
                raise Epos2NoAnswer(
                    f"EPOS2 node {self.node_id} did not answer: no boot-up within "
                    f"{cfg.boot_timeout} s of reset communication"
                )
            try:
                with self._sdo_lock:
                    self._configure()
            except (SdoCommunicationError, can.CanError) as e:
                raise Epos2Error(f"EPOS2 node {self.node_id}: no SDO reply during set-up ({e})")
            except SdoAbortedError as e:
                raise Epos2Error(f"EPOS2 node {self.node_id}: set-up refused: {e}")
            with self._lock:
                self._last_heartbeat = self._clock()
                self._heartbeat_lost = False
            self._send_nmt(cia402.NMT_START)
            if self._wait_status(lambda sw: True, cfg.state_timeout) is None:
                raise Epos2Error(
                    f"EPOS2 node {self.node_id}: no statusword TPDO within "
                    f"{cfg.state_timeout} s of NMT start"
                )
            self._started = True
            logger.info("%s started (%s)", self.source, self.state)
        finally:
            self._starting = False

    def _send_nmt(self, command: int) -> None:
        try:
            self.node.nmt.send_command(command)
        except can.CanError as e:
            raise Epos2Error(
                f"EPOS2 node {self.node_id}: NMT command 0x{command:02X} not sent: {e}"
            ) from e

    def _configure(self) -> None:
        cfg, sdo = self.config, self.node.sdo
        device_type = sdo[cia402.DEVICE_TYPE].raw
        if device_type & 0xFFFF != cia402.PROFILE_402:
            raise Epos2Error(
                f"EPOS2 node {self.node_id}: device type 0x{device_type:08X} is not a CiA 402 drive"
            )
        modes = sdo[cia402.SUPPORTED_DRIVE_MODES].raw
        if not modes & (1 << cia402.MODE_SUPPORT_BIT[cia402.MODE_PROFILE_POSITION]):
            raise Epos2Error(
                f"EPOS2 node {self.node_id}: supported drive modes 0x{modes:08X} "
                "lack profile position"
            )
        sdo[cia402.PRODUCER_HEARTBEAT_TIME].raw = cfg.heartbeat_ms
        if cfg.master_heartbeat_id:
            consumer_ms = int(round(cfg.heartbeat_timeout * 1000.0))
            consumer = (cfg.master_heartbeat_id << 16) | consumer_ms
            sdo[cia402.CONSUMER_HEARTBEAT_TIME][1].raw = consumer
        sdo[cia402.MODES_OF_OPERATION].raw = cia402.MODE_PROFILE_POSITION
        sdo[cia402.PROFILE_ACCELERATION].raw = self._rpm_value(cfg.profile_acceleration)
        sdo[cia402.PROFILE_DECELERATION].raw = self._rpm_value(cfg.profile_deceleration)
        sdo[cia402.QUICK_STOP_DECELERATION].raw = self._rpm_value(cfg.quick_stop_deceleration)
        self._configure_tpdos()
        if self._use_rpdo:
            try:
                self._configure_rpdos()
            except SdoAbortedError as e:
                self._use_rpdo = False
                self._emit("pdo_fallback", f"RPDO mapping refused ({e}); strokes go by SDO",
                           level="warning", abort_code=e.code)

    def _rpm_value(self, fin_value: float) -> int:
        """A fin rate (rad/s) or acceleration (rad/s2) as the EPOS2's UINT32 rpm (rpm/s)."""
        return max(1, min(_UINT32_MAX, int(round(abs(self.units.to_rpm(fin_value))))))

    def _configure_tpdos(self) -> None:
        period = self.config.feedback_period_ms
        tpdo = self.node.tpdo
        for n in (1, 2, 3, 4):
            pdo_map = tpdo[n]
            pdo_map.clear()
            pdo_map.cob_id = pdo_map.predefined_cob_id
            pdo_map.enabled = n in (_STATUS_TPDO, _FEEDBACK_TPDO)
            if pdo_map.enabled:
                pdo_map.trans_type = 255  # asynchronous: on change and on the event timer
                pdo_map.event_timer = period
        # at most one feedback frame per period even where the device sends on change
        tpdo[_FEEDBACK_TPDO].inhibit_time = period * 10  # 100 us units
        self._tp_status = tpdo[_STATUS_TPDO].add_variable(cia402.STATUSWORD)
        self._tp_mode = tpdo[_STATUS_TPDO].add_variable(cia402.MODES_OF_OPERATION_DISPLAY)
        self._tp_position = tpdo[_FEEDBACK_TPDO].add_variable(cia402.POSITION_ACTUAL)
        self._tp_velocity = tpdo[_FEEDBACK_TPDO].add_variable(cia402.VELOCITY_ACTUAL)
        electrical = self.config.electrical_period_ms
        self._tp_current = self._tp_voltage = None
        with self._lock:
            self._electrical_pdo = None
        for n in (1, 2, 3, 4):
            if n == _ELECTRICAL_TPDO and electrical > 0:
                try:
                    self._configure_electrical_tpdo(tpdo[n], electrical)
                except SdoAbortedError as e:  # read by SDO instead
                    tpdo[n].clear()
                    tpdo[n].enabled = False
                    self._tp_current = self._tp_voltage = None
                    self._emit("pdo_fallback", f"TPDO3 (current, supply voltage) refused ({e}); "
                               "read by SDO", level="warning", abort_code=e.code)
                else:
                    continue
            self._save_tpdo(tpdo[n], n)

    def _configure_electrical_tpdo(self, pdo_map: Any, period_ms: int) -> None:
        """TPDO3: the averaged motor current and the supply voltage every ``period_ms``."""
        pdo_map.enabled = True
        pdo_map.trans_type = 255
        pdo_map.event_timer = period_ms
        pdo_map.inhibit_time = min(period_ms * 10, 0xFFFF)  # 100 us units
        self._tp_current = pdo_map.add_variable(cia402.CURRENT_ACTUAL_AVERAGED)
        self._tp_voltage = pdo_map.add_variable(cia402.POWER_SUPPLY, cia402.POWER_SUPPLY_VOLTAGE_SUB)
        self._save_tpdo(pdo_map, _ELECTRICAL_TPDO)

    def _save_tpdo(self, pdo_map: Any, n: int) -> None:
        try:
            pdo_map.save()
        except SdoAbortedError as e:
            if pdo_map.event_timer is None:
                raise
            # drives without an event timer (0x18xx sub 5) send on change only
            pdo_map.event_timer = None
            self._emit("no_event_timer",
                       f"TPDO{n} event timer refused ({e}); sent on change only",
                       level="warning", abort_code=e.code)
            pdo_map.save()

    def _configure_rpdos(self) -> None:
        rpdo = self.node.rpdo
        for n in (1, 2, 3, 4):
            pdo_map = rpdo[n]
            pdo_map.clear()
            pdo_map.cob_id = pdo_map.predefined_cob_id
            pdo_map.enabled = n in (_CONTROL_RPDO, _SETPOINT_RPDO)
            if pdo_map.enabled:
                pdo_map.trans_type = 255
        self._rp_control = rpdo[_CONTROL_RPDO].add_variable(cia402.CONTROLWORD)
        self._rp_target = rpdo[_SETPOINT_RPDO].add_variable(cia402.TARGET_POSITION)
        self._rp_velocity = rpdo[_SETPOINT_RPDO].add_variable(cia402.PROFILE_VELOCITY)
        for n in (1, 2, 3, 4):
            rpdo[n].save()

    # ----------------------------------------------------------------------------- state
    @property
    def started(self) -> bool:
        return self._started

    @property
    def statusword(self) -> int | None:
        with self._lock:
            return self._statusword

    @property
    def state(self) -> str:
        sw = self.statusword
        return cia402.UNKNOWN if sw is None else cia402.state_of(sw)

    @property
    def uses_rpdo(self) -> bool:
        return self._use_rpdo

    @property
    def heartbeat_lost(self) -> bool:
        with self._lock:
            return self._heartbeat_lost

    @property
    def last_heartbeat_t(self) -> float | None:
        with self._lock:
            return self._last_heartbeat

    @property
    def last_feedback(self) -> FinFeedback | None:
        with self._lock:
            return self._last_feedback

    def _wait_status(self, predicate: Callable[[int], bool], timeout: float) -> int | None:
        """Wait for a TPDO statusword satisfying ``predicate``; SDO read as a last try."""
        deadline = time.monotonic() + timeout
        with self._status_changed:
            while True:
                sw = self._statusword
                if sw is not None and predicate(sw):
                    return sw
                remaining = deadline - time.monotonic()
                if remaining <= 0.0:
                    break
                self._status_changed.wait(remaining)
        try:
            sw = self._sdo_read(cia402.STATUSWORD)
        except _COMM_ERRORS:
            return None
        self._set_statusword(sw)
        return sw if predicate(sw) else None

    def _sdo_read(self, index: int) -> int:
        with self._sdo_lock:
            return self.node.sdo[index].raw

    def _sdo_write(self, index: int, value: int) -> None:
        with self._sdo_lock:
            self.node.sdo[index].raw = value

    def _send_controlword(self, cw: int) -> None:
        """Controlword by RPDO1 (or SDO); SDO errors propagate to the (non-callback) caller."""
        if self._use_rpdo and self._rp_control is not None:
            with self._lock:
                self._rp_control.raw = cw
                self._rp_control.pdo_parent.transmit()
                self._controlword = cw
        else:
            self._sdo_write(cia402.CONTROLWORD, cw)
            with self._lock:
                self._controlword = cw

    def _current_statusword(self) -> int | None:
        sw = self.statusword
        if sw is not None:
            return sw
        try:
            sw = self._sdo_read(cia402.STATUSWORD)
        except _COMM_ERRORS as e:
            self._emit(_failure_code(e), f"statusword not readable: {e}", level="warning")
            return None
        self._set_statusword(sw)
        return sw

    def _goto(self, cw: int, want: str) -> int | None:
        try:
            self._send_controlword(cw)
        except _COMM_ERRORS as e:
            self._emit(_failure_code(e), f"controlword 0x{cw:04X} not written: {e}",
                       controlword=cw)
            return None
        sw = self._wait_status(lambda s: cia402.is_state(s, want), self.config.state_timeout)
        if sw is None:
            last = self.statusword
            self._emit("state_timeout",
                       f"no {want} within {self.config.state_timeout} s of controlword 0x{cw:04X}",
                       controlword=cw, wanted=want,
                       statusword=last, state=self.state)
        return sw

    def enable(self) -> bool:
        """Walk the CiA 402 state machine to operation enabled (False + event on failure)."""
        self._require_started()
        steps = {
            cia402.SWITCH_ON_DISABLED: (cia402.SHUTDOWN, cia402.READY_TO_SWITCH_ON),
            cia402.READY_TO_SWITCH_ON: (cia402.SWITCH_ON, cia402.SWITCHED_ON),
            cia402.SWITCHED_ON: (cia402.ENABLE_OPERATION, cia402.OPERATION_ENABLED),
            cia402.QUICK_STOP_ACTIVE: (cia402.DISABLE_VOLTAGE, cia402.SWITCH_ON_DISABLED),
        }
        for _ in range(6):
            sw = self._current_statusword()
            if sw is None:
                return False
            state = cia402.state_of(sw)
            if state == cia402.OPERATION_ENABLED:
                with self._lock:
                    self._rejected = False
                return True
            if state in (cia402.FAULT, cia402.FAULT_REACTION_ACTIVE):
                self._emit("enable_refused", "node is in fault; reset the fault first",
                           statusword=sw)
                return False
            if state not in steps:
                if self._wait_status(lambda s: cia402.state_of(s) != state,
                                     self.config.state_timeout) is None:
                    self._emit("state_timeout", f"node stays in {state}", statusword=sw)
                    return False
                continue
            cw, want = steps[state]
            if self._goto(cw, want) is None:
                return False
        return self.state == cia402.OPERATION_ENABLED

    def disable(self) -> bool:
        """Power stage off: shutdown (0x0006), or disable voltage from quick stop."""
        self._require_started()
        sw = self._current_statusword()
        if sw is None:
            return False
        state = cia402.state_of(sw)
        with self._lock:
            self._pending_ack_since = None
        if state == cia402.QUICK_STOP_ACTIVE:
            return self._goto(cia402.DISABLE_VOLTAGE, cia402.SWITCH_ON_DISABLED) is not None
        if state in (cia402.OPERATION_ENABLED, cia402.SWITCHED_ON):
            return self._goto(cia402.SHUTDOWN, cia402.READY_TO_SWITCH_ON) is not None
        return True

    def quick_stop(self, wait: bool = True) -> bool:
        """Controlword 0x000B from operation enabled (brakes on the quick-stop ramp)."""
        self._require_started()
        with self._lock:
            self._pending_ack_since = None
        if self.state in (cia402.QUICK_STOP_ACTIVE, cia402.SWITCH_ON_DISABLED,
                          cia402.READY_TO_SWITCH_ON, cia402.SWITCHED_ON, cia402.FAULT,
                          cia402.FAULT_REACTION_ACTIVE):
            return True  # not moving under power
        if not wait:
            try:
                self._send_controlword(cia402.QUICK_STOP)
            except _COMM_ERRORS as e:
                self._emit(_failure_code(e), f"quick stop not written: {e}")
                return False
            return True
        return self._goto(cia402.QUICK_STOP, cia402.QUICK_STOP_ACTIVE) is not None

    def fault_reset(self, enable: bool = True) -> bool:
        """Rising edge of controlword bit 7, then back to operation enabled (``enable``) or
        left in switch on disabled, its power stage off."""
        self._require_started()
        sw = self._current_statusword()
        if sw is None:
            return False
        if cia402.state_of(sw) in (cia402.FAULT, cia402.FAULT_REACTION_ACTIVE):
            try:
                self._send_controlword(cia402.DISABLE_VOLTAGE)  # bit 7 low before the edge
            except _COMM_ERRORS as e:
                self._emit(_failure_code(e), f"fault reset not written: {e}")
                return False
            if self._goto(cia402.FAULT_RESET, cia402.SWITCH_ON_DISABLED) is None:
                return False
        return self.enable() if enable else True

    def _require_started(self) -> None:
        if not self._started:
            raise Epos2Error(f"EPOS2 node {self.node_id} is not started")

    # ----------------------------------------------------------------------------- strokes
    def command(self, target_rad: float, profile_velocity_rad_s: float) -> bool:
        """One stroke: absolute target angle (rad) at a profile rate (rad/s), both at the fin.

        Returns False (with an event) when the node is not in operation enabled or the
        set-point could not be sent.
        """
        if not (math.isfinite(target_rad) and math.isfinite(profile_velocity_rad_s)):
            raise ValueError(
                f"stroke: target {target_rad!r} rad and rate {profile_velocity_rad_s!r} rad/s "
                "must be finite"
            )
        if profile_velocity_rad_s == 0.0:
            raise ValueError("stroke: profile velocity must not be 0")
        qc = self.units.to_quadcounts(target_rad)
        if not -(2**31) <= qc < 2**31:
            raise ValueError(
                f"stroke: target {target_rad!r} rad is outside the INT32 position range"
            )
        rpm = self._rpm_value(profile_velocity_rad_s)
        state = self.state
        if not self._started or state != cia402.OPERATION_ENABLED:
            with self._lock:
                first = not self._rejected
                self._rejected = True
            if first:
                self._emit("command_rejected", f"stroke refused in state {state}",
                           level="warning", state=state)
            return False
        with self._lock:
            self._rejected = False
        if self._use_rpdo:
            return self._command_rpdo(qc, rpm)
        return self._command_sdo(qc, rpm)

    def _command_rpdo(self, qc: int, rpm: int) -> bool:
        try:
            with self._lock:
                if self._controlword & cia402.CW_NEW_SETPOINT:
                    self._send_controlword(cia402.ENABLE_OPERATION)  # bit 4 low for an edge
                self._rp_target.raw = qc
                self._rp_velocity.raw = rpm
                self._rp_target.pdo_parent.transmit()
                self._pending_ack_since = self._clock()
                self._send_controlword(cia402.NEW_SETPOINT_IMMEDIATE)
        except can.CanError as e:
            with self._lock:
                self._pending_ack_since = None
            self._emit("bus_error", f"stroke not sent: {e}", target_qc=qc, rpm=rpm)
            return False
        return True

    def _command_sdo(self, qc: int, rpm: int) -> bool:
        try:
            self._sdo_write(cia402.TARGET_POSITION, qc)
            self._sdo_write(cia402.PROFILE_VELOCITY, rpm)
            self._send_controlword(cia402.NEW_SETPOINT_IMMEDIATE)
            deadline = time.monotonic() + self.config.setpoint_ack_timeout
            acked = False
            while True:
                sw = self._sdo_read(cia402.STATUSWORD)
                self._set_statusword(sw)
                if sw & cia402.SW_SETPOINT_ACK:
                    acked = True
                    break
                if time.monotonic() > deadline:
                    break
            self._send_controlword(cia402.ENABLE_OPERATION)
        except (SdoCommunicationError, can.CanError) as e:
            self._emit(_failure_code(e), f"stroke not sent: {e}", target_qc=qc, rpm=rpm)
            return False
        except SdoAbortedError as e:
            self._emit("sdo_abort", f"stroke refused: {e}", abort_code=e.code,
                       target_qc=qc, rpm=rpm)
            return False
        if not acked:
            self._emit("setpoint_timeout",
                       f"no set-point acknowledge within {self.config.setpoint_ack_timeout} s",
                       level="warning", target_qc=qc, rpm=rpm)
        return acked

    def read_current(self) -> float | None:
        """Motor current (A) by SDO from 0x6078; None with an event when there is no answer."""
        try:
            milliamps = self._sdo_read(cia402.CURRENT_ACTUAL)
        except (SdoCommunicationError, can.CanError) as e:
            self._emit(_failure_code(e), f"current not read: {e}", level="warning")
            return None
        except SdoAbortedError as e:
            self._emit("sdo_abort", f"current not read: {e}", level="warning",
                       abort_code=e.code)
            return None
        return milliamps * cia402.CURRENT_UNIT

    def read_electrical(self) -> DriveElectrical | None:
        """The drive's electrical input: the motor current averaged by the drive (0x2027,
        mA) and the supply voltage (0x2200 sub 1, 0.1 V), as its last TPDO3 brought them
        (stamped on arrival) when that came within the last 2.5 electrical periods, else
        by SDO; None with a (throttled) event when the node does not answer or refuses."""
        with self._lock:
            last = self._electrical_pdo
        stale = _ELECTRICAL_STALE_PERIODS * self.config.electrical_period_ms / 1000.0
        if last is not None and self._clock() - last.t <= stale:
            return last
        try:
            with self._sdo_lock:
                milliamps = self.node.sdo[cia402.CURRENT_ACTUAL_AVERAGED].raw
                decivolts = self.node.sdo[cia402.POWER_SUPPLY][cia402.POWER_SUPPLY_VOLTAGE_SUB].raw
        except (SdoCommunicationError, can.CanError) as e:
            self._report.throttled(_failure_code(e), f"current and voltage not read: {e}", "warning")
            return None
        except SdoAbortedError as e:
            self._report.throttled("sdo_abort", f"current and voltage not read: {e}", "warning",
                                   abort_code=e.code)
            return None
        return DriveElectrical(t=self._clock(), fin=self.fin,
                               current_a=milliamps * cia402.CURRENT_UNIT,
                               voltage_v=decivolts * cia402.POWER_SUPPLY_VOLTAGE_UNIT)

    # ----------------------------------------------------------------------------- callbacks
    def _set_statusword(self, sw: int) -> None:
        """Record a statusword; report entering and leaving the fault state."""
        with self._lock:
            prev = self._statusword
            self._statusword = sw
            self._status_changed.notify_all()
            clear_bit4 = (self._pending_ack_since is not None and sw & cia402.SW_SETPOINT_ACK
                          and self._use_rpdo and self._controlword & cia402.CW_NEW_SETPOINT)
            if self._pending_ack_since is not None and sw & cia402.SW_SETPOINT_ACK:
                self._pending_ack_since = None
            if clear_bit4:
                try:
                    self._send_controlword(cia402.ENABLE_OPERATION)
                except can.CanError as e:
                    self._emit("bus_error", f"set-point handshake not finished: {e}")
        was_fault = prev is not None and cia402.is_state(prev, cia402.FAULT)
        is_fault = cia402.is_state(sw, cia402.FAULT)
        if is_fault and not was_fault:
            self._emit("fault", f"node in fault state (statusword 0x{sw:04X})", statusword=sw)
            if self._on_fault is not None and not self._starting:
                try:
                    self._on_fault(self)
                except Exception:
                    logger.exception("%s: fault reaction failed", self.source)
        elif was_fault and not is_fault:
            self._emit("fault_cleared", f"fault cleared (statusword 0x{sw:04X})", level="info",
                       statusword=sw)

    def _on_status_pdo(self, pdo_map: Any) -> None:
        try:
            sw = self._tp_status.raw
        except Exception as e:
            self._report.throttled("invalid_data", f"statusword TPDO unreadable: {e}",
                                   "warning", frame=bytes(pdo_map.data).hex())
            return
        try:
            self._set_statusword(sw)
        except Exception:
            logger.exception("%s: statusword handling failed", self.source)

    def _on_electrical_pdo(self, pdo_map: Any) -> None:
        if self._tp_current is None or self._tp_voltage is None:
            return
        try:
            milliamps = self._tp_current.raw
            decivolts = self._tp_voltage.raw
        except Exception as e:
            self._report.throttled("invalid_data", f"electrical TPDO unreadable: {e}",
                                   "warning", frame=bytes(pdo_map.data).hex())
            return
        reading = DriveElectrical(t=self._clock(), fin=self.fin, current_a=milliamps * cia402.CURRENT_UNIT,
                                  voltage_v=decivolts * cia402.POWER_SUPPLY_VOLTAGE_UNIT)
        with self._lock:
            self._electrical_pdo = reading

    def _on_feedback_pdo(self, pdo_map: Any) -> None:
        try:
            qc = self._tp_position.raw
            rpm = self._tp_velocity.raw
        except Exception as e:
            self._report.throttled("invalid_data", f"feedback TPDO unreadable: {e}",
                                   "warning", frame=bytes(pdo_map.data).hex())
            return
        feedback = FinFeedback(
            t=self._clock(), fin=self.fin, position_rad=self.units.to_rad(qc),
            velocity_rad_s=self.units.to_rad_s(rpm), state=self.state,
        )
        with self._lock:
            self._last_feedback = feedback
        try:
            self._on_feedback(feedback)
        except Exception:
            logger.exception("%s: feedback sink failed", self.source)

    def _on_heartbeat(self, nmt_state: int) -> None:
        try:
            with self._lock:  # when the frame arrived (it may have waited to be read)
                self._last_heartbeat = arrival_time(self.node.nmt.timestamp, self._clock())
                lost, self._heartbeat_lost = self._heartbeat_lost, False
                prev, self._nmt_state = self._nmt_state, nmt_state
            if nmt_state == cia402.NMT_BOOTUP:
                self._bootup.set()
                if self._started and not self._starting:
                    self._started = False
                    self._emit("bootup", "node restarted by itself (boot-up); start it again")
                return
            if lost:
                self._emit("heartbeat_restored", "heartbeat back", level="info",
                           nmt_state=cia402.NMT_STATE_NAMES.get(nmt_state, nmt_state))
            if self._started and nmt_state != prev and nmt_state != cia402.NMT_OPERATIONAL:
                name = cia402.NMT_STATE_NAMES.get(nmt_state, str(nmt_state))
                self._emit("nmt_state", f"node left operational: {name}", nmt_state=nmt_state)
        except Exception:
            logger.exception("%s: heartbeat handling failed", self.source)

    def _check_emcy_frame(self, can_id: int, data: bytearray, timestamp: float) -> None:
        if len(data) != 8:
            self._report.throttled("invalid_data",
                                   f"EMCY frame of {len(data)} bytes (8 expected)",
                                   "warning", frame=bytes(data).hex())

    def _on_emcy(self, emcy: EmcyError) -> None:
        try:
            if emcy.code == 0:
                self._emit("emcy_reset", "EMCY error reset", level="info",
                           register=emcy.register)
                return
            name = cia402.emcy_name(emcy.code)
            self._emit("emcy", f"EMCY 0x{emcy.code:04X} {name}", code=emcy.code,
                       register=emcy.register, name=name, vendor=bytes(emcy.data).hex())
        except Exception:
            logger.exception("%s: EMCY handling failed", self.source)

    # ----------------------------------------------------------------------------- supervision
    def check(self, now: float, heard_until: float = math.inf) -> None:
        """Heartbeat and set-point supervision at time ``now`` (the driver's clock), with
        every frame that arrived up to ``heard_until`` read (default: all of them): a
        heartbeat or acknowledge is missing only for as long as it could have been heard."""
        lost_for: float | None = None
        late: float | None = None
        until = min(now, heard_until)
        with self._lock:
            if self._started and self._last_heartbeat is not None and not self._heartbeat_lost:
                silent = until - self._last_heartbeat
                if silent > self.config.heartbeat_timeout:
                    self._heartbeat_lost = True
                    lost_for = silent
            last = self._last_heartbeat
            if self._pending_ack_since is not None:
                waited = until - self._pending_ack_since
                if waited > self.config.setpoint_ack_timeout:
                    self._pending_ack_since = None
                    late = waited
        if lost_for is not None:
            self._emit("heartbeat_lost",
                       f"no heartbeat for {lost_for * 1000:.0f} ms "
                       f"(period {self.config.heartbeat_ms} ms)",
                       last_heartbeat_t=last, silent_for_s=lost_for,
                       period_s=self.config.heartbeat_ms / 1000.0)
        if late is not None:
            self._emit("setpoint_timeout",
                       f"no set-point acknowledge within {self.config.setpoint_ack_timeout} s",
                       level="warning", waited_s=late)
