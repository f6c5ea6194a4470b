"""The closed loop: body-frame PIDs -> allocation -> fin planners -> executors -> robot.

One :class:`ClosedLoop` runs everything between the robot's readings and its fin
commands (control.md sections 7-9)::

    readings --> BodyController (median filters, PIDs) --> allocate --> per-fin targets
    FinFeedback --> FinExecutor (Algorithm 2) --> SendToServo --> RobotIO.command_fin
                      | PlanRequest                  ^ plan at t + plan_latency
                      v                              |
                   planner (the mode's: ``modes``), inline or in its own thread

and publishes what it does on a :class:`TelemetryStream` (channels of
``telemetry.channels``): sensors as sampled, BodyState / FinState / BodyCommand at
``state_rate`` / ``control_rate``, Power at ``power_rate``, each plan as it is made
(``FinPlan`` with every planner input), Setpoints and Status on change and at
``status_rate``, and Events (``mode``, ``tuning``, ``late_plan``, ``plan_overrun``,
``stroke_timeout``, ``stall``).

It is made of parts, each in its module, this one holding the run loop and putting them
together:

* ``commands``, ``command_channel``: what the supervisor and the page ask (mode,
  setpoints, tuning, restart, the supervisor's work in the loop's thread), typed commands
  checked in the caller's thread, submitted (:meth:`ClosedLoop.submit`) and applied by the
  loop's thread at its next event;
* the run loop (here): the compiled core's steps and what the loop does in Python between
  them;
* ``actuators``: each logical fin's executor and planner, the plan hand-over, the mode
  switch;
* ``outbox``: the telemetry out (the core's rows as messages, events, plans, status);
* ``modes``: the registry of fin controllers, ``planners``: the planners and where they run.

Per sample, compiled. Everything the loop does on every sample (the readings into the
estimate and the body-frame loops, the power estimate, the executors' stroke-end watch,
the control ticks, the telemetry ticks' numbers) and the scheduling of its events is the
compiled core's, ``control.loop_core``, on arrays this class owns. The core returns here
only when Python has something to do: an executor saw a stroke end (it sends the next
stroke, or asks for a plan), a plan is due, a status tick, the robot's readings (unless the
robot runs the core itself: the simulator, ``RobotIO.run_core``), telemetry to publish. So
the loop's Python runs a few times a second per fin, not on every sample.

Time. Everything happens at simulated event times: sensor samples (the robot says when the
next is due), control / telemetry ticks, and plan hand-overs. A plan requested at ``t`` is
handed to its executor at ``t + plan_latency``, whatever the clock, so the headless clock
(planners inline) and the paced clock (one planner thread per logical fin, waiting for a
thread that is not done) give the same trajectory for the same seed. A plan the fins needed
(driving, for the fins in control) whose solve took longer than the hand-over allows
(headless: solve time > plan_latency; paced: the loop reached the hand-over and waited for
the plan past its wall-clock deadline) is counted in ``plan_overruns``; a plan done before
a late loop got to its hand-over kept nobody waiting and is not. A plan arriving after its
fin went idle is counted in ``late_plans`` (the executor's LatePlan). Neither stalls the
loop in simulated time. A paced loop held back beyond the clock's ``max_lag`` skips ahead
(``clock``): counted in ``stalls``, an Event ``stall``. The first plans wait until the body
controller has had a DVL report and a depth: a fin never starts a stroke from a command that
assumed either (a DVL without bottom lock counts as reported: its fault is then shown and
the depth loop runs).

Mode switches are bumpless (``actuators``): a fin's stroke in flight is never interrupted.
Tuning (a tunable block of ``blocks``: MPC weights, PID gains, ...) applies from the next
plan / PID step. Commands may be submitted from any thread: they are validated at once and
applied by the loop's thread at its next event (``command_channel``).

Estimation: the attitude comes from the IMU's own filter, or from the core's EKF
(``control.estimation``, run here on each IMU reading when configured); dead reckoning is
the core's.

Fins: the controller uses the paper's order (0 front-starboard, 1 front-port,
2 rear-starboard, 3 rear-port); the robot and the telemetry use the robot's order,
mapped by ``robot.fins.PAPER_TO_ROBOT``.
"""

