"""The four EPOS2 fin drives on one CAN bus: :class:`FinDrives`.

One ``canopen.Network`` (and with it the one ``can.Notifier``; every driver subscribes
through it), one :class:`~ucat_console.backend.devices.epos2.Epos2Driver` per node, and a
supervision thread that checks heartbeats and runs the safe-state reaction: when a node
faults, every other node in operation enabled gets a quick stop.

Heartbeats are judged on what the bus's reader has heard (``canbus.HeardBus``): a node's
heartbeat is missing from its last one's arrival up to ``heard_until``, not up to the
present. A busy machine that holds the reader (or the supervision thread) back leaves
frames unread in the queue; a heartbeat among them is not missing, it is not heard yet.

Electrical input: with ``on_electrical`` given and ``electrical_period_ms`` > 0, a thread
takes every started node's averaged motor current and supply voltage once per period
(:meth:`Epos2Driver.read_electrical`: its last TPDO3, by SDO where none came lately) and
hands each round to ``on_electrical``: a list of :class:`DriveElectrical` by fin, None for
a node that did not answer. It runs apart from the supervision thread, so a slow SDO reply
never delays a heartbeat check.
"""

from __future__ import annotations

import logging
import math
import queue
import threading
import time
from collections.abc import Callable, Mapping
from typing import Any

import canopen

from ucat_console.backend.devices import cia402
from ucat_console.backend.devices.canbus import HeardBus, open_bus
from ucat_console.robot.readings import DriveElectrical
from ucat_console.telemetry.events import EventSink

from ucat_console.backend.devices.epos2 import (
    Epos2Config,
    Epos2Driver,
    Epos2Error,
    Epos2NoAnswer,
    FeedbackSink,
    check_node_id,
)

logger = logging.getLogger(__name__)

#: one round of electrical readings, by fin (None: the node did not answer)
ElectricalSink = Callable[[dict[int, DriveElectrical | None]], None]


