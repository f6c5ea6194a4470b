# Over 600 lines: the supervisor composes the console's parts and is the one door of every command (access and failsafe checks, then the part that acts).
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
  thread evaluates the failsafes and carries out their actions, and stops an automatic
  recording.
* Commands come from any thread (UI callbacks, the CLI). Each checks who asks
  (:class:`~ucat_console.backend.access.AccessDenied` unless the pilot) and what the
  failsafes allow, then submits a typed command to the loop
  (:mod:`ucat_console.backend.loop.commands`: the command checks its own values, a
  :class:`CommandRefused` naming the field and the allowed range); a refused command
  changes nothing. The work that must run in the loop's thread (arming, drive resets) is a
  :class:`LoopWork` command too: the caller waits up to ``loop_wait`` s for its answer,
  then cancels it, so it either ran and was answered or never runs. A disarm acts at once,
  never behind a queued command.
* Arming takes two steps (:class:`~.arm_requests.ArmRequests`): :meth:`Supervisor.request_arm`
  returns a nonce that the same pilot passes to :meth:`Supervisor.confirm_arm` within
  ``access.confirm_timeout``. :meth:`Supervisor.disarm` acts at once.
* The loop's stream is forwarded to the public one (:class:`~.forwarding.LoopOutlet`), a
  burst of plan overruns or stalls folded into one event. The loop publishes what the
  robot really does: its Status messages are the supervisor's (arming, pilot, failsafes),
  its fin states carry the set-points the gate actually sent (disarmed: the last, or the
  stop), and a disarmed loop publishes no stroke timeouts.
* Telemetry time ``t`` is the loop's time, seconds from the start; the recorder's epoch
  offset is the wall-clock time of ``t = 0``.
* The page reads the console through :meth:`Supervisor.state`, one immutable snapshot of
  values (:mod:`~.console_state`), and never through the parts; it commands through the
  methods here.

Who owns what: the supervisor owns the commanded mode and setpoints and the arming state
of the gate; :class:`~.tuning.Tuning` the commanded tuning and its journal;
:class:`~.recording.SessionRecording` the recording; :class:`~.rig_control.RigControl` the
drive and fault commands; :class:`~.manoeuvre.ManoeuvreRun` an identification manoeuvre;
:class:`~.scripted_run.ScriptRun` a scripted manoeuvre (docs/manoeuvres.md);
:class:`~.seek_run.SeekRun` a seek of efficiency (docs/seek.md);
the closed loop owns what it has applied. The parts live in the modules of this package
and get what they use passed in (``RigHost``, ``ManoeuvreHost``, ``ScriptHost``, ``SeekHost``: the few commands and
readings each needs), never the supervisor itself.

The module is over 500 lines because :class:`Supervisor` is the one entry point for
operator commands (about forty): each is a short method that checks who asks and what, then
acts through its part; the state and logic of the parts are in their own modules.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Mapping

from ucat_console.backend import redaction
from ucat_console.backend.access import LOCAL, AccessControl, AccessDenied, AccessState, Actor, actor_name
from ucat_console.backend.arming import ArmingGate
from ucat_console.backend.loop.clock import Clock, PacedClock
from ucat_console.backend.loop.closed_loop import ClosedLoop
from ucat_console.backend.loop.commands import (
    SETPOINTS,
    CommandRefused,
    LoopWork,
    Restart,
    SetMode,
    SetSetpoints,
    number,
)
from ucat_console.backend.loop.kernels_warm_up import warm_up
from ucat_console.backend.review.effects import ChangeEffects
from ucat_console.backend.review.run_report import ReportWriter
from ucat_console.backend.safety import SafetyMonitor, Transition
from ucat_console.backend.safety import channels as safety_channels
from ucat_console.backend.camera.source import CameraThread
from ucat_console.backend.sensors import OpenContext, SensorPoller
from ucat_console.backend.sessions.limits import MemoryBudget
from ucat_console.backend.sessions.shared import SharedReaders
from ucat_console.backend.sessions.foxglove import robot_geometry
from ucat_console.backend.sessions.recorder import Recorder
from ucat_console.backend.supervisor.arm_requests import ArmRequests
from ucat_console.backend.supervisor.bursts import BurstFolder
from ucat_console.backend.supervisor.console_state import ConsoleState, build_state
from ucat_console.backend.supervisor.forwarding import LoopOutlet
from ucat_console.backend.supervisor.health import Health
from ucat_console.backend.supervisor.manoeuvre import ManoeuvreHost, ManoeuvreRun
from ucat_console.backend.supervisor.recording import SessionRecording
from ucat_console.backend.supervisor.run_library import RunLibrary, RunView
from ucat_console.backend.supervisor.scripted_run import ScriptHost, ScriptRun
from ucat_console.backend.supervisor.seek_run import SeekHost, SeekRun
from ucat_console.backend.supervisor.rig_control import RigControl, RigHost
from ucat_console.backend.robots import robot
from ucat_console.backend.supervisor.robots import RobotFactory, SteadyPacedClock, simulated_rig
from ucat_console.backend.supervisor.tuning import (
    Journal,
    JournalEntry,
    Tuning,
    configured,
    fmt,
    is_tuning_key,
    param_field,
)
from ucat_console.backend.supervisor.watchdog import LoopWatchdog
from ucat_console.config import AppConfig, known_configs
from ucat_console.control.allocation import BodySetpoints
from ucat_console.control.scripted import Script
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.messages import BodyState, Status
from ucat_console.telemetry.stream import TelemetryStream
from ucat_console.typedconf import secret_values