from __future__ import annotations

import math
from concurrent.futures import Future
from typing import Any, Callable

import numpy as np

from ucat_console.backend.loop import blocks as tunable
from ucat_console.backend.loop.actuators import Actuators, kept_waiting
from ucat_console.backend.loop.clock import Clock, SimulatedClock
from ucat_console.backend.loop.command_channel import CommandChannel
from ucat_console.backend.loop.commands import LoopCommand, check_setpoints, pid_loop
from ucat_console.backend.loop.config import LoopConfig
from ucat_console.backend.loop.modes import MODES
from ucat_console.backend.loop.outbox import Outbox
from ucat_console.backend.loop.planners import Planner, PlanningService, ThreadedPlanning
from ucat_console.control import loop_core as lc
from ucat_console.control.allocation import BodySetpoints
from ucat_console.control.argcheck import finite
from ucat_console.control.body import BODY_FIELDS, EARLIER_T, BodyController
from ucat_console.control.estimation import AttitudeEstimator
from ucat_console.control.params import BaselineConfig, MpcConfig, PidGains
from ucat_console.control.power import P_T, PowerBank, drag_coefficient
from ucat_console.control.stroke_watch import StrokeWatches
from ucat_console.robot import reading_rows as rr
from ucat_console.robot.fins import N_FINS
from ucat_console.robot.interface import RobotIO, RobotTruth
from ucat_console.robot.readings import DepthReading, ImuReading, Reading
from ucat_console.telemetry.messages import Status
from ucat_console.telemetry.stream import TelemetryStream

__all__ = ["ClosedLoop", "check_setpoints", "kept_waiting"]