class FinDrives:
    """The fin drives on one CAN bus: one network, one notifier, one driver per node.

    ``fins`` maps fin index to node id (default: ``config.node_ids`` for fins 0..3). A
    supervision thread checks heartbeats and runs the safe-state reaction: when a node
    faults, every other node in operation enabled gets a quick stop.
    """

    NOTIFIER_CYCLE = 0.1  # s; bounds how long closing the network takes

    def __init__(
        self,
        config: Epos2Config,
        on_feedback: FeedbackSink,
        on_event: EventSink,
        *,
        fins: Mapping[int, int] | None = None,
        clock: Callable[[], float] = time.monotonic,
        supervise: bool = True,
        bus_time: Callable[[], float] | None = None,
        on_electrical: ElectricalSink | None = None,
    ) -> None:
        self.config = config
        if fins is None:
            fins = dict(enumerate(config.node_ids))
        seen: set[int] = set()
        for fin, node in fins.items():
            check_node_id(node, f"fins[{fin}]")
            if node in seen:
                raise ValueError(f"fins[{fin}]: node {node} is used twice")
            seen.add(node)
        self.fins: dict[int, int] = dict(fins)
        self._on_feedback = on_feedback
        self._on_event = on_event
        self._clock = clock
        self._bus_time = bus_time
        self._supervise = supervise
        self._on_electrical = on_electrical
        self._electrical_thread: threading.Thread | None = None
        self._bus: HeardBus | None = None
        self.network: canopen.Network | None = None
        self.drivers: dict[int, Epos2Driver] = {}
        self._master_heartbeat: Any = None
        self._actions: queue.Queue[Callable[[], None] | None] = queue.Queue()
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()

    # ----------------------------------------------------------------------------- lifecycle
    def connect(self) -> None:
        """Open the bus and start every node; raise Epos2NoAnswer / Epos2Error on failure."""
        cfg = self.config
        bus = self._bus = HeardBus(open_bus(cfg.interface, cfg.channel, cfg.bitrate), self._clock, self._bus_time)
        network = canopen.Network(bus)
        network.NOTIFIER_CYCLE = self.NOTIFIER_CYCLE
        network.connect()
        self.network = network
        for fin, node in self.fins.items():
            self.drivers[fin] = Epos2Driver(
                network, fin, node, cfg, self._on_feedback, self._on_event,
                clock=self._clock, on_fault=self._on_node_fault,
            )
        if cfg.master_heartbeat_id:
            self._master_heartbeat = network.send_periodic(
                0x700 + cfg.master_heartbeat_id, bytes([cia402.NMT_OPERATIONAL]),
                cfg.heartbeat_ms / 1000.0,
            )
        failures: list[tuple[Epos2Driver, Epos2Error]] = []
        for driver in self.drivers.values():
            try:
                driver.start()
            except Epos2Error as e:
                failures.append((driver, e))
                driver._emit("no_answer" if isinstance(e, Epos2NoAnswer) else "start_failed",
                             str(e))
        if failures:
            self.close(disable=False)
            message = "; ".join(str(e) for _, e in failures)
            if all(isinstance(e, Epos2NoAnswer) for _, e in failures):
                raise Epos2NoAnswer(message)
            raise Epos2Error(message)
        if self._supervise:
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name="epos2-supervision",
                                            daemon=True)
            self._thread.start()
        if self._on_electrical is not None and cfg.electrical_period_ms > 0:
            self._stop.clear()
            self._electrical_thread = threading.Thread(target=self._run_electrical,
                                                       name="epos2-electrical", daemon=True)
            self._electrical_thread.start()

    def close(self, disable: bool = True) -> None:
        """Stop supervision, optionally send shutdown to enabled nodes, leave the bus."""
        if self._thread is not None:
            self._stop.set()
            self._actions.put(None)
            self._thread.join(timeout=2.0)
            self._thread = None
        if self._electrical_thread is not None:
            self._stop.set()
            self._electrical_thread.join(timeout=2.0 + 2 * self.config.sdo_timeout)
            self._electrical_thread = None
        if disable:
            for driver in self.drivers.values():
                if driver.started and driver.state in (cia402.OPERATION_ENABLED,
                                                       cia402.QUICK_STOP_ACTIVE):
                    try:
                        driver.disable()
                    except Exception:
                        logger.exception("%s: disable on close failed", driver.source)
        if self._master_heartbeat is not None:
            self._master_heartbeat.stop()
            self._master_heartbeat = None
        if self.network is not None:
            try:
                self.network.disconnect()
            except Exception:
                logger.exception("closing the CAN network failed")
            self.network = None

    def __enter__(self) -> FinDrives:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ----------------------------------------------------------------------------- commands
    def drive(self, fin: int) -> Epos2Driver:
        try:
            return self.drivers[fin]
        except KeyError:
            raise KeyError(f"fin {fin}: no drive (fins: {sorted(self.drivers)})") from None

    def command(self, fin: int, target_rad: float, profile_velocity_rad_s: float) -> bool:
        return self.drive(fin).command(target_rad, profile_velocity_rad_s)

    def enable_all(self) -> bool:
        return all([d.enable() for d in self.drivers.values()])

    def disable_all(self) -> bool:
        return all([d.disable() for d in self.drivers.values()])

    def quick_stop_all(self) -> bool:
        return all([d.quick_stop() for d in self.drivers.values()])

    def fault_reset(self, fin: int) -> bool:
        return self.drive(fin).fault_reset()

    def reset_faults(self) -> bool:
        """Reset every drive in fault and leave it unpowered (True when none is left in fault)."""
        return all([d.fault_reset(enable=False) for d in self.drivers.values()])

    def restart(self, fin: int) -> None:
        """Run one node's start-up again (after a ``bootup`` event); raises like connect."""
        driver = self.drive(fin)
        try:
            driver.start()
        except Epos2Error as e:
            driver._emit("no_answer" if isinstance(e, Epos2NoAnswer) else "start_failed", str(e))
            raise

    # ----------------------------------------------------------------------------- supervision
    @property
    def heard_until(self) -> float:
        """Every frame that arrived up to this time (on the drives' clock) has been read and
        handed on (``canbus.HeardBus``); -inf before the bus is open."""
        return self._bus.heard_until if self._bus is not None else -math.inf

    def check(self, now: float) -> None:
        """Every node's heartbeat and set-point acknowledge at ``now``, as far as heard."""
        heard = self._bus.heard_until if self._bus is not None else now
        for driver in self.drivers.values():
            driver.check(now, heard)

    def _on_node_fault(self, faulted: Epos2Driver) -> None:
        """Safe state: quick stop on every other enabled node (run on the supervision thread)."""

        def react() -> None:
            for driver in self.drivers.values():
                if driver is faulted or driver.state != cia402.OPERATION_ENABLED:
                    continue
                ok = driver.quick_stop()
                driver._emit("quick_stop", f"safe state: {faulted.source} faulted",
                             level="warning" if ok else "error", reason=faulted.source,
                             done=ok)

        if self._thread is not None:
            self._actions.put(react)
        else:
            logger.warning("no supervision thread: safe-state reaction for %s not run",
                           faulted.source)

    def _run(self) -> None:
        interval = self.config.heartbeat_ms / 5000.0
        next_check = time.monotonic()
        while not self._stop.is_set():
            try:
                action = self._actions.get(timeout=max(0.0, next_check - time.monotonic()))
            except queue.Empty:
                action = None
            if self._stop.is_set():
                break
            try:
                if action is not None:
                    action()
                if time.monotonic() >= next_check:
                    next_check = time.monotonic() + interval
                    self.check(self._clock())
            except Exception:
                logger.exception("EPOS2 supervision step failed")

    def read_electrical(self) -> dict[int, DriveElectrical | None]:
        """One round: every started node's electrical input, by fin (None: no answer)."""
        return {fin: driver.read_electrical() if driver.started else None
                for fin, driver in sorted(self.drivers.items())}

    def _run_electrical(self) -> None:
        sink = self._on_electrical
        assert sink is not None
        period = self.config.electrical_period_ms / 1000.0
        next_round = time.monotonic()
        while not self._stop.wait(max(0.0, next_round - time.monotonic())):
            next_round = max(next_round + period, time.monotonic())
            try:
                sink(self.read_electrical())
            except Exception:
                logger.exception("EPOS2 electrical readings failed")