if TYPE_CHECKING:
    from ucat_console.backend.sim_rig import SimRig

log = logging.getLogger(__name__)

#: seconds a command waits for the loop's thread
WAIT_LOOP = 5.0
#: the longest note of a live marker (characters)
MAX_MARKER_NOTE = 500
#: s, how long stopping the supervisor waits for the last recording's report (a headless run's)
REPORT_WAIT = 60.0


class Supervisor:
    """Runs the robot and the loop; the one entry point for operator commands."""

    def __init__(
        self,
        cfg: AppConfig | None = None,
        *,
        robot_factory: RobotFactory | None = None,
        clock: Clock | None = None,
        sessions_dir: str | Path | None = None,
        planner_ready: Callable[[str], bool] | None = None,
        config_name: str = "",
    ) -> None:
        """``planner_ready(formulation)``: whether that formulation's planner is compiled
        (a preparation running in child processes, ``backend.prepare``); without it every
        formulation is loaded, or compiled here, before the robot starts. ``config_name``:
        the name ``cfg`` was loaded by (its recordings say so; "" when none)."""
        self.cfg = cfg = cfg or AppConfig()
        self.stream = TelemetryStream()
        #: plan overruns and the loop's stalls, one event per burst
        self.bursts = BurstFolder(lambda ev: self.stream.publish(ch.EVENTS, ev), ("plan_overrun", "stall"))
        self._loop_stream = LoopOutlet(self.stream, self.bursts)
        self._lock = threading.RLock()
        self._listeners: list[Callable[[], None]] = []
        self.access = AccessControl(cfg.access)
        self._secrets = [self.access.token, *secret_values(cfg)]
        redaction.keep_out_of_logs(self._secrets)
        self.safety = SafetyMonitor(cfg.failsafe)
        for name in cfg.failsafe.warn_only():
            log.warning("failsafe %s is set to warn: it will not act on the robot (its action under [failsafe])", name)
        # the compiled solver first: a compile holds the interpreter for a minute or more,
        # which the drivers' heartbeat supervision would read as silent drives
        mine = (cfg.loop.mpc.formulation,) if planner_ready is not None else None
        log.debug("planners warmed up in %.2f s", warm_up(cfg.loop, formulations=mine))
        entry = robot(cfg.robot)
        factory = robot_factory or (lambda c, events: entry.build(c.devices, c.plant, events))
        inner, self._close_robot = factory(cfg, self.report_event)
        #: the simulated rig behind the drivers (robot "sim-devices"), else None
        self.rig: SimRig | None = simulated_rig(inner)
        try:
            self.gate = ArmingGate(inner, on_invalid=self._on_invalid_reading)
            # a computed reading may be taken early, a device's not before its time
            early = cfg.console.sim_early if entry.computed_readings else 0.0
            self.clock: Clock = clock if clock is not None else SteadyPacedClock(1.0, early, cfg.console.max_lag)
            #: where the depth setpoint starts (the simulated robot's start, else the surface)
            self.start_depth = min(entry.start_depth(cfg.devices), cfg.loop.max_depth)
            self.loop = ClosedLoop(
                cfg.loop, self.gate, self._loop_stream, self.clock,
                setpoints=BodySetpoints(depth=self.start_depth),
                source=cfg.robot, driving=lambda: self.gate.armed, status=self.status,
            )
        except BaseException:
            inner.close()
            self._close_robot()
            raise
        self.journal_log = Journal(lambda: self.loop.time)
        self.tuning_state = Tuning(cfg, self.loop, self.journal_log, planner_ready or (lambda f: True))
        self.arm_requests = ArmRequests(cfg.access.confirm_timeout)
        #: seconds a command waits for the loop's thread (:meth:`_in_loop`)
        self.loop_wait = WAIT_LOOP
        self._armed_at: float | None = None
        #: the identification manoeuvre last started (None: none yet)
        self.manoeuvre: ManoeuvreRun | None = None
        self._last_body: BodyState | None = None
        self._lag = 0.0
        self.fault = ""
        self.wall0 = time.time()
        #: the console's open session readers, all within its memory budget (``[review]``)
        self.readers = SharedReaders(MemoryBudget(cfg.review))
        self.recorder = Recorder(
            self.stream, cfg.recorder,
            directory=sessions_dir if sessions_dir is not None else (cfg.console.sessions_dir or None),
            epoch_offset=self.wall0, geometry=robot_geometry(cfg.plant),
        )
        #: each stopped recording's HTML report, written in the background (``[console] write_reports``)
        self.reports = ReportWriter() if cfg.console.write_reports else None
        if self.reports is not None:
            self.recorder.add_stop_listener(self.reports.submit)
        self.recording = SessionRecording(
            self.recorder, config_toml=lambda: self.current_config().to_toml(redact=True),
            weights=self._weights, on_arm=cfg.console.record_on_arm, tail=cfg.console.record_tail,
            tail_max=cfg.console.record_tail_max, notify=self._notify, config_name=config_name,
        )
        #: the sessions folder's run library, as the pages find and annotate runs
        self.run_library = RunLibrary(self.recorder.directory, self.readers.budget, known_configs)
        #: counts the writes of tags and notes: a page lists its runs again when it changes
        self.runs_version = 0
        #: the registered auxiliary sensors (``backend.sensors``: the leak detector first), read by
        #: the console on any robot, published on their channels
        self.sensors = SensorPoller(OpenContext(cfg.devices, entry.simulated, inner, self.report_event,
                                                lambda: self.loop.time), self.stream.publish)
        #: the vehicle's camera (``[camera]``; None: none), read in its own thread onto camera/image
        self.camera = CameraThread(cfg.camera, self.stream.publish, self.report_event,
                                   lambda: self.loop.time) if cfg.camera.enabled else None
        #: the emulated leak detector of a simulated robot without devices.leak.path (fault injection)
        self.leak_emulator = self.sensors.emulator("leak")
        self.rig_control = RigControl(RigHost(
            robot=cfg.robot, rig=self.rig, gate=self.gate, require_pilot=self.access.require_pilot,
            in_loop=self._in_loop, publish_event=self._publish_event, notify=self._notify,
            leak=self._set_leak if self.leak_emulator is not None else None,
        ))
        #: what an identification manoeuvre uses: the operator's commands, checked as any
        self.manoeuvre_host = ManoeuvreHost(
            require_pilot=self.access.require_pilot, armed=lambda: self.gate.armed, mode=lambda: self.loop.mode,
            set_mode=self.set_mode, recording=lambda: self.recording.session_id,
            start_recording=self.start_recording, stop_recording=self.stop_recording,
            add_marker=self.add_marker, time=lambda: self.loop.time, duration=cfg.loop.manoeuvre.duration,
        )
        #: what a scripted manoeuvre uses: the operator's commands, checked as any
        self.script_host = ScriptHost(
            require_pilot=self.access.require_pilot, is_pilot=self.access.is_pilot, armed=lambda: self.gate.armed,
            failsafes=self.safety.active, mode=lambda: self.loop.mode, set_mode=self.set_mode,
            setpoints=lambda: self.loop.setpoints, set_setpoints=self.set_setpoints,
            recording=lambda: self.recording.session_id, start_recording=self.start_recording,
            stop_recording=self.stop_recording, add_marker=self.add_marker,
            publish_event=lambda ev: self.stream.publish(ch.EVENTS, ev), subscribe=self.stream.subscribe,
            time=lambda: self.loop.time, metrics=cfg.metrics,
        )
        #: the scripted manoeuvre last started (None: none yet)
        self.script_run: ScriptRun | None = None
        #: what a seek of efficiency uses: the pilot's tuning, checked as any
        self.seek_host = SeekHost(
            require_pilot=self.access.require_pilot, is_pilot=self.access.is_pilot, armed=lambda: self.gate.armed,
            failsafes=self.safety.active, param_field=param_field, param_value=self.param_value,
            set_params=self.set_params, journal=self.journal_log.add,
            publish_event=lambda ev: self.stream.publish(ch.EVENTS, ev), subscribe=self.stream.subscribe,
            time=lambda: self.loop.time, metrics=cfg.metrics, off_track=self.safety.off_track,
            tracking_timeout=cfg.failsafe.tracking.timeout, restart_expected=self.safety.restart_expected,
        )
        #: the seek of efficiency last started (None: none yet)
        self.seek_run: SeekRun | None = None
        #: each tuning, mode or setpoint change with the figures before and after it
        self.effects = ChangeEffects(cfg.metrics, lambda ev: self.stream.publish(ch.EVENTS, ev))
        self._thread: threading.Thread | None = None
        #: the loop's watchdog (its thread runs with the loop's, :meth:`start`, under a paced
        #: clock only: under a simulated one the simulated robot stands still with the loop, so a
        #: loop the computer holds back for a while is no danger, only a slower run)
        self.watchdog = LoopWatchdog(cfg.failsafe.loop_watchdog.timeout, self._loop_stuck, self.safety.loop_resumed)
        self._unstall = threading.Event()
        self._stopping = False
        self._closed = False
        self._chunks = 0
        self._unsubs = [
            self.stream.subscribe_batches(self.safety.on_messages, safety_channels()),
            self.stream.subscribe_batches(self._on_bodies, [ch.BODY_STATE]),
            self.stream.subscribe(self.effects.on_message, self.effects.channels),
        ]
        add_telemetry = getattr(inner, "add_telemetry_sink", None)  # the drives' electrical input
        if add_telemetry is not None:
            self._unsubs.append(add_telemetry(self.stream.publish))
        self.access.add_listener(self._on_access)
        self.safety.sensors_open(tuple(self.sensors.sources), self.loop.time)
        self.sensors.start()  # once the failsafes hear them
        if self.camera is not None:
            self.camera.start()

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
        if self.clock.paced:
            self.watchdog.start()
        log.info("supervisor started (robot %s, mode %s)", self.cfg.robot, self.loop.mode)

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
        self.watchdog.stop()
        self._unstall.set()
        self._disarm(LOCAL, "shutdown")
        self.bursts.check(self.loop.time, flush=True)
        self._stopping = True
        self.loop.stop()
        if self._thread is not None:
            self._thread.join(timeout=10.0)
            if self._thread.is_alive():
                log.error("the loop thread did not stop within 10 s")
        else:
            self.gate.flush()
        self.loop.commands.fail_all("the supervisor is stopping")
        try:
            self.recorder.stop()
            if self.reports is not None and not self.reports.join(REPORT_WAIT):
                log.warning("the run report was not written within %g s of stopping; left unfinished", REPORT_WAIT)
        finally:
            for unsub in self._unsubs:
                unsub()
            self.sensors.close()
            if self.camera is not None:
                self.camera.close()
            self.run_library.close()
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
            self.loop.commands.fail_all("the loop is not running")

    def _chunk(self) -> None:
        """One chunk of ``supervise_period`` of loop time, with the supervisor's work at its
        start and end. A paced loop does the chunks' ends and starts where it waits for the
        clock anyway (:meth:`_between`), without returning; it returns (ending a chunk here)
        only when it has not waited for a whole period more, or is stopped. Commands are
        the loop's to take, at its next event."""
        self.gate.flush()
        self._chunks += 1
        period = self.cfg.console.supervise_period
        t_end = max(self._chunks * period, self.loop.time)
        if self.clock.paced:
            self.loop.run_until(t_end + period, between=self._between)
        else:
            self.loop.run_until(t_end)
        self._after_chunk()

    def _between(self, t: float) -> float:
        """At a wait of the paced loop (loop time ``t``): once the chunk's end is reached,
        the work of a chunk's end and of the next one's start, as :meth:`_chunk` does; the
        time the loop may run until without waiting (a period past the chunk's end)."""
        period = self.cfg.console.supervise_period
        self.watchdog.beat()
        if t >= self._chunks * period - 1e-9:
            self._after_chunk()
            self.gate.flush()
            self._chunks = max(self._chunks + 1, math.floor(t / period + 1e-9) + 1)
        return self._chunks * period + period

    def _in_loop(self, fn: Callable[[], Any], what: str = "") -> Any:
        """``fn()`` in the loop's thread (at once when no loop thread runs, or from it),
        submitted as :class:`LoopWork`; its answer. Not taken within ``loop_wait`` s, it is
        cancelled and never runs (CommandRefused "nothing was done")."""
        t = self._thread
        if t is None or threading.current_thread() is t:
            return fn()
        if not t.is_alive():
            raise CommandRefused(f"the loop is not running{': ' + self.fault if self.fault else ''}")
        fut = self.loop.submit(LoopWork(fn, what))
        try:
            return fut.result(timeout=self.loop_wait)
        except TimeoutError:
            if fut.cancel():  # not started: it never will be
                raise CommandRefused("the loop did not answer in time; nothing was done") from None
            return fut.result()  # started: wait for its answer

    def _after_chunk(self) -> None:
        self.watchdog.beat()
        now = self.loop.time
        clock = self.clock
        if isinstance(clock, PacedClock):
            self._lag = max(0.0, time.perf_counter() - clock.wall_deadline(now))
        self._expire_request()
        for tr in self.safety.check(now):
            self._on_failsafe(tr)
        self.bursts.check(now)
        self.effects.check(now)
        self.recording.check(now, self.gate.armed, faulted=bool(self.safety.active() or self.safety.motor_faults()))
        run = self.manoeuvre
        if run is not None and not run.finished:
            try:
                run.poll()
            except Exception:
                log.exception("finishing the identification manoeuvre failed")
        self._poll_script()
        self._poll_seek()

    def _poll_seek(self) -> None:
        run = self.seek_run
        if run is not None and not run.finished:
            try:
                if run.poll():
                    self._notify()
            except Exception as e:  # a candidate's change refused past its check: the seek ends there
                log.exception("the seek failed")
                run.finish(f"failed: {e}", keep=False)
                self._notify()

    def _poll_script(self) -> None:
        run = self.script_run
        if run is not None and not run.finished:
            try:
                if run.poll():
                    self._notify()
            except Exception as e:  # a segment's command refused: the manoeuvre ends there
                log.exception("the scripted manoeuvre failed")
                run.finish(f"failed: {e}")
                self._notify()

    # ================================================================== telemetry
    def _on_bodies(self, items: Any) -> None:
        self._last_body = items[-1][1]

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
            t=self.loop.time if t is None else t, armed=self.gate.armed, mode=self.loop.mode,
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
        """The commanded mode (the loop's)."""
        return self.loop.mode

    @property
    def setpoints(self) -> BodySetpoints:
        """The commanded setpoints (the loop's)."""
        return self.loop.setpoints

    def tuning(self) -> dict[str, Any]:
        """The commanded tuning: each tunable block (``backend.loop.blocks``) -> its config."""
        return self.tuning_state.blocks()

    def param_value(self, key: str) -> Any:
        return self.tuning_state.value(key)

    def saved_tuning(self) -> dict[str, Any]:
        return self.tuning_state.saved()

    def journal(self, last: int | None = None) -> list[JournalEntry]:
        return self.journal_log.last(last)

    def health(self) -> Health:
        clock = self.clock
        lag_max = clock.lag_max if isinstance(clock, PacedClock) else 0.0
        pilot = self.access.pilot
        return Health(
            t=self.loop.time, mode=self.loop.mode, armed=self.gate.armed, lag=self._lag,
            lag_max=max(lag_max, self._lag), late_plans=self.loop.late_plans,
            plan_overruns=self.loop.plan_overruns, failsafes=self.safety.active(),
            clients=len(self.access.clients), pilot="" if pilot is None else actor_name(pilot),
            recording=self.recording.session_id, fault=self.fault,
            recording_failed=self.recording.failed, stalls=self.loop.stalls,
        )

    def state(self) -> ConsoleState:
        """The console as the page shows it, now: an immutable snapshot of values
        (:mod:`~.console_state`; built on each call, taking no lock of the supervisor's)."""
        return build_state(self)

    @property
    def sessions_dir(self) -> Path:
        """Where the recorder writes its sessions."""
        return self.recorder.directory

    def current_config(self) -> AppConfig:
        """The configuration in force (the file's, with the live tuning applied)."""
        cfg = configured(self.cfg, self.tuning())
        return cfg.replace(loop=cfg.loop.replace(mode=self.loop.mode))

    def _weights(self) -> dict[str, float]:
        m = self.tuning()["mpc"]
        return {"lam_f": m.lam_f, "lam_st": m.lam_st, "lam_a": m.lam_a, "lam_d": m.lam_d}

    # ================================================================== access
    def client_connected(self, client: int, address: str = "") -> None:
        """A page connected (from remote ``address``)."""
        self.access.connect(client, address)

    def client_disconnected(self, client: int, silent_for: float = 0.0) -> None:
        """A page is gone: its socket closed, or it has not answered for ``silent_for`` s.

        When it was the pilot's, nobody flies (a request made to it lapses) and the
        pilot-gone failsafe counts from the page's last sign of life (``silent_for`` s ago)."""
        self.arm_requests.cancel(client)
        asked = self.access.pending
        if not self.access.disconnect(client):
            return
        how = (f"has not answered for {silent_for:.1f} s" if silent_for > 0 else "is gone")
        self._publish_event("access", "pilot_left", f"the pilot's page (client {client}) {how}",
                            "warning", {"client": client, "silent_for": silent_for})
        self.safety.pilot_left(now=max(self.loop.time - silent_for, 0.0))
        if asked is not None and asked != client:
            self._publish_event("access", "request_lapsed",
                                f"client {asked}'s request for control lapsed: the pilot's page is gone; "
                                "the pilot token takes control at once", "info", {"client": asked})

    def _expire_request(self) -> None:
        """A request for control not handed over within ``access.handover_timeout`` lapses."""
        lapsed = self.access.expire()
        if lapsed is not None:
            self._publish_event("access", "request_lapsed",
                                f"client {lapsed}'s request for control lapsed: not handed over within "
                                f"{self.cfg.access.handover_timeout:g} s", "info", {"client": lapsed})

    def is_pilot(self, who: Actor) -> bool:
        """Whether ``who`` is the pilot (or the console itself), now."""
        return self.access.is_pilot(who)

    def require_pilot(self, who: Actor, action: str) -> None:
        """AccessDenied unless ``who`` is the pilot: the check of a page's own pilot-only
        action (its plots' window, repairing a session file)."""
        self.access.require_pilot(who, action)

    def set_name(self, client: int, name: object) -> None:
        """Page ``client``'s own name, shown to the others when it flies."""
        self.access.set_name(client, name)

    def note_gamepad(self, who: Actor, driving: bool) -> None:
        """Journal the start (``driving``) or the end of the pilot's gamepad driving (its
        setpoints are not journalled one by one)."""
        self.access.require_pilot(who, "gamepad")
        name = actor_name(who)
        self.journal_log.add(name, "gamepad", *(("off", "driving") if driving else ("driving", "off")))

    def may_replay(self, who: Actor) -> bool:
        """CommandRefused unless ``who`` may start a counterfactual replay now: any page while
        the robot is disarmed, only the pilot while it is armed (the replay takes CPU); True
        for the pilot (whose replay cancels another page's running one)."""
        pilot = who is not None and self.access.is_pilot(who)
        if self.gate.armed and not pilot:
            raise CommandRefused("counterfactual replay: while the robot is armed only the pilot may start one")
        return pilot

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
        self.arm_requests.clear()
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
        return self.arm_requests.request(who)

    def cancel_arm(self, who: Actor) -> None:
        self.arm_requests.cancel(who)

    def confirm_arm(self, who: Actor, nonce: object) -> None:
        """Second step of arming: the motors move from now on."""
        self.access.require_pilot(who, "arm")
        self.arm_requests.confirm(who, nonce)
        self._check_can_arm()
        self._in_loop(lambda: self._do_arm(who), "arm")

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
        try:  # a failsafe that triggered while the drives came up (the loop watchdog) refuses too
            self._check_can_arm()
        except CommandRefused:
            self.gate.stop_drives()
            raise
        try:  # first, so the recording holds the moment of arming
            self.recording.armed()
        except Exception as e:  # recording must never stop arming
            log.exception("automatic recording failed")
            self._publish_event("recorder", "start_failed", f"recording did not start: {e}", "error")
        self.loop.submit(Restart())  # nothing the loop did while the fins were held carries over
        self.gate.arm()
        self._armed_at = self.loop.time
        self._publish_event("supervisor", "armed", f"motors armed by {actor_name(who)}", "warning",
                            {"who": str(who)})
        self._publish_status()
        self._notify()

    def disarm(self, who: Actor, reason: str = "operator") -> None:
        """Motors off at once (the pilot, the console, or a failsafe)."""
        self.access.require_pilot(who, "disarm")
        self._disarm(who, reason)

    def _disarm(self, who: Actor | str, reason: str, at_once: bool = False) -> None:
        """``at_once``: the drives are turned off from this thread (the loop's is stuck),
        not at the loop's next step."""
        was = self.gate.armed
        self.gate.disarm()
        if at_once and self.gate.has_drives and not self.gate.stop_drives():
            log.error("a fin drive did not confirm its stop (see its events)")
        self.arm_requests.clear()
        self._poll_script()  # a scripted manoeuvre stops at once, before the recording's tail counts
        self._poll_seek()
        if was:
            self._armed_at = None
            self.recording.disarmed(self.loop.time)
            self._publish_event("supervisor", "disarmed", f"motors disarmed ({reason})", "warning",
                                {"who": str(who), "reason": reason})
            self._publish_status()
            self._notify()

    # ================================================================== failsafes
    def _loop_stuck(self, silent_for: float) -> None:
        """The watchdog's thread: the loop has not stepped for ``silent_for`` s."""
        tr = self.safety.loop_stuck(silent_for)
        if tr is not None:
            self._on_failsafe(tr, at_once=True)

    def stall_loop(self, who: Actor, seconds: object) -> None:
        """Fault injection on a simulated robot: the loop's thread is held for ``seconds``
        s at its next chunk (the loop watchdog's trigger). The caller does not wait."""
        self.access.require_pilot(who, "stall the loop")
        if not self.cfg.simulated:
            raise CommandRefused(f"stall the loop: only on a simulated robot (this one is {self.cfg.robot!r})")
        s = number("seconds", seconds, False)
        if not 0.0 < s <= 60.0:
            raise CommandRefused(f"stall the loop: seconds {s:g} outside (0, 60]")
        self._unstall.clear()
        self.loop.submit(LoopWork(lambda: self._unstall.wait(s), "stall"))

    def inject_leak(self, who: Actor, water: object) -> None:
        """Fault injection on a simulated robot: water at the emulated leak detector, or dry
        (on the rig also ``inject_fault(who, "leak", "water")``, the Safety tab's rig faults)."""
        self.access.require_pilot(who, "leak")
        if self.leak_emulator is None:
            raise CommandRefused("leak: no emulated leak detector (only a simulated robot without "
                                 "devices.leak.path has one)")
        if not isinstance(water, bool):
            raise CommandRefused(f"leak: expected true (water) or false (dry), got {water!r}")
        self._set_leak(water)

    def _set_leak(self, water: bool) -> Event:
        assert self.leak_emulator is not None
        self.leak_emulator.set(water)
        return self._publish_event("rig", "fault_injected" if water else "fault_cleared",
                                   f"leak: {'water' if water else 'dry'} at the emulated detector", "info",
                                   {"device": "leak", "fault": "water", "water": water})

    def _on_failsafe(self, tr: Transition, at_once: bool = False) -> None:
        """Carry out a failsafe's action; ``at_once``: from a thread other than the loop's,
        which is stuck (a disarm turns the drives off from here)."""
        rule = self.safety.rule(tr.name)
        if tr.active:
            data = {"action": tr.action, "timeout": rule.timeout, "cause": tr.cause}
            if tr.escalated:
                message = (f"{tr.name}: {tr.cause}; escalated after {rule.escalate_after:g} s of "
                           f"{rule.action}: {tr.action}")
                data.update(escalated=True, escalate_after=rule.escalate_after, before=rule.action)
            else:
                message = f"{tr.name}: {tr.cause}; action: {tr.action}"
            self._publish_event("failsafe", tr.name, message, "error", data)
            if tr.action == "disarm":
                self._disarm("failsafe", f"failsafe {tr.name}", at_once)
            elif tr.action in ("hold", "surface"):
                if tr.action == "hold":
                    body = self._last_body
                    depth = body.depth if body is not None and math.isfinite(body.depth) else self.loop.setpoints.depth
                    depth = round(min(max(depth, 0.0), self.cfg.loop.max_depth), 3)  # to the mm
                else:
                    depth = 0.0
                self._submit_setpoints(SetSetpoints(0.0, depth, 0.0), f"failsafe {tr.name}")
            self._poll_seek()  # a seek stops at once
        else:
            self._publish_event("failsafe", "cleared", f"{tr.name} cleared", "info", {"failsafe": tr.name})
        self._publish_status()
        self._notify()

    def _holding(self) -> list[str]:
        return [s.name for s in self.safety.states() if s.active and s.action in ("hold", "surface")]

    # ================================================================== commands
    def set_mode(self, who: Actor, mode: object) -> None:
        self.access.require_pilot(who, "mode")
        command = SetMode(mode, actor_name(who))  # type: ignore[arg-type]  # checked here; its event names who
        with self._lock:
            old = self.loop.mode
            if mode == old:
                return
            self.loop.submit(command)
        self.journal_log.add(actor_name(who), "mode", old, mode)
        self._publish_status()
        self._notify()

    def set_setpoints(self, who: Actor, velocity: object = None, depth: object = None,
                      yaw_rate: object = None, quiet: bool = False) -> None:
        """New setpoints (unchanged where None), inside the loop's envelope; ``quiet``: not
        journalled or announced one by one (a gamepad sends several a second; the loop
        still records every setpoint on its Setpoints channel)."""
        self.access.require_pilot(who, "setpoints")
        command = SetSetpoints(velocity, depth, yaw_rate)  # type: ignore[arg-type]  # checked here
        holding = self._holding()
        if holding:
            raise CommandRefused(
                f"setpoints: failsafe {', '.join(holding)} holds the setpoints until its cause clears"
            )
        self._submit_setpoints(command, actor_name(who), quiet)

    def _submit_setpoints(self, command: SetSetpoints, who: str, quiet: bool = False) -> None:
        with self._lock:
            old = self.loop.setpoints
            self.loop.submit(command)  # the envelope checked there
            sp = self.loop.setpoints
        changes = {}
        for k in SETPOINTS:
            a, b = getattr(old, k), getattr(sp, k)
            if a != b:
                changes[k] = [a, b]
                if not quiet:
                    self.journal_log.add(who, f"setpoint.{k}", a, b)
        if changes and not quiet:
            self._publish_event("operator", "setpoints", f"{who}: " + ", ".join(
                f"{k} {fmt(v[0])} -> {fmt(v[1])}" for k, v in changes.items()), "info",
                {"who": who, "changes": changes})
        self._notify()

    def set_params(self, who: Actor, changes: Mapping[str, object]) -> None:
        """Apply ``{"mpc.lam_st": 2.0, "pid.depth.kp": 4.0, ...}`` together, or none of them."""
        self.access.require_pilot(who, "tuning")
        name = actor_name(who)
        self._apply_tuning(self.tuning_state.check(changes, name), name)

    def set_param(self, who: Actor, key: str, value: object) -> None:
        self.set_params(who, {key: value})

    def _apply_tuning(self, commands: Mapping[str, Any], who: str) -> None:
        if self.tuning_state.apply(commands, who):  # the loop's event of each block names who
            self._notify()

    def save_baseline(self, who: Actor) -> None:
        """The present tuning becomes the one to revert to."""
        self.access.require_pilot(who, "save tuning")
        self.tuning_state.save(actor_name(who))
        self._notify()

    def revert_tuning(self, who: Actor) -> None:
        """Back to the saved tuning in one step (journalled like any change)."""
        self.access.require_pilot(who, "revert tuning")
        name = actor_name(who)
        self._apply_tuning(self.tuning_state.commands(self.saved_tuning(), name), name)

    def undo_tuning(self, who: Actor) -> None:
        """The latest tuning change undone in one step: the parameters it changed back to
        their values before it (journalled like any change, so a second undo redoes it)."""
        self.access.require_pilot(who, "undo tuning")
        changes = [e for e in self.journal() if is_tuning_key(e.key)]
        if not changes:
            raise CommandRefused("undo: no tuning change to undo")
        last = changes[-1]
        self.set_params(who, {e.key: e.old for e in changes if (e.t, e.who) == (last.t, last.who)})

    # ================================================================== recording and markers
    def start_recording(self, who: Actor, notes: object = "") -> str:
        self.access.require_pilot(who, "record")
        sid = self.recording.start(notes)
        self._publish_event("operator", "recording", f"{actor_name(who)} started recording {sid}", "info",
                            {"session": sid})
        self._notify()
        return sid

    def stop_recording(self, who: Actor) -> list[Path]:
        """Stop recording; after a failed write, acknowledge the failure (the recorder's
        failure_cleared event clears the recording failsafe)."""
        self.access.require_pilot(who, "record")
        if self.recording.failed:
            paths = self.recording.stop()
            self._notify()
            return paths
        if not self.recording.recording:
            raise CommandRefused("record: not recording")
        self._publish_event("operator", "recording", f"{actor_name(who)} stopped recording "
                            f"{self.recorder.session_id}", "info", {"session": self.recorder.session_id})
        paths = self.recording.stop()
        self._notify()
        return paths

    # ================================================================== the run library
    def refresh_runs(self) -> None:
        """Bring the run library up to the sessions folder (reads the new sessions' files:
        call it off the page's message handler)."""
        self.run_library.refresh()

    def find_runs(self, query: object = "", sort: object = "start", desc: object = False) -> list[RunView]:
        """The runs matching ``query`` (the library's query language), sorted; ValueError
        naming a bad query, sort or direction (any page may search)."""
        return self.run_library.find(query, sort, desc)

    def run_view(self, session_id: object) -> RunView:
        """One run of the library (ValueError when it has none)."""
        return self.run_library.view(self.run_library.get(session_id))

    def _run_editor(self, who: Actor, action: str) -> str:
        """Who writes tags or notes, as the journal names them: the pilot, or a page that has
        given its name (AccessDenied for any other)."""
        if self.access.is_pilot(who):
            name = self.access.name(who) if isinstance(who, int) else ""
            return f"{name} ({actor_name(who)})" if name else actor_name(who)
        name = self.access.name(who) if isinstance(who, int) else ""
        if not name:
            raise AccessDenied(f"{action}: give your name first (Your name), or take control")
        return f"{name} ({actor_name(who)})"

    def set_run_tags(self, who: Actor, session_id: object, changes: object) -> tuple[str, ...]:
        """Add (``+tag``) and remove (``-tag``) tags of a recorded session (the pilot, or a page
        with a name); journalled; the tags now."""
        name = self._run_editor(who, "tags")
        old, new = self.run_library.set_tags(session_id, changes)
        self.journal_log.add(name, f"session {session_id} tags", " ".join(old) or "(none)", " ".join(new) or "(none)")
        self.runs_version += 1
        self._notify()
        return new

    def set_run_notes(self, who: Actor, session_id: object, notes: object) -> str:
        """Replace a recorded session's notes (the pilot, or a page with a name); journalled;
        the notes now."""
        name = self._run_editor(who, "notes")
        old, row = self.run_library.set_notes(session_id, notes)
        self.journal_log.add(name, f"session {session_id} notes", _short(old), _short(row.notes))
        self.runs_version += 1
        self._notify()
        return row.notes

    def trend_runs(self, query: object, figure: object, by: object) -> list[Any]:
        """A figure of the runs matching ``query`` by day or by a recorded MPC weight
        (``backend.review.trend``'s choices); ValueError naming a bad query, figure or axis
        (any page may look)."""
        return self.run_library.trend(query, figure, by)

    def run_report(self, session_id: object) -> Path | None:
        """The report file of a recorded session (None: it has none)."""
        return self.run_library.report(session_id)

    def add_marker(self, who: Actor, note: object = "") -> Event:
        """A marker with a note on the events channel (recorded when recording)."""
        self.access.require_pilot(who, "marker")
        if not isinstance(note, str) or len(note) > MAX_MARKER_NOTE:
            raise CommandRefused(f"marker: the note must be text of at most {MAX_MARKER_NOTE} characters")
        ev = self._publish_event("operator", "marker", note or "marker", "info",
                                 {"note": note, "who": str(who)})
        self._notify()
        return ev

    # ================================================================== identification
    def start_manoeuvre(self, who: Actor) -> ManoeuvreRun:
        """The identification manoeuvre, recorded (pilot, armed; one at a time); it ends by
        itself (its steps done, or the robot disarmed) and its session is then fitted with
        ``backend.identification.identify_sessions``; :meth:`ManoeuvreRun.wait` waits for
        its end."""
        with self._lock:
            if self.manoeuvre is not None and not self.manoeuvre.finished:
                raise CommandRefused("identification manoeuvre: one is running")
            if self.script_run is not None and not self.script_run.finished:
                raise CommandRefused(f"identification manoeuvre: manoeuvre {self.script_run.name} is running")
            if self.seek_run is not None and not self.seek_run.finished:
                raise CommandRefused("identification manoeuvre: a seek is running")
            run = ManoeuvreRun(self.manoeuvre_host, who)
            run.start()
            self.manoeuvre = run
        self._notify()
        return run

    def stop_manoeuvre(self, who: Actor) -> list[Path]:
        """End the running manoeuvre now (pilot): the previous mode back, the recording kept."""
        self.access.require_pilot(who, "identification manoeuvre")
        run = self.manoeuvre
        if run is None or run.finished:
            raise CommandRefused("identification manoeuvre: none is running")
        paths = run.finish()
        self._notify()
        return paths

    # ================================================================== scripted manoeuvres
    def start_script(self, who: Actor, script: Script) -> ScriptRun:
        """A scripted manoeuvre (pilot, armed, no failsafe active; one at a time, not beside
        the identification manoeuvre), recorded; it ends by itself (its segments done, or
        the robot disarmed, a failsafe, the pilot gone: ``ScriptRun.reason`` says which)."""
        self.access.require_pilot(who, f"manoeuvre {script.name}")
        with self._lock:
            for running in (self.script_run, self.manoeuvre):
                if running is not None and not running.finished:
                    raise CommandRefused(f"manoeuvre {script.name}: a manoeuvre is running; stop it first")
            if self.seek_run is not None and not self.seek_run.finished:
                raise CommandRefused(f"manoeuvre {script.name}: a seek is running; stop it first")
            run = ScriptRun(self.script_host, who, script)
            run.start()
            self.script_run = run
        self._notify()
        return run

    def stop_script(self, who: Actor) -> list[Path]:
        """End the running scripted manoeuvre now (pilot): what it found put back."""
        self.access.require_pilot(who, "manoeuvre")
        run = self.script_run
        if run is None or run.finished:
            raise CommandRefused("manoeuvre: none is running")
        paths = run.finish(f"stopped by {actor_name(who)}")
        self._notify()
        return paths

    # ================================================================== seeking efficiency
    def start_seek(self, who: Actor, params: tuple[str, ...] = (), candidates: int | None = None,
                   seed: int | None = None, confirm: int | None = None) -> SeekRun:
        """Seek efficiency over ``params`` (the configured ``[[seek.params]]`` names; all
        when empty), ``candidates``, ``seed`` and ``confirm`` overriding the configuration's (pilot, armed,
        no failsafe active; one at a time, not beside a manoeuvre); docs/seek.md."""
        self.access.require_pilot(who, "seek")
        cfg = self.cfg.seek
        try:
            names = tuple(params)
            if not all(isinstance(n, str) for n in names):
                raise ValueError(f"params: expected parameter names, got {params!r}")
            changes: dict[str, Any] = {}
            if candidates is not None:
                changes["max_candidates"] = number("candidates", candidates, True)
            if seed is not None:
                changes["seed"] = number("seed", seed, True)
            if confirm is not None:
                changes["confirm"] = number("confirm", confirm, True)
            cfg = cfg.replace(**changes)
            cfg.only(names)
        except (TypeError, ValueError) as e:
            raise CommandRefused(f"seek: {e}") from None
        with self._lock:
            for running in (self.script_run, self.manoeuvre, self.seek_run):
                if running is not None and not running.finished:
                    raise CommandRefused("seek: a manoeuvre or a seek is running; stop it first")
            run = SeekRun(self.seek_host, who, cfg, names)
            run.start()
            self.seek_run = run
        self._notify()
        return run

    def stop_seek(self, who: Actor, keep: bool) -> None:
        """End the running seek now (pilot): the best in force (``keep``), else the values
        it found."""
        self.access.require_pilot(who, "seek")
        if not isinstance(keep, bool):
            raise CommandRefused(f"seek: keep must be true or false, got {keep!r}")
        run = self.seek_run
        if run is None or run.finished:
            raise CommandRefused("seek: none is running")
        run.finish(f"stopped by {actor_name(who)}", keep=keep)
        self._notify()

    # ================================================================== the robot's devices
    @property
    def has_drives(self) -> bool:
        """The fins are moved by motor drives (the robot, or the rig's emulated EPOS2s)."""
        return self.gate.has_drives

    def fault_tables(self) -> tuple[dict[str, tuple[str, ...]], int]:
        """(the faults each emulated device takes, the default EMCY code); CommandRefused
        when the robot is not the simulated rig."""
        return self.rig_control.fault_tables()

    def inject_fault(self, who: Actor, device: object, fault: object, **kw: Any) -> Event:
        return self.rig_control.inject_fault(who, device, fault, **kw)

    def clear_fault(self, who: Actor, device: object, fault: object = None) -> None:
        self.rig_control.clear_fault(who, device, fault)

    def reset_drive_faults(self, who: Actor) -> None:
        self.rig_control.reset_drive_faults(who)

    def zero_depth(self, who: Actor) -> float:
        return self.rig_control.zero_depth(who)


def _short(text: str, most: int = 60) -> str:
    """Notes as the journal shows them (the first ``most`` characters)."""
    one = " ".join(text.split())
    return "(none)" if not one else one if len(one) <= most else one[: most - 1] + "…"
