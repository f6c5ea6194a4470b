"""The supervisor: one process running the robot, the closed loop, the failsafes and the recorder.

::

    robot factory --> RobotIO --> ArmingGate --> ClosedLoop (own thread, PacedClock,
                                                  one planner thread per logical fin)
                                                     | private stream
                                                     v
    operator (UI, CLI) --> Supervisor  --- forward ---> public TelemetryStream
      commands, checked:                                  |--> UI (plots, 3-D view)
      access (pilot only), typed bounds                   |--> Recorder (on demand, on arming)
      and the envelope, before the loop                   '--> SafetyMonitor --> actions

* The loop runs in chunks of ``console.supervise_period``; between chunks the supervisor's
  thread arms (resetting the PID integrators so arming is bumpless), evaluates the
  failsafes and carries out their actions, and stops an automatic recording.
* Commands come from any thread (UI callbacks, the CLI). Each checks who asks
  (:class:`~ucat_console.backend.access.AccessDenied` unless the pilot) and the value
  (:class:`CommandRefused`, a ValueError naming the value and the allowed range) before
  anything changes; a refused command changes nothing.
* Arming takes two steps: :meth:`Supervisor.request_arm` returns a nonce that the same
  pilot passes to :meth:`Supervisor.confirm_arm` within ``access.confirm_timeout``.
  :meth:`Supervisor.disarm` acts at once.
* The loop's stream is forwarded to the public one; on the way, Status messages get the
  supervisor's arming, pilot and failsafe state, and while disarmed the fins' commanded
  angles are the ones really sent (none) and the executors' stroke timeouts are dropped.
* Telemetry time ``t`` is the loop's time, seconds from the start; the recorder's epoch
  offset is the wall-clock time of ``t = 0``.

The robot comes from a factory ``(app_config, event_sink) -> (robot_io, close)``:
:func:`sim_robot` (the default for ``robot = "sim"``) or :func:`rig_robot` (the device
rig, ``ucat_console.backend.rig.build_robot_io``).
"""

from __future__ import annotations

import logging
import math
import queue
import secrets
import threading
import time
from dataclasses import dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Mapping

from ucat_console.backend import redaction
from ucat_console.backend.access import LOCAL, AccessControl, AccessDenied, AccessState, Actor, actor_name
from ucat_console.backend.arming import ArmingGate
from ucat_console.backend.loop.clock import Clock, PacedClock
from ucat_console.backend.loop.closed_loop import PID_LOOPS, ClosedLoop
from ucat_console.backend.loop.config import MODES
from ucat_console.backend.loop.planners import MpcFinPlanner, warm_up
from ucat_console.backend.sim.robot_io import SimRobotIO
from ucat_console.robot.interface import RobotIO
from ucat_console.backend.safety import CHANNELS as SAFETY_CHANNELS
from ucat_console.backend.safety import SafetyMonitor, Transition
from ucat_console.backend.sessions.foxglove import robot_geometry
from ucat_console.backend.sessions.recorder import Recorder
from ucat_console.config import AppConfig
from ucat_console.control.allocation import BodySetpoints
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.events import Event, EventSink
from ucat_console.telemetry.messages import BodyState, FinState, Status
from ucat_console.telemetry.stream import TelemetryStream
from ucat_console.typedconf import check_value, secret_values

if TYPE_CHECKING:
    from ucat_console.backend.sim_rig import SimRig

log = logging.getLogger(__name__)

RobotFactory = Callable[[AppConfig, EventSink], tuple[RobotIO, Callable[[], None]]]

#: what the operator may tune live: block -> fields (PID blocks are "pid.<loop>")
TUNABLE: dict[str, tuple[str, ...]] = {
    "mpc": ("formulation", "lam_f", "lam_st", "lam_a", "lam_d", "lam_c", "lam_e", "st_opt", "st_low",
            "st_high", "n_samples"),
    **{f"pid.{loop}": ("kp", "ki", "kd", "limit") for loop in PID_LOOPS},
    "baseline": ("frequency",),
}
#: the setpoints the operator sets
SETPOINTS = ("velocity", "depth", "yaw_rate")
_JOURNAL_KEEP = 500
_WAIT_LOOP = 5.0  # s a command waits for the loop's thread


class CommandRefused(ValueError):
    """A command refused because of its value or the present state (the message says why)."""


def sim_robot(cfg: AppConfig, events: EventSink) -> tuple[RobotIO, Callable[[], None]]:
    """The in-process simulated U-CAT, level at ``console.sim_depth``."""
    return SimRobotIO(cfg.plant, depth=cfg.console.sim_depth), lambda: None


def rig_robot(cfg: AppConfig, events: EventSink) -> tuple[RobotIO, Callable[[], None]]:
    """The device rig (drivers on emulators or the robot), from ``backend.rig``."""
    from ucat_console.backend import rig

    return rig.build_robot_io(cfg, event_sink=events)


