"""The closed loop: body-frame PIDs -> allocation -> fin planners -> executors -> robot.

One :class:`ClosedLoop` runs everything between the robot's readings and its fin
commands (control.md sections 7-9)::

    readings --> BodyController (median filters, PIDs) --> allocate --> per-fin targets
    FinFeedback --> FinExecutor (Algorithm 2) --> SendToServo --> RobotIO.command_fin
                      | PlanRequest                  ^ plan at t + plan_latency
                      v                              |
                   planner (MPC / MPC sync / baseline), inline or in its own thread

and publishes what it does on a :class:`TelemetryStream` (channels of
``telemetry.channels``): sensors as sampled, BodyState / FinState / BodyCommand at
``state_rate`` / ``control_rate``, Power at ``power_rate``, each plan as it is made
(``FinPlan`` with every planner input), Setpoints and Status on change and at
``status_rate``, and Events (``mode``, ``tuning``, ``late_plan``, ``plan_overrun``,
``stroke_timeout``, ``stall``).

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

Mode switches are bumpless: a fin's stroke in flight is never interrupted. The old
executors finish the plans they hold (their plan requests are no longer served) while the
new controller's first plan is made at once from where that fin will be (the end angle of
its last plan) with the last executed plan as u_prev; the new executor takes over when the
old ones are idle. Tuning (MPC weights, PID gains) applies from the next plan / PID step.
Mutators may be called from any thread: they are validated at once and applied by the
loop's thread at its next event.

Estimation: the attitude comes from the IMU's own filter, or from the core's EKF
(``control.estimation``, run here on each IMU reading when configured); dead reckoning is
the core's. This module schedules the plans, hands them over between modes and publishes.
It is over 500 lines because those three share the actuators' hand-over state, which one
loop thread owns.

Fins: the controller uses the paper's order (0 front-starboard, 1 front-port,
2 rear-starboard, 3 rear-port); the robot and the telemetry use the robot's order,
mapped by ``robot.fins.PAPER_TO_ROBOT``.
"""

from __future__ import annotations

import logging
import math
import queue
import threading
import time
from dataclasses import fields, replace
from typing import Any, Callable

import numpy as np

from ucat_console.backend.loop.clock import Clock, SimulatedClock
from ucat_console.backend.loop.config import MODES, LoopConfig
from ucat_console.backend.loop.planners import (
    BaselineFinPlanner,
    ManoeuvreFinPlanner,
    MpcFinPlanner,
    PlanInputs,
    PlanJob,
    PlanningService,
    Planner,
    ThreadedPlanning,
)
from ucat_console.control import loop_core as lc
from ucat_console.control.allocation import INDEPENDENT_FINS, SYNC_FINS, BodySetpoints, cut_names
from ucat_console.control.body import BODY_FIELDS, EARLIER_T, BodyController
from ucat_console.control.estimation import AttitudeEstimator
from ucat_console.control.executor import (
    CycleComplete,
    FinExecutor,
    LatePlan,
    PlanRequest,
    SendToServo,
    StrokeTimeout,
)
from ucat_console.control.argcheck import finite
from ucat_console.control.cost import stroke_strouhal
from ucat_console.control.fin_cycle import CycleForce, executed_force, planned_duration
from ucat_console.control.stroke_timing import profile_velocity
from ucat_console.control.params import BaselineConfig, MpcConfig, PidGains
from ucat_console.control.power import P_T, PowerBank, drag_coefficient
from ucat_console.control.stroke_watch import W_T_FB, StrokeWatches
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.messages import (
    BodyAllocation,
    BodyCommand,
    BodyState,
    BodyTracking,
    FinCycle,
    FinPlan,
    FinState,
    FinStrouhal,
    Power,
    Setpoints,
    Status,
)
from ucat_console.robot import reading_rows as rr
from ucat_console.robot.fins import N_FINS, PAPER_TO_ROBOT
from ucat_console.robot.interface import RobotIO, RobotTruth
from ucat_console.robot.readings import DepthReading, DvlVelocity, ImuReading, Reading
from ucat_console.telemetry.stream import TelemetryStream

log = logging.getLogger(__name__)