class ClosedLoop:
    """The controller side of the robot, driven by a :class:`Clock` (module docstring)."""

    def __init__(
        self,
        cfg: LoopConfig,
        io: RobotIO,
        stream: TelemetryStream | None = None,
        clock: Clock | None = None,
        *,
        setpoints: BodySetpoints | None = None,
        source: str = "sim",
        driving: Callable[[], bool] | None = None,
        status: Callable[[float], Status] | None = None,
        mpc_planner: Callable[[int], Planner] | None = None,
    ) -> None:
        self.cfg = cfg
        # the Status message at time t: the supervisor's (armed, pilot, failsafes) when one
        # runs this loop, else what the loop knows (driving, no pilot, no failsafes)
        self._status = status or self._own_status
        # whether the fins are being driven (the supervisor: armed); the distance travelled
        # and the fins' energy and mean power count only then, not DVL noise or drift at rest
        self._driving = driving or (lambda: True)
        self.io = io
        self.stream = stream if stream is not None else TelemetryStream()
        self.clock = clock if clock is not None else SimulatedClock()
        self._planning: PlanningService = ThreadedPlanning() if self.clock.threaded else PlanningService()
        self._source = source
        self.body = BodyController(cfg.body, cfg.mpc, cfg.executor)
        self.commands = CommandChannel(cfg, setpoints or BodySetpoints(), self)
        # in force (the loop's thread); the commanded ones are the channel's
        self._setpoints = self.commands.commanded.setpoints
        self._mode = cfg.mode
        self._blocks = dict(self.commands.commanded.blocks)  # tunable block -> config in force
        self._stop = False
        self._power = PowerBank(cfg.power, N_FINS)  # rows: robot order
        # the executors' stroke-end table (rows: paper order) and, per fin, the rows of the
        # executor that owns it (checked after each of its samples, as that executor would)
        watches = StrokeWatches(cfg.executor, N_FINS)
        members = np.full((N_FINS, 2), -1, dtype=np.int64)
        self._found = np.zeros(2, dtype=np.int64)
        # the per-sample core (control.loop_core): the estimate, the body-frame loops, the
        # power estimate, the stroke ends and the schedule, on these arrays
        pcfg = cfg.power
        self._core = lc.LoopCore(
            self.body.state, watches.table, members, self._found, self._power.table,
            rates=(cfg.control_rate, cfg.state_rate, cfg.power_rate, cfg.status_rate),
            w_th=watches.w_th, min_time=watches.min_time, k_drag=drag_coefficient(pcfg),
            inertia=float(pcfg.fin_inertia), tau=float(pcfg.filter_tau))
        self._s = self._core.s
        self._attitude = AttitudeEstimator()
        self._ekf = cfg.attitude != "imu"
        self._fed: list[Reading] = []  # the event's readings as objects (a robot running the core gives rows)
        lc.set_targets(self._s, self.body.state, self._sync)
        self.stalls = 0
        self.outbox = Outbox(self.stream)
        # looked up at each call: a caller may wrap the robot's command_fin or replace driving
        self.fins = Actuators(cfg, self._s, members, watches, self._planning, self.outbox, self._command_fin,
                              self.clock.wall_deadline, lambda: self._driving(), mpc_planner,
                              on_cycle=lambda fin, target, force: self.body.on_cycle(fin, target, force, self._t),
                              on_executed=self._on_executed)
        self._scaled = False  # whether the body layer follows a measured force scale (its event said so)
        # the set-points the fins are actually sent: the robot's report (the arming gate:
        # those it passes on, and its stops), else each command as given
        self._sent_as_given = not io.report_sent(self.fins.sent)
        self.limit_fins()

    def _on_executed(self, fin: int, planned: tuple[float, float], executed: tuple[float, float]) -> None:
        """A fin finished a cycle: the body layer's correction, and whether it now follows a
        measured force scale (an event when it starts or stops: the fins are not the model)."""
        self.body.on_executed(fin, planned, executed)
        scale, measured = self.body.force_scale
        if (scale > 1.0) != self._scaled:
            self._scaled = scale > 1.0
            if self._scaled:
                self.outbox.event(self._t, "fin_force_scale", f"the fins make {measured:.1f} times the fin model's "
                                  "force: the body layer asks them for that much less; identify the fins "
                                  "(ucat-console identify --fit scale)", "warning", {"scale": measured})
            else:
                self.outbox.event(self._t, "fin_force_scale_cleared", f"the fins make {measured:.2f} times the fin "
                                  "model's force: the body layer asks them as the model says", "info",
                                  {"scale": measured})

    # ------------------------------------------------------------------ public state
    @property
    def time(self) -> float:
        """Simulated time of the last event processed (s)."""
        return float(self._s[lc.C_T])

    @property
    def _t(self) -> float:
        return float(self._s[lc.C_T])

    @property
    def distance(self) -> float:
        """Metres travelled while driving (dead reckoning)."""
        return float(self._s[lc.C_DISTANCE])

    @property
    def late_plans(self) -> int:
        return self.fins.late_plans

    @property
    def plan_overruns(self) -> int:
        return self.fins.plan_overruns

    @property
    def stroke_timeouts(self) -> int:
        return self.fins.stroke_timeouts

    @property
    def plans_made(self) -> int:
        return self.fins.plans_made

    # What the loop is commanded to do (``command_channel``); in force from its next event.
    # The loop is the one owner of these: the supervisor and the page read them here.
    @property
    def mode(self) -> str:
        return self.commands.commanded.mode

    @property
    def setpoints(self) -> BodySetpoints:
        return self.commands.commanded.setpoints

    def block_config(self, name: str) -> Any:
        """The commanded configuration of the tunable block ``name`` (``blocks``); a block
        registered after this loop was made: its value in the loop's configuration."""
        entry = tunable.block(name)
        now = self.commands.commanded.blocks
        return now[name] if name in now else entry.initial(self.cfg)

    @property
    def mpc_config(self) -> MpcConfig:
        return self.block_config("mpc")

    @property
    def baseline_config(self) -> BaselineConfig:
        return self.block_config("baseline")

    def pid_gains(self, loop: str) -> PidGains:
        """The gains of the body-frame PID ``loop`` ("velocity", "depth" or "yaw_rate")."""
        return self.block_config(f"pid.{pid_loop(loop)}")

    @property
    def planner_threads(self) -> int:
        """Planner threads started so far (0 when headless)."""
        return self._planning.threads if isinstance(self._planning, ThreadedPlanning) else 0

    def truth(self) -> RobotTruth | None:
        return self.io.truth()

    def fin_command(self, fin: int) -> tuple[float, float]:
        """(target angle, profile velocity) robot fin ``fin`` was last actually sent."""
        return float(self._s[lc.C_CMD_ANGLE + fin]), float(self._s[lc.C_CMD_RATE + fin])

    @property
    def _sync(self) -> bool:
        return MODES[self._mode].rear_synchronised

    # ------------------------------------------------------------------ commands (``commands``)
    def submit(self, command: LoopCommand) -> Future:
        """Queue ``command`` (``commands``: SetSetpoints, SetMode, SetBlock, Restart,
        LoopWork) for the loop's thread, from any thread: checked now (a refused one
        raises CommandRefused and changes nothing), commanded from now, applied at the next
        event; the Future answers what it returns (SetSetpoints, SetMode: what was in force
        before). Restart starts the body loops and every fin afresh, as at start-up (an
        Event with code "restarted"): the supervisor submits it on arming."""
        return self.commands.submit(command)

    def stop(self) -> None:
        """Make :meth:`run_until` return at its next event (any thread)."""
        self._stop = True
        self._s[lc.C_FLAGS] = int(self._s[lc.C_FLAGS]) | lc.F_STOP
        self.clock.interrupt()

    def close(self) -> None:
        """Stop the planner threads and release the robot."""
        self._planning.close()
        self.io.close()

    def __enter__(self) -> ClosedLoop:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # ------------------------------------------------------------------ commands applied (the loop's thread)
    def apply_setpoints(self, sp: BodySetpoints, t: float) -> BodySetpoints:
        old, self._setpoints = self._setpoints, sp
        self.outbox.setpoints(t, sp)
        return old

    def apply_mode(self, mode: str, t: float, who: str = "") -> str:
        old = self._mode
        if mode == old:
            return old
        self._mode = mode
        lc.retarget(self._s, self.body.state, self._sync)
        self.fins.switch(mode, t)
        self.limit_fins()
        self.outbox.event(t, "mode", f"{who + ': ' if who else ''}controller {old} -> {mode}", "info",
                          {"from": old, "to": mode, **({"who": who} if who else {})})
        self.fins.check_handovers(t)
        self._publish_status(t)
        return old

    def limit_fins(self) -> None:
        """The body layer fitted to the mode's planners in force: its allocation limits (a
        fixed beat frequency makes less than the fin model's deliverable force) and whether
        its loops follow the fins' cycle periods (``Mode.schedules_body``)."""
        self.body.set_fin_model(self.fins.blocks["mpc"], self.fins.force_limit(self._mode))
        self.body.set_scheduled(MODES[self._mode].schedules_body)

    def apply_block(self, block: str, cfg: Any, t: float, who: str) -> None:
        entry = tunable.block(block)
        old = self._blocks[block] if block in self._blocks else entry.initial(self.cfg)
        entry.apply(self, cfg)
        self._blocks[block] = cfg
        self.limit_fins()
        self.outbox.tuning_event(t, block, old, cfg, who)

    def apply_restart(self, t: float) -> None:
        self.body.reset()
        self.fins.restart(self._mode)  # the next control tick requests their first plans
        self.outbox.event(t, "restarted", "body loops and fins start afresh from the measured state",
                          "info", {"mode": self._mode})

    def _command_fin(self, fin: int, target: float, rate: float) -> None:
        self.io.command_fin(fin, target, rate)
        if self._sent_as_given:
            self.fins.sent(fin, target, rate)

    # ------------------------------------------------------------------ running
    def run(self, duration: float) -> None:
        """Run for ``duration`` simulated seconds from the present time."""
        if not math.isfinite(duration) or duration < 0.0:
            raise ValueError(f"duration: expected a finite duration >= 0 s, got {duration!r}")
        self.run_until(self._t + duration)

    def run_until(self, t_end: float, between: Callable[[float], float] | None = None) -> None:
        """Process every event up to simulated time ``t_end`` (s).

        The per-sample work is the compiled core's (``control.loop_core``): it runs the
        events and returns here only for what the loop does in Python (module docstring of
        the core), each handled below; a robot that can run the core itself (the simulator)
        does the sampling in compiled code too.

        ``between(t)``, when given, is called each time the loop is about to wait for the
        clock (a paced one: ``Clock.paced``), at loop time ``t``: its caller's work between
        two events, done without returning from here (a return and the next call cost the
        loop a step of its core). It returns the time to run until from then on, ``t_end``
        or a later one."""
        if not math.isfinite(t_end):
            raise ValueError(f"t_end: expected a finite time, got {t_end!r}")
        self._stop = False
        if self.clock.start(self._t):
            self.io.resync(self._t)
        s = self._s
        s[lc.C_T_END] = t_end
        s[lc.C_HORIZON] = math.inf
        paced = self.clock.paced
        if paced:
            s[lc.C_HORIZON] = self.clock.horizon(self._t)
        io = self.io
        runs_core = io.runs_core
        commands = self.commands
        fins = self.fins
        while True:
            self._inputs(commands.waiting)
            if runs_core and s[lc.C_ROWS_PENDING] == 0.0:
                st = io.run_core(self._core)
            else:
                if s[lc.C_ROWS_PENDING] != 0.0:
                    self._feed(io.advance_to(float(s[lc.C_T_NEXT])))
                    continue
                s[lc.C_T_ROBOT] = io.next_reading_time()
                st = self._core.step()
            if s[lc.C_OUT_N]:
                self.outbox.publish_rows(s, self._core.out, MODES[self._mode].follows_targets)
            if st == lc.END:
                break
            t = float(s[lc.C_T])
            if st == lc.READINGS:
                continue  # the robot's readings (above)
            if st == lc.WAIT:
                if between is not None:
                    t_end = between(t)
                    if not math.isfinite(t_end):
                        raise ValueError(f"between: expected a finite time to run until, got {t_end!r}")
                    s[lc.C_T_END] = t_end
                    if self._stop:
                        break
                self.clock.wait_until(float(s[lc.C_T_NEXT]))
                if self._stop:
                    break
                s[lc.C_HORIZON] = max(float(s[lc.C_T_NEXT]), self.clock.horizon(t))
            elif st == lc.STROKE:
                fins.stroke_checked(int(s[lc.C_STROKE_ROW]), float(s[lc.C_T_NOW]), self._found)
            elif st == lc.DELIVER:
                fins.deliver_due(t)
            elif st == lc.CONTROL:
                if self.body.sensors_reported:  # the first plans wait for the first DVL and depth reports
                    fins.request_first(t)
            elif st == lc.HANDOVER:
                fins.check_handovers(t)
            elif st == lc.STATUS:
                self._publish_status(t)
            elif st == lc.EKF:
                r = self._reading(int(s[lc.C_CURSOR]))
                assert type(r) is ImuReading
                s[lc.C_Q:lc.C_Q + 4] = self._attitude.update(r).q
            elif st == lc.COMMANDS:
                commands.drain(self._t)
            elif st == lc.OUTBOX:
                pass  # published above
            elif st == lc.ERROR:
                self._raise_core_error()
            else:
                raise RuntimeError(f"closed loop: the core returned {st}")
            if paced:
                s[lc.C_HORIZON] = max(float(s[lc.C_HORIZON]), self.clock.horizon(float(s[lc.C_T])))
                skipped = self.clock.take_skip()
                if skipped:
                    self._skipped(float(s[lc.C_T]), skipped)

    def _skipped(self, t: float, lag: float) -> None:
        """The paced clock skipped ``lag`` s of wall time at loop time ``t`` (a stall):
        the robot is told, and the stall is an event."""
        self.io.resync(t)
        self.stalls += 1
        self.outbox.event(t, "stall", f"the loop fell {lag:.2f} s behind the wall clock (the computer was busy); "
                          "it goes on from the present and skips the time it missed instead of replaying it",
                          "warning", {"late": lag})

    def _inputs(self, commands_waiting: bool) -> None:
        """What the core needs of the loop before a step: when plans are due, the flags."""
        s = self._s
        t_deliver, requests = self.fins.next_delivery()
        s[lc.C_T_DELIVER] = t_deliver
        flags = self.outbox.wanted_flags()
        if self.fins.handover:
            flags |= lc.F_HANDOVER
        if requests:
            flags |= lc.F_REQUESTS
        if self._driving():
            flags |= lc.F_DRIVING
        if self._sync:
            flags |= lc.F_SYNC
        if self._ekf:
            flags |= lc.F_EKF
        if commands_waiting:
            flags |= lc.F_COMMANDS
        if self._stop:
            flags |= lc.F_STOP
        s[lc.C_FLAGS] = flags
        sp = self._setpoints
        s[lc.C_SP_V], s[lc.C_SP_Z], s[lc.C_SP_R] = sp.velocity, sp.depth, sp.yaw_rate

    def _feed(self, readings: list[Reading]) -> None:
        """The robot's readings of the event, into the core's rows."""
        s = self._s
        rows = self._core.rows
        if len(readings) > rows.shape[0]:
            self._core.rows = rows = np.zeros((len(readings), rr.ROW))
        for k, r in enumerate(readings):
            rr.to_row(r, rows[k])
        self._fed = readings
        s[lc.C_NROWS] = len(readings)
        s[lc.C_ROWS_PENDING] = 0.0

    def _reading(self, k: int) -> Reading:
        """The event's reading ``k``: the robot's own object, or made from its row."""
        if self.io.runs_core:
            return rr.from_row(self._core.rows[k])
        return self._fed[k]

    def _raise_core_error(self) -> None:
        """The core refused a reading (or a control step): the ValueError naming what."""
        s = self._s
        code, what = int(s[lc.C_ERR_CODE]), int(s[lc.C_ERR])
        if code == lc.ERR_BODY and what == EARLIER_T:
            raise ValueError(f"t: {self._t!r} is earlier than the last update of a body-frame loop")
        r = self._reading(int(s[lc.C_CURSOR]))
        if code == lc.ERR_BODY:
            name = BODY_FIELDS[what]
            value = r.t if name.endswith(".t") else (
                r.gyro[2] if type(r) is ImuReading else r.depth_m if type(r) is DepthReading else r.vx)  # type: ignore[union-attr]
            finite(name, value)  # raises, naming the field
        if code == lc.ERR_POWER:
            raise ValueError(f"t: {r.t!r} is not after fin {what}'s last sample at "
                             f"{float(self._power.table[what, P_T])!r}")
        if code == lc.ERR_BACKWARDS:
            raise ValueError(f"fin {what}: feedback at t={r.t!r} is earlier than its last sample")
        raise ValueError(f"reading: the loop's core refused {r!r} (error {code})")

    # ------------------------------------------------------------------ telemetry
    def _own_status(self, t: float) -> Status:
        return Status(t=t, armed=self._driving(), mode=self._mode, pilot="", failsafes=(),
                      late_plans=self.late_plans, source=self._source)

    def _publish_status(self, t: float) -> None:
        self.outbox.status(t, self._status(t), self._setpoints)