ROBOT_FACTORIES: dict[str, RobotFactory] = {"sim": sim_robot, "rig": rig_robot}


def simulated_rig(robot_io: RobotIO) -> SimRig | None:
    """The simulated rig behind ``robot_io`` (fault injection), None for any other robot."""
    if getattr(robot_io, "rig", None) is None:
        return None  # no device stack to import for the in-process simulator
    from ucat_console.backend.rig import rig_of

    return rig_of(robot_io)


class SteadyPacedClock(PacedClock):
    """A :class:`PacedClock` anchored once: the loop runs in chunks without drifting."""

    def __init__(self, pace: float = 1.0) -> None:
        super().__init__(pace)
        self._anchored = False

    def start(self, t0: float) -> None:
        if not self._anchored:
            super().start(t0)
            self._anchored = True
        else:
            self._wake.clear()


@dataclass(frozen=True)
class JournalEntry:
    """One operator or failsafe change: who, when (wall clock and stream time), old -> new."""

    wall: float
    t: float
    who: str
    key: str
    old: Any
    new: Any

    def text(self) -> str:
        stamp = time.strftime("%H:%M:%S", time.localtime(self.wall))
        return f"{stamp} {self.who}: {self.key} {_fmt(self.old)} -> {_fmt(self.new)}"


@dataclass(frozen=True)
class Health:
    """What the terminal's health line shows."""

    t: float
    mode: str
    armed: bool
    lag: float  # s the loop is behind the wall clock now
    lag_max: float
    late_plans: int
    plan_overruns: int
    failsafes: tuple[str, ...]
    clients: int
    pilot: str
    recording: str
    fault: str

    def line(self) -> str:
        fs = ",".join(self.failsafes) or "none"
        parts = [
            f"t={self.t:7.1f}s", f"mode={self.mode}", "ARMED" if self.armed else "disarmed",
            f"lag={self.lag * 1e3:.0f}ms(max {self.lag_max * 1e3:.0f})",
            f"late_plans={self.late_plans}", f"overruns={self.plan_overruns}",
            f"failsafes={fs}", f"clients={self.clients}", f"pilot={self.pilot or 'none'}",
            f"rec={self.recording or 'off'}",
        ]
        if self.fault:
            parts.append(f"FAULT={self.fault}")
        return " ".join(parts)


@dataclass
class _ArmRequest:
    nonce: str
    who: Actor
    expires: float


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:g}"
    return str(v)