#: events closer than this (s) are simultaneous
_EPS = lc.EPS
PID_LOOPS = ("velocity", "depth", "yaw_rate")
_FIN_STATE = tuple(ch.fin_state(pf) for pf in range(N_FINS))
_FIN_CYCLE = tuple(ch.fin_cycle(pf) for pf in range(N_FINS))
#: the telemetry a flag of the core asks for
_WANTED = ((lc.F_BODY_COMMAND, (ch.BODY_COMMAND, ch.BODY_ALLOCATION, ch.BODY_TRACKING)),
           (lc.F_STATE, (ch.BODY_STATE, *_FIN_STATE)), (lc.F_POWER, (ch.POWER,)), (lc.F_IMU, (ch.IMU,)),
           (lc.F_DEPTH, (ch.DEPTH,)), (lc.F_DVL, (ch.DVL,)))


def kept_waiting(done: float, arrived: float, deadline: float) -> float:
    """How long past its hand-over deadline a plan kept the loop waiting (s of wall time;
    > 0: an overrun): ``done`` when the plan was made, ``arrived`` when the loop reached its
    hand-over, ``deadline`` when the hand-over was due. A loop that came late to a plan
    done in time, or a plan done before the loop came, is no overrun."""
    return done - max(arrived, deadline)


def check_setpoints(cfg: LoopConfig, sp: BodySetpoints) -> BodySetpoints:
    """``sp`` if it lies inside the envelope of ``cfg``, else ValueError naming the value."""
    return sp.within(cfg.max_velocity, cfg.max_depth, cfg.max_yaw_rate)