def _number(key: str, value: Any, integer: bool) -> float | int:
    """``value`` as a finite number of the right kind, or CommandRefused naming ``key``."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        kind = "an integer" if integer else "a number"
        raise CommandRefused(f"{key}: expected {kind}, got {value!r}")
    if not math.isfinite(value):
        raise CommandRefused(f"{key}: {value!r} is not a finite number")
    if integer:
        if float(value) != int(value):
            raise CommandRefused(f"{key}: expected an integer, got {value!r}")
        return int(value)
    return float(value)


class Supervisor:
    """Runs the robot and the loop; the one entry point for operator commands."""

    def __init__(
        self,
        cfg: AppConfig | None = None,
        *,
        robot_factory: RobotFactory | None = None,
        clock: Clock | None = None,
        sessions_dir: str | Path | None = None,
    ) -> None:
        self.cfg = cfg = cfg or AppConfig()
        self.stream = TelemetryStream()
        self._loop_stream = TelemetryStream(validate=False)
        self._lock = threading.RLock()
        self._listeners: list[Callable[[], None]] = []
        self.access = AccessControl(cfg.access)
        self._secrets = [self.access.token, *secret_values(cfg)]
        redaction.keep_out_of_logs(self._secrets)
        self.safety = SafetyMonitor(cfg.failsafe)
        # the compiled solver first: a compile holds the interpreter for a minute or more,
        # which the drivers' heartbeat supervision would read as silent drives
        log.debug("planners warmed up in %.2f s", warm_up(cfg.loop))
        factory = robot_factory or ROBOT_FACTORIES[cfg.robot]
        inner, self._close_robot = factory(cfg, self.report_event)
        #: the simulated rig behind the drivers (robot "rig" on "sim-devices"), else None
        self.rig: SimRig | None = simulated_rig(inner)
        try:
            self.gate = ArmingGate(inner, on_invalid=self._on_invalid_reading)
            self.clock: Clock = clock if clock is not None else SteadyPacedClock(1.0)
            start_depth = cfg.console.sim_depth if cfg.robot == "sim" else 0.0
            self._setpoints = BodySetpoints(depth=min(start_depth, cfg.loop.max_depth))
            self.loop = ClosedLoop(
                cfg.loop, self.gate, self._loop_stream, self.clock, setpoints=self._setpoints,
                source=cfg.robot, driving=lambda: self.gate.armed,
            )
        except BaseException:
            inner.close()
            self._close_robot()
            raise
        self._mode = cfg.loop.mode
        self._tuning: dict[str, Any] = self._tuning_from(cfg)
        self._saved: dict[str, Any] = dict(self._tuning)
        self._journal: list[JournalEntry] = []
        self._arm_request: _ArmRequest | None = None
        self._armed_at: float | None = None
        self._disarmed_at: float | None = None
        self._auto_recording = False
        self._last_body: BodyState | None = None
        self._lag = 0.0
        self.fault = ""
        self.wall0 = time.time()
        self.recorder = Recorder(
            self.stream, cfg.recorder,
            directory=sessions_dir if sessions_dir is not None else (cfg.console.sessions_dir or None),
            epoch_offset=self.wall0, geometry=robot_geometry(cfg.plant),
        )
        self._pending: queue.SimpleQueue[tuple[Callable[[], Any], dict]] = queue.SimpleQueue()
        self._pending_lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._stopping = False
        self._closed = False
        self._chunks = 0
        self._unsubs = [
            self._loop_stream.subscribe(self._forward),
            self.stream.subscribe(self.safety.on_message, SAFETY_CHANNELS),
            self.stream.subscribe(self._on_body, [ch.BODY_STATE]),
        ]
        self.access.add_listener(self._on_access)

    # ================================================================== lifecycle
    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def start(self) -> None:
        """Run the loop in its own thread, in real time (with the default clock)."""
        if self._thread is not None:
            raise RuntimeError("the supervisor is already running")
        if self._closed:
            raise RuntimeError("the supervisor has been stopped")
        self.wall0 = time.time() - self.loop.time
        self.recorder.epoch_offset = self.wall0
        self._thread = threading.Thread(target=self._run, name="supervisor-loop", daemon=True)
        self._thread.start()
        log.info("supervisor started (robot %s, mode %s)", self.cfg.robot, self._mode)

    def step(self, duration: float) -> None:
        """Run the loop for ``duration`` s in the calling thread (tests; no thread started)."""
        if self._thread is not None:
            raise RuntimeError("step: the supervisor runs in its own thread")
        t_end = self.loop.time + duration
        while self.loop.time < t_end - 1e-9:
            self._chunk()

    def stop(self) -> None:
        """Disarm, stop the motors and the loop, close the recording and the robot."""
        if self._closed:
            return
        self._closed = True
        self._disarm(LOCAL, "shutdown")
        self._stopping = True
        self.loop.stop()
        if self._thread is not None:
            self._thread.join(timeout=10.0)
            if self._thread.is_alive():
                log.error("the loop thread did not stop within 10 s")
        else:
            self.gate.flush()
        self._fail_pending("the supervisor is stopping")
        try:
            self.recorder.stop()
        finally:
            for unsub in self._unsubs:
                unsub()
            try:
                self.loop.close()
            finally:
                self._close_robot()
                redaction.release(self._secrets)
        log.info("supervisor stopped")

    def __enter__(self) -> Supervisor:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.stop()

    # ================================================================== loop thread
    def _run(self) -> None:
        try:
            while not self._stopping:
                self._chunk()
        except BaseException as e:  # the loop failed: motors off, keep the UI informed
            self.fault = f"{type(e).__name__}: {e}"
            log.exception("the closed loop stopped")
            self.gate.disarm()
            self._armed_at = None
            self._publish_event("supervisor", "loop_fault", f"the closed loop stopped: {self.fault}",
                                "fatal", {"error": self.fault})
            self._notify()
        finally:
            try:
                self.gate.flush()
            except Exception:
                log.exception("stopping the fins failed")
            self._fail_pending("the loop is not running")

    def _chunk(self) -> None:
        self._run_pending()
        self.gate.flush()
        self._chunks += 1
        period = self.cfg.console.supervise_period
        t_end = max(self._chunks * period, self.loop.time)
        self.loop.run_until(t_end)
        self._after_chunk()

    def _after_chunk(self) -> None:
        now = self.loop.time
        clock = self.clock
        if isinstance(clock, PacedClock):
            self._lag = max(0.0, time.perf_counter() - clock.wall_deadline(now))
        self._run_pending()
        for tr in self.safety.check(now):
            self._on_failsafe(tr)
        if (self._auto_recording and self._armed_at is None and self._disarmed_at is not None
                and now - self._disarmed_at >= self.cfg.console.record_tail and self.recorder.recording):
            self._auto_recording = False
            threading.Thread(target=self._stop_recording_quietly, name="recorder-stop", daemon=True).start()

    def _in_loop(self, fn: Callable[[], Any]) -> Any:
        """Run ``fn`` in the loop's thread between chunks (at once when no thread runs)."""
        if self._thread is None or threading.current_thread() is self._thread:
            return fn()
        if not self._thread.is_alive():
            raise CommandRefused(f"the loop is not running{': ' + self.fault if self.fault else ''}")
        box: dict[str, Any] = {"done": threading.Event()}
        self._pending.put((fn, box))
        if not box["done"].wait(_WAIT_LOOP):
            with self._pending_lock:  # a command either runs, and is answered, or never runs
                started = box.setdefault("started", False)
                if not started:
                    box["abandoned"] = True
            if not started:
                raise CommandRefused("the loop did not answer in time; nothing was done")
            box["done"].wait()
        if "error" in box:
            raise box["error"]
        return box.get("result")

    def _run_pending(self) -> None:
        while True:
            try:
                fn, box = self._pending.get_nowait()
            except queue.Empty:
                return
            with self._pending_lock:
                if box.get("abandoned"):
                    continue
                box["started"] = True
            try:
                box["result"] = fn()
            except BaseException as e:
                box["error"] = e
            box["done"].set()

    def _fail_pending(self, why: str) -> None:
        while True:
            try:
                _, box = self._pending.get_nowait()
            except queue.Empty:
                return
            box["error"] = CommandRefused(why)
            box["done"].set()

    # ================================================================== telemetry
    def _forward(self, channel: str, msg: Any) -> None:
        if channel == ch.STATUS:
            msg = self.status(msg.t)
        elif not self.gate.armed:
            tp = type(msg)
            if tp is FinState:
                a, r = self.gate.sent[msg.fin]
                msg = FinState(msg.t, msg.fin, msg.angle, msg.rate, a, r)
            elif tp is Event and msg.code == "stroke_timeout" and msg.source == "loop":
                return
        self.stream.publish(channel, msg)

    def _on_body(self, channel: str, msg: BodyState) -> None:
        self._last_body = msg

    def report_event(self, event: Event) -> None:
        """Event sink for the robot's devices (any thread): onto the stream."""
        if not isinstance(event, Event):
            raise ValueError(f"event: expected an Event, got {type(event).__name__}")
        self.stream.publish(ch.EVENTS, event)

    def _publish_event(self, source: str, code: str, message: str, level: str = "info",
                       data: dict | None = None) -> Event:
        ev = Event(t=self.loop.time, source=source, code=code, message=message, level=level, data=data or {})
        self.stream.publish(ch.EVENTS, ev)
        return ev

    def _on_invalid_reading(self, sensor: str, what: str) -> None:
        if sensor in ("imu", "dvl", "depth"):
            self.safety.note_invalid(sensor, what)

    def status(self, t: float | None = None) -> Status:
        return Status(
            t=self.loop.time if t is None else t, armed=self.gate.armed, mode=self._mode,
            pilot="" if self.access.pilot is None else str(self.access.pilot),
            failsafes=self.safety.active(), late_plans=self.loop.late_plans, source=self.cfg.robot,
        )

    def _publish_status(self) -> None:
        self.stream.publish(ch.STATUS, self.status())

    def add_listener(self, fn: Callable[[], None]) -> None:
        """``fn()`` after every change of state the operator sees (any thread)."""
        self._listeners.append(fn)

    def _notify(self) -> None:
        for fn in list(self._listeners):
            try:
                fn()
            except Exception:
                log.exception("supervisor listener failed")

    def wall_time(self, t: float) -> float:
        """UNIX time of stream time ``t`` (real-time runs)."""
        return self.wall0 + t

    # ================================================================== state
    @property
    def armed(self) -> bool:
        return self.gate.armed

    @property
    def mode(self) -> str:
        return self._mode

    @property
    def setpoints(self) -> BodySetpoints:
        return self._setpoints

    def tuning(self) -> dict[str, Any]:
        """The commanded tuning: block -> config (MpcConfig, PidGains, BaselineConfig)."""
        with self._lock:
            return dict(self._tuning)

    def param_value(self, key: str) -> Any:
        block, name = self._split_key(key)
        return getattr(self.tuning()[block], name)

    def saved_tuning(self) -> dict[str, Any]:
        with self._lock:
            return dict(self._saved)

    def journal(self, last: int | None = None) -> list[JournalEntry]:
        with self._lock:
            return list(self._journal if last is None else self._journal[-last:])

    def health(self) -> Health:
        clock = self.clock
        lag_max = clock.lag_max if isinstance(clock, PacedClock) else 0.0
        pilot = self.access.pilot
        return Health(
            t=self.loop.time, mode=self._mode, armed=self.gate.armed, lag=self._lag,
            lag_max=max(lag_max, self._lag), late_plans=self.loop.late_plans,
            plan_overruns=self.loop.plan_overruns, failsafes=self.safety.active(),
            clients=len(self.access.clients), pilot="" if pilot is None else actor_name(pilot),
            recording=self.recorder.session_id if self.recorder.recording else "", fault=self.fault,
        )

    def current_config(self) -> AppConfig:
        """The configuration in force (the file's, with the live tuning applied)."""
        t = self.tuning()
        body = self.cfg.body.replace(**{loop: t[f"pid.{loop}"] for loop in PID_LOOPS})
        return self.cfg.replace(mpc=t["mpc"], baseline=t["baseline"], body=body,
                                loop=self.cfg.loop.replace(mode=self._mode))

    @staticmethod
    def _tuning_from(cfg: AppConfig) -> dict[str, Any]:
        out: dict[str, Any] = {"mpc": cfg.mpc, "baseline": cfg.baseline}
        for loop in PID_LOOPS:
            out[f"pid.{loop}"] = getattr(cfg.body, loop)
        return out

    def _journal_add(self, who: str, key: str, old: Any, new: Any) -> JournalEntry:
        e = JournalEntry(time.time(), self.loop.time, who, key, old, new)
        with self._lock:
            self._journal.append(e)
            if len(self._journal) > _JOURNAL_KEEP:
                del self._journal[: len(self._journal) - _JOURNAL_KEEP]
        return e

    # ================================================================== access
    def client_connected(self, client: int, address: str = "") -> None:
        """A page connected (from remote ``address``)."""
        self.access.connect(client, address)

    def client_disconnected(self, client: int, silent_for: float = 0.0) -> None:
        """A page is gone: its socket closed, or it has not answered for ``silent_for`` s.

        When it was the pilot's, the pilot-gone failsafe counts from the page's last sign of
        life (``silent_for`` s ago), unless the page that was waiting for a hand-over has
        taken control."""
        if self._arm_request is not None and self._arm_request.who == client:
            self._arm_request = None
        if not self.access.disconnect(client):
            return
        successor = self.access.pilot
        how = (f"has not answered for {silent_for:.1f} s" if silent_for > 0 else "is gone")
        self._publish_event("access", "pilot_left", f"the pilot's page (client {client}) {how}",
                            "warning", {"client": client, "silent_for": silent_for})
        if successor is None:
            self.safety.pilot_left(now=max(self.loop.time - silent_for, 0.0))
        else:
            self._publish_event("access", "pilot", f"client {successor} took control (it had asked for it)",
                                "info", {"client": successor})

    def take_control(self, client: int, token: object) -> bool:
        """True: ``client`` is the pilot now; False: waiting for the pilot's hand-over."""
        try:
            granted = self.access.request_control(client, token)
        except AccessDenied as e:
            self._publish_event("access", "refused", str(e), "warning", {"client": client})
            raise
        if granted:
            self._publish_event("access", "pilot", f"client {client} took control", "info", {"client": client})
        else:
            self._publish_event("access", "request", f"client {client} asks for control", "info",
                                {"client": client, "pilot": self.access.pilot})
        return granted

    def hand_over(self, pilot: Actor, to: int) -> None:
        self.access.hand_over(pilot, to)
        self._arm_request = None
        self._publish_event("access", "pilot", f"{actor_name(pilot)} handed control to client {to}",
                            "info", {"client": to, "from": str(pilot)})

    def decline(self, pilot: Actor) -> None:
        self.access.decline(pilot)

    def release(self, client: Actor) -> None:
        if self.gate.armed:
            raise CommandRefused("release: disarm first, or hand control over to another page")
        self.access.release(client)
        self.safety.pilot_released()
        self._publish_event("access", "released", f"{actor_name(client)} released control", "info")

    def _on_access(self, st: AccessState) -> None:
        if st.pilot is not None:
            self.safety.pilot_present()
        self._publish_status()
        self._notify()

    # ================================================================== arming
    def _check_can_arm(self) -> None:
        if self.fault:
            raise CommandRefused(f"arm: the closed loop has stopped ({self.fault})")
        blocking = [s for s in self.safety.states() if s.active and s.action != "warn"]
        if blocking:
            why = "; ".join(f"{s.name} ({s.cause})" for s in blocking)
            raise CommandRefused(f"arm: refused while failsafes are active: {why}")

    def request_arm(self, who: Actor) -> str:
        """First step of arming: a nonce to pass to :meth:`confirm_arm`."""
        self.access.require_pilot(who, "arm")
        self._check_can_arm()
        nonce = secrets.token_hex(8)
        self._arm_request = _ArmRequest(nonce, who, time.monotonic() + self.cfg.access.confirm_timeout)
        return nonce

    def cancel_arm(self, who: Actor) -> None:
        req = self._arm_request
        if req is not None and req.who == who:
            self._arm_request = None

    def confirm_arm(self, who: Actor, nonce: object) -> None:
        """Second step of arming: the motors move from now on."""
        self.access.require_pilot(who, "arm")
        req = self._arm_request
        if req is None or req.who != who:
            raise CommandRefused("arm: nothing to confirm; press Arm first")
        self._arm_request = None  # one confirmation attempt per request
        if not isinstance(nonce, str) or not secrets.compare_digest(nonce, req.nonce):
            raise CommandRefused("arm: the confirmation does not match the request; press Arm again")
        if time.monotonic() > req.expires:
            raise CommandRefused("arm: the confirmation came too late; press Arm again")
        self._check_can_arm()
        self._in_loop(lambda: self._do_arm(who))

    def arm(self, who: Actor = LOCAL) -> None:
        """Request and confirm in one call (the console itself: headless runs)."""
        self.confirm_arm(who, self.request_arm(who))

    def _do_arm(self, who: Actor) -> None:
        if self.gate.armed:
            return
        self._check_can_arm()
        if not self.gate.enable_drives():
            self.gate.stop_drives()  # those that came up go off again: nothing is half-armed
            raise CommandRefused("arm: not every fin drive reached operation enabled (see its "
                                 "events); the robot stays disarmed")
        if self.cfg.console.record_on_arm and not self.recorder.recording:
            try:  # first, so the recording holds the moment of arming
                self._start_recording(label="armed", notes="started on arming")
                self._auto_recording = True
            except Exception as e:  # recording must never stop arming
                log.exception("automatic recording failed")
                self._publish_event("recorder", "start_failed", f"recording did not start: {e}", "error")
        self.loop.restart()  # nothing the loop did while the fins were held carries over
        self.gate.arm()
        self._armed_at = self.loop.time
        self._disarmed_at = None
        self._publish_event("supervisor", "armed", f"motors armed by {actor_name(who)}", "warning",
                            {"who": str(who)})
        self._publish_status()
        self._notify()

    def disarm(self, who: Actor, reason: str = "operator") -> None:
        """Motors off at once (the pilot, the console, or a failsafe)."""
        self.access.require_pilot(who, "disarm")
        self._disarm(who, reason)

    def _disarm(self, who: Actor | str, reason: str) -> None:
        was = self.gate.armed
        self.gate.disarm()
        self._arm_request = None
        if was:
            self._armed_at = None
            self._disarmed_at = self.loop.time
            self._publish_event("supervisor", "disarmed", f"motors disarmed ({reason})", "warning",
                                {"who": str(who), "reason": reason})
            self._publish_status()
            self._notify()

    # ================================================================== failsafes
    def _on_failsafe(self, tr: Transition) -> None:
        rule = self.safety.rule(tr.name)
        if tr.active:
            self._publish_event("failsafe", tr.name, f"{tr.name}: {tr.cause}; action: {rule.action}", "error",
                                {"action": rule.action, "timeout": rule.timeout, "cause": tr.cause})
            if rule.action == "disarm":
                self._disarm("failsafe", f"failsafe {tr.name}")
            elif rule.action in ("hold", "surface"):
                if rule.action == "hold":
                    body = self._last_body
                    depth = body.depth if body is not None and math.isfinite(body.depth) else self._setpoints.depth
                    depth = min(max(depth, 0.0), self.cfg.loop.max_depth)
                else:
                    depth = 0.0
                self._apply_setpoints(BodySetpoints(0.0, depth, 0.0), f"failsafe {tr.name}")
        else:
            self._publish_event("failsafe", "cleared", f"{tr.name} cleared", "info", {"failsafe": tr.name})
        self._publish_status()
        self._notify()

    def _holding(self) -> list[str]:
        return [s.name for s in self.safety.states() if s.active and s.action in ("hold", "surface")]

    # ================================================================== commands
    def set_mode(self, who: Actor, mode: object) -> None:
        self.access.require_pilot(who, "mode")
        if not isinstance(mode, str) or mode not in MODES:
            raise CommandRefused(f"mode: {mode!r} is not one of {', '.join(MODES)}")
        with self._lock:
            old = self._mode
            if mode == old:
                return
            self.loop.set_mode(mode)
            self._mode = mode
        self._journal_add(actor_name(who), "mode", old, mode)
        self._publish_event("operator", "mode", f"{actor_name(who)}: mode {old} -> {mode}", "info",
                            {"who": str(who), "from": old, "to": mode})
        self._publish_status()
        self._notify()

    def set_setpoints(self, who: Actor, velocity: object = None, depth: object = None,
                      yaw_rate: object = None) -> None:
        """New setpoints (unchanged where None), inside the loop's envelope."""
        self.access.require_pilot(who, "setpoints")
        given = {"velocity": velocity, "depth": depth, "yaw_rate": yaw_rate}
        values = {k: _number(k, v, False) for k, v in given.items() if v is not None}
        holding = self._holding()
        if holding:
            raise CommandRefused(
                f"setpoints: failsafe {', '.join(holding)} holds the setpoints until its cause clears"
            )
        cur = self._setpoints
        try:
            sp = self.loop.check_setpoints(BodySetpoints(
                velocity=values.get("velocity", cur.velocity), depth=values.get("depth", cur.depth),
                yaw_rate=values.get("yaw_rate", cur.yaw_rate),
            ))
        except ValueError as e:
            raise CommandRefused(str(e)) from None
        self._apply_setpoints(sp, actor_name(who))

    def _apply_setpoints(self, sp: BodySetpoints, who: str) -> None:
        with self._lock:
            old = self._setpoints
            self.loop.set_setpoints(velocity=sp.velocity, depth=sp.depth, yaw_rate=sp.yaw_rate)
            self._setpoints = sp
        changes = {}
        for k in SETPOINTS:
            a, b = getattr(old, k), getattr(sp, k)
            if a != b:
                changes[k] = [a, b]
                self._journal_add(who, f"setpoint.{k}", a, b)
        if changes:
            self._publish_event("operator", "setpoints", f"{who}: " + ", ".join(
                f"{k} {_fmt(v[0])} -> {_fmt(v[1])}" for k, v in changes.items()), "info",
                {"who": who, "changes": changes})
        self._notify()

    @staticmethod
    def _split_key(key: object) -> tuple[str, str]:
        if not isinstance(key, str) or "." not in key:
            raise CommandRefused(f"parameter: {key!r} is not a tunable parameter")
        block, _, name = key.rpartition(".")
        if name not in TUNABLE.get(block, ()):
            raise CommandRefused(f"{key}: not a tunable parameter")
        return block, name

    def check_params(self, changes: Mapping[str, object]) -> dict[str, Any]:
        """The tuning blocks ``changes`` would give, or CommandRefused; changes nothing."""
        if not isinstance(changes, Mapping) or not changes:
            raise CommandRefused("tuning: no changes given")
        current = self.tuning()
        per_block: dict[str, dict[str, Any]] = {}
        for key, value in changes.items():
            block, name = self._split_key(key)
            cfg = current[block]
            f = next(f for f in fields(cfg) if f.name == name)
            if isinstance(getattr(cfg, name), str):  # a choice field: its value is a name
                if not isinstance(value, str):
                    raise CommandRefused(f"{key}: expected a name, got {value!r}")
                v: Any = value
            else:
                v = _number(key, value, isinstance(getattr(cfg, name), int))
            try:
                check_value(f, v, prefix=f"{block}.")
            except ValueError as e:
                raise CommandRefused(str(e)) from None
            per_block.setdefault(block, {})[name] = v
        out: dict[str, Any] = {}
        for block, vals in per_block.items():
            try:
                new = current[block].replace(**vals)
            except ValueError as e:
                raise CommandRefused(f"{block}.{e}" if not str(e).startswith(block) else str(e)) from None
            if block == "mpc":
                try:
                    MpcFinPlanner(new, 0)
                except ValueError as e:
                    raise CommandRefused(f"mpc: {e}") from None
            out[block] = new
        return out

    def set_params(self, who: Actor, changes: Mapping[str, object]) -> None:
        """Apply ``{"mpc.lam_st": 2.0, "pid.depth.kp": 4.0, ...}`` together, or none of them."""
        self.access.require_pilot(who, "tuning")
        self._apply_tuning(self.check_params(changes), actor_name(who))

    def set_param(self, who: Actor, key: str, value: object) -> None:
        self.set_params(who, {key: value})

    def _apply_tuning(self, new_blocks: Mapping[str, Any], who: str) -> None:
        diffs: dict[str, list[Any]] = {}
        with self._lock:
            for block, new in new_blocks.items():
                old = self._tuning[block]
                if new == old:
                    continue
                if block == "mpc":
                    self.loop.set_mpc_config(new)
                elif block == "baseline":
                    self.loop.set_baseline_config(new)
                else:
                    self.loop.set_pid_gains(block.split(".", 1)[1], new)
                self._tuning[block] = new
                for f in fields(new):
                    a, b = getattr(old, f.name), getattr(new, f.name)
                    if a != b:
                        diffs[f"{block}.{f.name}"] = [a, b]
        if not diffs:
            return
        for key, (a, b) in diffs.items():
            self._journal_add(who, key, a, b)
        self._publish_event("operator", "tuning", f"{who}: " + ", ".join(
            f"{k} {_fmt(v[0])} -> {_fmt(v[1])}" for k, v in diffs.items()), "info",
            {"who": who, "changes": diffs})
        self._notify()

    def save_baseline(self, who: Actor) -> None:
        """The present tuning becomes the one to revert to."""
        self.access.require_pilot(who, "save tuning")
        with self._lock:
            self._saved = dict(self._tuning)
        self._journal_add(actor_name(who), "tuning", "saved", "baseline")
        self._notify()

    def revert_tuning(self, who: Actor) -> None:
        """Back to the saved tuning in one step (journalled like any change)."""
        self.access.require_pilot(who, "revert tuning")
        self._apply_tuning(self.saved_tuning(), actor_name(who))

    # ================================================================== recording
    def _start_recording(self, label: str = "", notes: str = "") -> str:
        t = self.tuning()["mpc"]
        return self.recorder.start(
            label=label, notes=notes, config_toml=self.current_config().to_toml(redact=True),
            weights={"lam_f": t.lam_f, "lam_st": t.lam_st, "lam_a": t.lam_a, "lam_d": t.lam_d},
        )

    def start_recording(self, who: Actor, notes: object = "") -> str:
        self.access.require_pilot(who, "record")
        if not isinstance(notes, str) or len(notes) > 2000:
            raise CommandRefused("notes: expected text of at most 2000 characters")
        if self.recorder.recording:
            raise CommandRefused(f"record: already recording session {self.recorder.session_id}")
        sid = self._start_recording(notes=notes)
        self._auto_recording = False
        self._publish_event("operator", "recording", f"{actor_name(who)} started recording {sid}", "info",
                            {"session": sid})
        self._notify()
        return sid

    def stop_recording(self, who: Actor) -> list[Path]:
        self.access.require_pilot(who, "record")
        if not self.recorder.recording:
            raise CommandRefused("record: not recording")
        sid = self.recorder.session_id
        self._publish_event("operator", "recording", f"{actor_name(who)} stopped recording {sid}", "info",
                            {"session": sid})
        paths = self.recorder.stop()
        self._auto_recording = False
        self._notify()
        return paths

    def _stop_recording_quietly(self) -> None:
        try:
            self.recorder.stop()
        except Exception:
            log.exception("stopping the recording failed")
        self._notify()

    # ================================================================== rig faults
    def inject_fault(self, who: Actor, device: object, fault: object, **kw: Any) -> Event:
        """Start an emulator fault on the simulated rig (the pilot rehearsing a failsafe).

        Arguments as :meth:`SimRig.inject`; its ``fault_injected`` event and every event the
        fault causes reach the events channel (and the recording)."""
        self.access.require_pilot(who, "fault injection")
        rig = self._require_rig("fault injection")
        if not isinstance(device, str) or not isinstance(fault, str):
            raise CommandRefused(f"fault injection: device and fault must be names, got {device!r}, {fault!r}")
        try:
            event = rig.inject(device, fault, **kw)
        except ValueError as e:
            raise CommandRefused(f"fault injection: {e}") from None
        self._notify()
        return event

    def clear_fault(self, who: Actor, device: object, fault: object = None) -> None:
        """End one emulator fault of ``device`` on the simulated rig, or all of its faults."""
        self.access.require_pilot(who, "fault injection")
        rig = self._require_rig("fault injection")
        if not isinstance(device, str) or not (fault is None or isinstance(fault, str)):
            raise CommandRefused(f"fault injection: device and fault must be names, got {device!r}, {fault!r}")
        try:
            rig.clear(device, fault)
        except ValueError as e:
            raise CommandRefused(f"fault injection: {e}") from None
        self._notify()

    # ================================================================== drives
    @property
    def has_drives(self) -> bool:
        """The fins are moved by motor drives (the robot, or the rig's emulated EPOS2s)."""
        return self.gate.has_drives

    def reset_drive_faults(self, who: Actor) -> None:
        """Reset the drives in fault (after an EMCY), disarmed; they are powered at arming."""
        self.access.require_pilot(who, "drive fault reset")
        if not self.has_drives:
            raise CommandRefused(f"drive fault reset: robot {self.cfg.robot!r} has no motor drives")
        if self.gate.armed:
            raise CommandRefused("drive fault reset: disarm first")
        ok = self._in_loop(self.gate.reset_drive_faults)
        self._publish_event("operator", "drive_fault_reset",
                            f"{actor_name(who)} reset the drive faults" + ("" if ok else ": not every drive left its fault"),
                            "info" if ok else "error", {"who": str(who), "ok": ok})
        self._notify()
        if not ok:
            raise CommandRefused("drive fault reset: not every drive left its fault (see its events)")

    def zero_depth(self, who: Actor) -> float:
        """Take the present pressure as the surface's (disarmed, the robot at the surface);
        the surface pressure (Pa)."""
        self.access.require_pilot(who, "depth zeroing")
        if self.gate.armed:
            raise CommandRefused("depth zeroing: disarm first, with the robot floating at the surface")
        try:  # in the caller's thread: it waits for the sensor's next readings, the loop runs on
            p = self.gate.zero_depth()
        except ValueError as e:
            raise CommandRefused(str(e)) from None
        self._publish_event("operator", "depth_zeroed", f"{actor_name(who)} zeroed the depth at "
                            f"{p:.1f} Pa", "info", {"who": str(who), "surface_pressure_pa": p})
        return p

    def _require_rig(self, what: str) -> SimRig:
        if self.rig is None:
            raise CommandRefused(
                f"{what}: only the simulated robot behind the device emulators takes faults "
                f"(robot = 'rig' with devices.robot = 'sim-devices'); this console runs robot "
                f"{self.cfg.robot!r}"
            )
        return self.rig

    def add_marker(self, who: Actor, note: object = "") -> Event:
        """A marker with a note on the events channel (recorded when recording)."""
        self.access.require_pilot(who, "marker")
        if not isinstance(note, str) or len(note) > 500:
            raise CommandRefused("marker: the note must be text of at most 500 characters")
        ev = self._publish_event("operator", "marker", note or "marker", "info",
                                 {"note": note, "who": str(who)})
        self._notify()
        return ev