class _Actuator:
    """One logical fin: its executor, its planner, and the plan hand-over state."""

    __slots__ = (
        "index", "key", "fins", "executor", "planner", "mode", "u_prev", "job", "t_deliver",
        "running_end", "pending_end", "active", "predecessors", "ready", "requested", "retiring", "loaded",
    )

    def __init__(self, index: int, fins: tuple[int, ...], executor: FinExecutor, planner: Planner,
                 mode: str, u_prev: tuple[float, float, float, float]) -> None:
        self.index = index  # position in the mode's allocation
        self.key = "fin" + "".join(str(f) for f in fins)  # planner thread
        self.fins = fins  # paper indices
        self.executor = executor
        self.planner = planner
        self.mode = mode
        self.u_prev = u_prev
        self.job: PlanJob | None = None
        self.t_deliver = math.inf
        self.running_end: float | None = None  # last target of the running plan
        self.pending_end: float | None = None  # last target of the loaded, waiting plan
        self.active = True
        self.predecessors: list[_Actuator] = []
        self.ready: tuple[PlanInputs, FinPlan] | None = None
        self.requested = False
        self.retiring = False
        self.loaded: tuple[tuple[float, float], float] = ((0.0, 0.0), 0.0)  # the last plan's target, duration

    @property
    def idle(self) -> bool:
        return not self.executor.running and not self.executor.has_pending

    def end_angle(self) -> float | None:
        return self.pending_end if self.pending_end is not None else self.running_end


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
        # an experiment's own planner for the MPC modes (by actuator index), e.g. E7's oracle
        self._mpc_planner = mpc_planner
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
        # in force (the loop's thread), and as commanded (any thread; in force from the next event)
        self._mpc_cfg = cfg.mpc
        self._baseline_cfg = cfg.baseline
        self._setpoints = self.check_setpoints(setpoints or BodySetpoints())
        self._mode = cfg.mode
        self._cmd_lock = threading.Lock()
        self._commanded: dict[str, Any] = {
            "mode": self._mode, "setpoints": self._setpoints, "mpc": cfg.mpc, "baseline": cfg.baseline,
            **{f"pid.{loop}": getattr(cfg.body, loop) for loop in PID_LOOPS},
        }
        self._commands: queue.SimpleQueue[Callable[[float], None]] = queue.SimpleQueue()
        self._stop = False
        self._power = PowerBank(cfg.power, N_FINS)  # rows: robot order
        # the executors' stroke-end table (rows: paper order) and, per fin, the rows of the
        # executor that owns it (checked after each of its samples, as that executor would)
        self._watches = StrokeWatches(cfg.executor, N_FINS)
        self._members = np.full((N_FINS, 2), -1, dtype=np.int64)
        self._found = np.zeros(2, dtype=np.int64)
        # the per-sample core (control.loop_core): the estimate, the body-frame loops, the
        # power estimate, the stroke ends and the schedule, on these arrays
        pcfg = cfg.power
        self._core = lc.LoopCore(
            self.body.state, self._watches.table, self._members, self._found, self._power.table,
            rates=(cfg.control_rate, cfg.state_rate, cfg.power_rate, cfg.status_rate),
            w_th=self._watches.w_th, min_time=self._watches.min_time, k_drag=drag_coefficient(pcfg),
            inertia=float(pcfg.fin_inertia), tau=float(pcfg.filter_tau))
        self._s = self._core.s
        self._attitude = AttitudeEstimator()
        self._ekf = cfg.attitude != "imu"
        self._fed: list[Reading] = []  # the event's readings as objects (a robot running the core gives rows)
        self._wanted_key: frozenset[str] | None = None
        self._wanted_flags = 0
        lc.set_targets(self._s, self.body.state, self._sync)
        # counters
        self.late_plans = 0
        self.plan_overruns = 0
        self.stroke_timeouts = 0
        self.stalls = 0
        self.plans_made = 0
        self._generation = 0
        self._owner: list[_Actuator] = [None] * N_FINS  # type: ignore[list-item]
        # each fin's cycle being executed (paper order): its plan's mode, target and duration,
        # and the measured angle and time at each stroke's start
        self._cycles: list[tuple[str, tuple[float, float], float, list[float], list[float]] | None] = [None] * N_FINS
        self._install_actuators(self._new_actuators(self._mode))

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

    # What the loop is commanded to do; in force from its next event. The loop is the one
    # owner of these: the supervisor and the page read them here.
    @property
    def mode(self) -> str:
        return self._commanded["mode"]

    @property
    def setpoints(self) -> BodySetpoints:
        return self._commanded["setpoints"]

    @property
    def mpc_config(self) -> MpcConfig:
        return self._commanded["mpc"]

    @property
    def baseline_config(self) -> BaselineConfig:
        return self._commanded["baseline"]

    def pid_gains(self, loop: str) -> PidGains:
        """The gains of the body-frame PID ``loop`` ("velocity", "depth" or "yaw_rate")."""
        if loop not in PID_LOOPS:
            raise ValueError(f"loop: {loop!r} is not one of {', '.join(PID_LOOPS)}")
        return self._commanded[f"pid.{loop}"]

    @property
    def planner_threads(self) -> int:
        """Planner threads started so far (0 when headless)."""
        return self._planning.threads if isinstance(self._planning, ThreadedPlanning) else 0

    def truth(self) -> RobotTruth | None:
        return self.io.truth()

    def fin_command(self, fin: int) -> tuple[float, float]:
        """(target angle, profile velocity) last sent to robot fin ``fin``."""
        return float(self._s[lc.C_CMD_ANGLE + fin]), float(self._s[lc.C_CMD_RATE + fin])

    @property
    def _sync(self) -> bool:
        return self._mode == "mpc_sync"

    # ------------------------------------------------------------------ mutators
    def check_setpoints(self, sp: BodySetpoints) -> BodySetpoints:
        """``sp`` if it lies inside the configured envelope, else ValueError naming the value."""
        return check_setpoints(self.cfg, sp)

    def set_setpoints(
        self, velocity: float | None = None, depth: float | None = None, yaw_rate: float | None = None
    ) -> BodySetpoints:
        """New setpoints (unchanged where None), checked against the envelope now; the
        setpoints commanded before (they are in force from the next event)."""
        with self._cmd_lock:
            cur = self._commanded["setpoints"]
            sp = self.check_setpoints(BodySetpoints(
                velocity=cur.velocity if velocity is None else velocity,
                depth=cur.depth if depth is None else depth,
                yaw_rate=cur.yaw_rate if yaw_rate is None else yaw_rate,
            ))
            self._commanded["setpoints"] = sp
            self._commands.put(lambda t: self._apply_setpoints(sp, t))
        return cur

    def set_mode(self, mode: str, who: str = "") -> str:
        """Switch the fin controller while swimming (bumpless; an Event with code "mode"
        naming ``who``); the mode commanded before."""
        if mode not in MODES:
            raise ValueError(f"mode: {mode!r} is not one of {', '.join(MODES)}")
        with self._cmd_lock:
            old = self._commanded["mode"]
            self._commanded["mode"] = mode
            self._commands.put(lambda t: self._apply_mode(mode, t, who))
        return old

    def set_mpc_config(self, cfg: MpcConfig, who: str = "") -> None:
        """New MPC configuration (e.g. ``loop.mpc_config.replace(lam_st=2.0)``) from the next plan."""
        if not isinstance(cfg, MpcConfig):
            raise ValueError(f"mpc config: expected an MpcConfig, got {type(cfg).__name__}")
        MpcFinPlanner(cfg, 0)  # a configuration the planner refuses fails here, in the caller
        self._command("mpc", cfg, lambda t: self._apply_mpc(cfg, t, who))

    def set_baseline_config(self, cfg: BaselineConfig, who: str = "") -> None:
        if not isinstance(cfg, BaselineConfig):
            raise ValueError(f"baseline config: expected a BaselineConfig, got {type(cfg).__name__}")
        self._command("baseline", cfg, lambda t: self._apply_baseline(cfg, t, who))

    def set_pid_gains(self, loop: str, gains: PidGains, who: str = "") -> None:
        """New gains of one body-frame PID ("velocity", "depth" or "yaw_rate")."""
        if loop not in PID_LOOPS:
            raise ValueError(f"loop: {loop!r} is not one of {', '.join(PID_LOOPS)}")
        if not isinstance(gains, PidGains):
            raise ValueError(f"gains: expected PidGains, got {type(gains).__name__}")
        self._command(f"pid.{loop}", gains, lambda t: self._apply_gains(loop, gains, t, who))

    def _command(self, key: str, value: Any, apply: Callable[[float], None]) -> None:
        with self._cmd_lock:
            self._commanded[key] = value
            self._commands.put(apply)

    def restart(self) -> None:
        """Start the body loops and every fin afresh, as at start-up (an Event with code
        "restarted"): the PIDs and filters are reset, and each fin's first plan waits for new
        depth and DVL reports and starts from its measured angle. The supervisor calls it on
        arming: the strokes run while the motors were held never happened (each fin would
        wait for its stroke timeout), and the loops' outputs were held ones."""
        self._commands.put(self._apply_restart)

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
        commands = self._commands
        while True:
            self._inputs(not commands.empty())
            if runs_core and s[lc.C_ROWS_PENDING] == 0.0:
                st = io.run_core(self._core)
            else:
                if s[lc.C_ROWS_PENDING] != 0.0:
                    self._feed(io.advance_to(float(s[lc.C_T_NEXT])))
                    continue
                s[lc.C_T_ROBOT] = io.next_reading_time()
                st = self._core.step()
            if s[lc.C_OUT_N]:
                self._publish_outbox()
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
                owner = self._owner[int(s[lc.C_STROKE_ROW])]
                t_now = float(s[lc.C_T_NOW])
                actions = owner.executor.stroke_checked(t_now, self._found[:len(owner.fins)].tolist())
                if actions:
                    self._handle(owner, actions, t_now)
            elif st == lc.DELIVER:
                lim = t + _EPS
                for act in self._actuators:
                    if act.t_deliver <= lim:
                        self._deliver(act, t)
            elif st == lc.CONTROL:
                self._control(t)
            elif st == lc.HANDOVER:
                self._check_handovers(t)
            elif st == lc.STATUS:
                self._publish_status(t)
            elif st == lc.EKF:
                r = self._reading(int(s[lc.C_CURSOR]))
                assert type(r) is ImuReading
                s[lc.C_Q:lc.C_Q + 4] = self._attitude.update(r).q
            elif st == lc.COMMANDS:
                self._drain_commands()
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
        self._event(t, "stall", f"the loop fell {lag:.2f} s behind the wall clock (the computer was busy); "
                    "it goes on from the present and skips the time it missed instead of replaying it",
                    "warning", {"late": lag})

    def _inputs(self, commands_waiting: bool) -> None:
        """What the core needs of the loop before a step: when plans are due, the flags."""
        s = self._s
        t_deliver = math.inf
        requests = False
        for act in self._actuators:
            if act.t_deliver < t_deliver:
                t_deliver = act.t_deliver
            if not act.requested and act.active:
                requests = True
        s[lc.C_T_DELIVER] = t_deliver
        wanted = self.stream.wanted
        if wanted is not self._wanted_key:
            self._wanted_key = wanted
            self._wanted_flags = sum(f for f, chans in _WANTED if any(c in wanted for c in chans))
        flags = self._wanted_flags
        if self._handover:
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

    def _drain_commands(self) -> None:
        while True:
            try:
                fn = self._commands.get_nowait()
            except queue.Empty:
                return
            fn(self._t)

    # ------------------------------------------------------------------ control
    def _control(self, t: float) -> None:
        """After a control tick (the core ran the body-frame loops): the first plans."""
        if not self.body.sensors_reported:
            return  # the first plans wait for the first DVL and depth reports: no stroke from a guess
        for act in self._actuators:
            if not act.requested and act.active:
                angle = float(self._s[lc.C_FB_ANGLE + PAPER_TO_ROBOT[act.fins[0]]])
                if not math.isnan(angle):
                    self._request(act, t, angle)

    def _request(self, act: _Actuator, t: float, theta0: float) -> None:
        s = self._s
        k = lc.C_TARGETS + 2 * act.index
        inputs = PlanInputs(
            t=t, fins=act.fins, target=(float(s[k]), float(s[k + 1])), v_body=float(s[lc.C_V_BODY]),
            theta0=theta0, u_prev=act.u_prev,
        )
        act.job = self._planning.submit(act.key, act.planner, inputs)
        act.t_deliver = t + self.cfg.plan_latency
        act.requested = True

    def _deliver(self, act: _Actuator, t: float) -> None:
        job = act.job
        assert job is not None
        deadline = act.t_deliver
        act.job = None
        act.t_deliver = math.inf
        if self._planning.threaded:  # the loop waited for it, past the wall-clock deadline
            arrived = time.perf_counter()
            outcome = job.wait()
            late = kept_waiting(job.done_wall, arrived, self.clock.wall_deadline(deadline))
        else:  # the solve took longer than the hand-over allows
            outcome = job.wait()
            late = outcome.solve_time - self.cfg.plan_latency
        act.u_prev = outcome.u
        self.plans_made += 1
        if late > 0.0 and act.active and self._driving():  # a plan the fins were waiting for
            self.plan_overruns += 1
            self._event(t, "plan_overrun", f"plan for fins {list(act.fins)} ready {late * 1e3:.1f} ms after its "
                        f"hand-over deadline ({self.cfg.plan_latency * 1e3:.1f} ms after the request; "
                        f"solve {outcome.solve_time * 1e3:.2f} ms)",
                        "warning", {"fins": list(act.fins), "solve_time": outcome.solve_time,
                                    "plan_latency": self.cfg.plan_latency, "late": late})
        if not act.active:
            act.ready = (job.inputs, outcome)
            return
        self._load(act, job.inputs, outcome, t)

    def _load(self, act: _Actuator, inputs: PlanInputs, outcome: FinPlan, t: float) -> None:
        was_running = act.executor.running
        act.loaded = (inputs.target, planned_duration(outcome.u))
        actions = act.executor.load(outcome.commands, t, theta_start=inputs.theta0)
        if was_running:
            act.pending_end = outcome.commands[2]
        else:
            act.running_end = outcome.commands[2]
            act.pending_end = None
        late = False
        for a in actions:
            if type(a) is LatePlan:
                late = True
        stream = self.stream
        for p in act.fins:
            pf = PAPER_TO_ROBOT[p]
            if stream.wants(ch.fin_plan(pf)):
                stream.publish(ch.fin_plan(pf), replace(outcome, t=t, fin=pf, mode=act.mode, late=late))
        self._handle(act, actions, t)

    def _handle(self, act: _Actuator, actions: list, t: float) -> None:
        for a in actions:
            tp = type(a)
            if tp is SendToServo:
                pf = PAPER_TO_ROBOT[a.fin]
                self._stroke_begins(act, a.fin, a.stroke, t)
                angle = float(self._s[lc.C_FB_ANGLE + pf])
                if angle != angle:  # no feedback yet: from the last command
                    angle = float(self._s[lc.C_CMD_ANGLE + pf])
                ex = self.cfg.executor
                v = profile_velocity(a.theta_ref - angle, a.w_ref, ex.acceleration, ex.max_rate)
                self.io.command_fin(pf, a.theta_ref, v)
                self._publish_stroke(t, pf, a.theta_ref - float(self._s[lc.C_CMD_ANGLE + pf]), a.w_ref)
                self._s[lc.C_CMD_ANGLE + pf] = a.theta_ref
                self._s[lc.C_CMD_RATE + pf] = v
            elif tp is PlanRequest:
                if not act.retiring:
                    self._request(act, t, a.theta_start)
            elif tp is CycleComplete:
                for p in a.fins:
                    self._cycle_ends(p, t)
                if not a.idle:
                    act.running_end = act.pending_end
                    act.pending_end = None
                elif act.retiring:
                    self._handover = True
            elif tp is LatePlan:
                self.late_plans += 1
                self._event(t, "late_plan", f"plan for fins {list(a.fins)} arrived "
                            f"{a.lateness * 1e3:.1f} ms after the fin went idle", "warning",
                            {"fins": list(a.fins), "lateness": a.lateness})
            elif tp is StrokeTimeout:
                self.stroke_timeouts += 1
                self._event(t, "stroke_timeout", f"fin {a.fin} stroke ended by its timeout",
                            "info", {"fin": a.fin, "elapsed": a.elapsed, "planned": a.planned})

    def _stroke_begins(self, act: _Actuator, fin: int, stroke: int, t: float) -> None:
        """Paper fin ``fin`` starts stroke ``stroke`` of its plan: a stroke boundary of the
        cycle being executed (the first stroke begins a cycle)."""
        angle = float(self._s[lc.C_FB_ANGLE + PAPER_TO_ROBOT[fin]])
        cycle = self._cycles[fin]
        if stroke == 0:
            target, duration = act.loaded
            self._cycles[fin] = (act.mode, target, duration, [angle], [t])
        elif cycle is not None:
            cycle[3].append(angle)
            cycle[4].append(t)

    def _cycle_ends(self, fin: int, t: float) -> None:
        """Paper fin ``fin`` finished its plan's last stroke: publish what the cycle delivered."""
        cycle, self._cycles[fin] = self._cycles[fin], None
        pf = PAPER_TO_ROBOT[fin]
        if cycle is None or not self.stream.wants(_FIN_CYCLE[pf]):
            return
        mode, target, duration, angles, times = cycle
        angles.append(float(self._s[lc.C_FB_ANGLE + pf]))
        times.append(t)
        if any(a != a for a in angles):
            return  # a fin without feedback yet
        c = CycleForce(target, executed_force(angles, times, self._mpc_cfg), t - times[0], duration)
        self.stream.publish(_FIN_CYCLE[pf], FinCycle(
            t=t, fin=pf, mode=mode, target=c.target, delivered=c.delivered, direction_error=c.direction_error,
            magnitude_error=c.magnitude_error, duration=c.duration, planned_duration=c.planned_duration))

    # ------------------------------------------------------------------ modes and tuning
    def _new_actuators(self, mode: str) -> list[_Actuator]:
        groups = SYNC_FINS if mode == "mpc_sync" else INDEPENDENT_FINS
        self._generation += 1
        out = []
        for i, fins in enumerate(groups):
            ex = (FinExecutor.synced(self.cfg.executor, fins, watches=self._watches) if len(fins) == 2
                  else FinExecutor(self.cfg.executor, fins[0], watches=self._watches))
            out.append(_Actuator(i, fins, ex, self._make_planner(mode, i), mode, self.cfg.initial_u_prev))
        return out

    def _install_actuators(self, actuators: list[_Actuator]) -> None:
        self._actuators = actuators
        for act in actuators:
            self._take_over(act)
        self._handover = False

    def _take_over(self, act: _Actuator) -> None:
        """``act`` drives its fins from now on: their feedback goes to its executor."""
        rows = act.executor.rows
        for p in act.fins:
            self._owner[p] = act
            self._members[p, :] = -1
            self._members[p, :len(rows)] = rows
        act.executor.take_over()

    def _apply_restart(self, t: float) -> None:
        self.body.reset()
        for act in self._actuators:  # plans still being made are not wanted any more
            act.job = None
            act.t_deliver = math.inf
        news = self._new_actuators(self._mode)
        for n in news:
            n.u_prev = self._owner[n.fins[0]].u_prev
        self._install_actuators(news)  # _control requests their first plans
        self._event(t, "restarted", "body loops and fins start afresh from the measured state",
                    "info", {"mode": self._mode})

    def _make_planner(self, mode: str, index: int) -> Planner:
        if mode == "baseline":
            return BaselineFinPlanner(self._mpc_cfg, self._baseline_cfg, self.cfg.executor)
        if mode == "identify":
            return ManoeuvreFinPlanner(self.cfg.manoeuvre, self._mpc_cfg)
        if self._mpc_planner is not None:
            return self._mpc_planner(index)
        seed = int(np.random.SeedSequence([self.cfg.planner_seed, self._generation, index]).generate_state(1)[0])
        return MpcFinPlanner(self._mpc_cfg, seed, self.cfg.executor)

    def _apply_mode(self, mode: str, t: float, who: str = "") -> None:
        if mode == self._mode:
            return
        old = self._mode
        self._mode = mode
        lc.retarget(self._s, self.body.state, self._sync)
        for act in self._actuators:  # no more plans for the old controller
            act.retiring = True
            act.job = None
            act.t_deliver = math.inf
        news = self._new_actuators(mode)
        for n in news:
            preds: list[_Actuator] = []
            for p in n.fins:
                if self._owner[p] not in preds:
                    preds.append(self._owner[p])
            n.predecessors = preds
            n.active = False
            ref = self._owner[n.fins[0]]
            theta0 = ref.end_angle()
            if theta0 is None:
                a = float(self._s[lc.C_FB_ANGLE + PAPER_TO_ROBOT[n.fins[0]]])
                theta0 = 0.0 if math.isnan(a) else a
            n.u_prev = ref.u_prev
            self._request(n, t, theta0)
        self._actuators = news
        self._handover = True
        self._event(t, "mode", f"{who + ': ' if who else ''}controller {old} -> {mode}", "info",
                    {"from": old, "to": mode, **({"who": who} if who else {})})
        self._check_handovers(t)
        self._publish_status(t)

    def _check_handovers(self, t: float) -> None:
        waiting = False
        for n in self._actuators:
            if n.active:
                continue
            if all(p.idle for p in n.predecessors):
                n.active = True
                n.predecessors = []
                self._take_over(n)
                if n.ready is not None:
                    inputs, outcome = n.ready
                    n.ready = None
                    self._load(n, inputs, outcome, t)
            else:
                waiting = True
        self._handover = waiting

    def _apply_mpc(self, cfg: MpcConfig, t: float, who: str) -> None:
        old, self._mpc_cfg = self._mpc_cfg, cfg
        self.body.set_fin_model(cfg)
        self._generation += 1
        for act in self._actuators:
            act.planner = self._make_planner(act.mode, act.index)
        self._tuning_event(t, "mpc", old, cfg, who)

    def _apply_baseline(self, cfg: BaselineConfig, t: float, who: str) -> None:
        old, self._baseline_cfg = self._baseline_cfg, cfg
        for act in self._actuators:
            if act.mode == "baseline":
                act.planner = self._make_planner("baseline", act.index)
        self._tuning_event(t, "baseline", old, cfg, who)

    def _apply_gains(self, loop: str, gains: PidGains, t: float, who: str) -> None:
        pid = self.body.pid(loop)
        old = pid.gains
        pid.set_gains(gains)
        self._tuning_event(t, f"pid.{loop}", old, gains, who)

    def _tuning_event(self, t: float, block: str, old: Any, new: Any, who: str) -> None:
        """The one event of a tuning change: what changed in ``block``, and who changed it."""
        changes = {}
        for f in fields(new):
            a, b = getattr(old, f.name), getattr(new, f.name)
            if a != b:
                changes[f.name] = [_jsonable(a), _jsonable(b)]
        text = ", ".join(f"{block}.{k} {v[0]} -> {v[1]}" for k, v in changes.items()) or f"{block}: no change"
        self._event(t, "tuning", f"{who + ': ' if who else ''}{text}", "info",
                    {"block": block, "changes": changes, **({"who": who} if who else {})})

    def _apply_setpoints(self, sp: BodySetpoints, t: float) -> None:
        self._setpoints = sp
        self.stream.publish(ch.SETPOINTS, Setpoints(t, sp.velocity, sp.depth, sp.yaw_rate))

    # ------------------------------------------------------------------ telemetry
    def _event(self, t: float, code: str, message: str, level: str, data: dict) -> None:
        self.stream.publish(ch.EVENTS, Event(t=t, source="loop", code=code, message=message, level=level, data=data))

    def _publish_outbox(self) -> None:
        """The core's telemetry rows as messages, in the order it kept them, published at
        once (``publish_many``)."""
        s = self._s
        n = int(s[lc.C_OUT_N])
        s[lc.C_OUT_N] = 0.0
        items: list[tuple[str, Any]] = []
        add = items.append
        for v in self._core.out[:n].tolist():
            kind = v[lc.O_KIND]
            if kind == lc.O_STATE:
                self._state_messages(v, add)
            elif kind == lc.O_POWER:
                add((ch.POWER, self._power_message(v)))
            elif kind == lc.O_BODY_COMMAND:
                self._body_messages(v, add)
            else:
                r = rr.reading_of(v)
                add((_READING_CHANNEL[type(r)], r))
        self.stream.publish_many(items)

    def _state_messages(self, v: list[float], add: Callable[[tuple[str, Any]], None]) -> None:
        """The body state and the fin states of a state row, those a subscriber takes."""
        wants = self.stream.wants
        t, b = v[lc.O_T], lc.O_V
        if wants(ch.BODY_STATE):
            add((ch.BODY_STATE, BodyState(
                t=t, position=(v[b], v[b + 1], v[b + 2]), orientation=(v[b + 3], v[b + 4], v[b + 5], v[b + 6]),
                velocity=(v[b + 7], v[b + 8], v[b + 9]), rates=(v[b + 10], v[b + 11], v[b + 12]), depth=v[b + 13],
            )))
        f = lc.O_STATE_FINS
        for pf, channel in enumerate(_FIN_STATE):
            if wants(channel):
                a = v[f + pf]
                add((channel, FinState(t, pf, 0.0 if a != a else a, v[f + N_FINS + pf],
                                       v[f + 2 * N_FINS + pf], v[f + 3 * N_FINS + pf])))

    def _body_messages(self, v: list[float], add: Callable[[tuple[str, Any]], None]) -> None:
        """The body command, the allocation and the tracking of a body-command row, those a
        subscriber takes."""
        t, b = v[lc.O_T], lc.O_V
        wants = self.stream.wants
        if wants(ch.BODY_COMMAND):
            add((ch.BODY_COMMAND, BodyCommand(t, v[b], v[b + 1], v[b + 2])))
        if wants(ch.BODY_ALLOCATION):
            add((ch.BODY_ALLOCATION, BodyAllocation(t, v[b + 3], v[b + 4], v[b + 5], v[b + 6], v[b + 7], v[b + 8],
                                                    cut_names(int(v[b + 9])))))
        if wants(ch.BODY_TRACKING):
            refs, errors = v[b + 11:b + 15], v[b + 15:b + 18]
            if self._mode == "identify":  # the manoeuvre's fins ignore the loops: no tracking to judge
                errors = [math.nan] * 3
            add((ch.BODY_TRACKING, BodyTracking(t, v[b + 10] != 0.0, *refs, *errors)))

    def _publish_stroke(self, t: float, fin: int, stroke: float, rate: float) -> None:
        if not self.stream.wants(ch.fin_strouhal(fin)):
            return
        m = self._mpc_cfg
        v_body = float(self._s[lc.C_V_BODY])
        self.stream.publish(ch.fin_strouhal(fin), FinStrouhal(
            t, fin, stroke_strouhal(rate, v_body, m), m.st_low, m.st_high, m.st_opt,
            v_body, stroke, rate,
        ))

    def _power_message(self, v: list[float]) -> Power:
        per = [0.0 if x != x else x for x in v[lc.O_V:lc.O_V + N_FINS]]
        energy = 0.0
        mean = 0.0
        for pf in range(N_FINS):
            energy += v[lc.O_POWER_ENERGY + pf]
            m = v[lc.O_POWER_MEAN + pf]
            mean += m if m == m else 0.0
        d = v[lc.O_POWER_DISTANCE]
        return Power(
            t=v[lc.O_T], per_fin=(per[0], per[1], per[2], per[3]), total=sum(per), mean_total=mean,
            energy=energy, distance=d, energy_per_metre=energy / d if d > 0.0 else math.nan,
        )

    def _own_status(self, t: float) -> Status:
        return Status(t=t, armed=self._driving(), mode=self._mode, pilot="", failsafes=(),
                      late_plans=self.late_plans, source=self._source)

    def _publish_status(self, t: float) -> None:
        sp = self._setpoints
        self.stream.publish(ch.STATUS, self._status(t))
        self.stream.publish(ch.SETPOINTS, Setpoints(t, sp.velocity, sp.depth, sp.yaw_rate))


#: the channel of each kind of reading the loop publishes
_READING_CHANNEL = {ImuReading: ch.IMU, DepthReading: ch.DEPTH, DvlVelocity: ch.DVL}


def _jsonable(v: Any) -> Any:
    if isinstance(v, tuple):
        return [_jsonable(x) for x in v]
    if isinstance(v, (int, float, str, bool)) or v is None:
        return v
    return str(v)
