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
``stroke_timeout``).

Time. Everything happens at simulated event times: sensor samples (the robot says when the
next is due), control / telemetry ticks, and plan hand-overs. A plan requested at ``t`` is
handed to its executor at ``t + plan_latency``, whatever the clock, so the headless clock
(planners inline) and the paced clock (one planner thread per logical fin, waiting for a
thread that is not done) give the same trajectory for the same seed. A plan whose solve
took longer than the hand-over allows (headless: solve time > plan_latency; paced: done
after the wall-clock deadline) is counted in ``plan_overruns``; a plan arriving after its
fin went idle is counted in ``late_plans`` (the executor's LatePlan). Neither stalls the
loop in simulated time. The first plans wait until the body controller has had a DVL
report and a depth: a fin never starts a stroke from a command that assumed either (a DVL
without bottom lock counts as reported: its fault is then shown and the depth loop runs).

Mode switches are bumpless: a fin's stroke in flight is never interrupted. The old
executors finish the plans they hold (their plan requests are no longer served) while the
new controller's first plan is made at once from where that fin will be (the end angle of
its last plan) with the last executed plan as u_prev; the new executor takes over when the
old ones are idle. Tuning (MPC weights, PID gains) applies from the next plan / PID step.
Mutators may be called from any thread: they are validated at once and applied by the
loop's thread at its next event.

Estimation (the attitude EKF, dead reckoning) is the core's (``control.estimation``); this
module schedules, hands plans over between modes and publishes. It is over 500 lines
because those three share the actuators' hand-over state, which one loop thread owns.

Fins: the controller uses the paper's order (0 front-starboard, 1 front-port,
2 rear-starboard, 3 rear-port); the robot and the telemetry use the robot's order,
mapped by ``robot.fins.PAPER_TO_ROBOT``.
"""

from __future__ import annotations

import logging
import math
import queue
import threading
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
from ucat_console.control.allocation import (
    INDEPENDENT_FINS,
    SYNC_FINS,
    BodyController,
    BodySetpoints,
    allocate,
)
from ucat_console.control.estimation import MAX_DEAD_RECKONING_GAP, AttitudeEstimator, dead_reckon
from ucat_console.control.executor import (
    CycleComplete,
    FinExecutor,
    LatePlan,
    PlanRequest,
    SendToServo,
    StrokeTimeout,
)
from ucat_console.control.cost import stroke_strouhal
from ucat_console.control.params import BaselineConfig, MpcConfig, PidGains
from ucat_console.control.power import PowerBank
from ucat_console.control.stroke_watch import BACKWARDS, StrokeWatches, feedback_kernel
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.messages import (
    BodyCommand,
    BodyState,
    FinPlan,
    FinState,
    FinStrouhal,
    Power,
    Setpoints,
    Status,
)
from ucat_console.robot.fins import N_FINS, PAPER_TO_ROBOT, ROBOT_TO_PAPER
from ucat_console.robot.interface import RobotIO, RobotTruth
from ucat_console.robot.readings import DepthReading, DvlVelocity, FinFeedback, FinFeedbacks, ImuReading
from ucat_console.telemetry.stream import TelemetryStream

log = logging.getLogger(__name__)

#: events closer than this (s) are simultaneous
_EPS = 1e-7
PID_LOOPS = ("velocity", "depth", "yaw_rate")
_FIN_STATE = tuple(ch.fin_state(pf) for pf in range(N_FINS))


def check_setpoints(cfg: LoopConfig, sp: BodySetpoints) -> BodySetpoints:
    """``sp`` if it lies inside the envelope of ``cfg``, else ValueError naming the value."""
    return sp.within(cfg.max_velocity, cfg.max_depth, cfg.max_yaw_rate)


class _Actuator:
    """One logical fin: its executor, its planner, and the plan hand-over state."""

    __slots__ = (
        "index", "key", "fins", "executor", "planner", "mode", "u_prev", "job", "t_deliver",
        "running_end", "pending_end", "active", "predecessors", "ready", "requested", "retiring",
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
        self.body = BodyController(cfg.body)
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
        self._t = 0.0
        # fin state, robot order
        self._fb_angle = [math.nan] * N_FINS
        self._fb_rate = [0.0] * N_FINS
        self._cmd_angle = [0.0] * N_FINS
        self._cmd_rate = [0.0] * N_FINS
        self._power = PowerBank(cfg.power, N_FINS)  # rows: robot order
        # the executors' stroke-end table (rows: paper order) and, per fin, the rows of the
        # executor that owns it (checked after each of its samples, as that executor would)
        self._watches = StrokeWatches(cfg.executor, N_FINS)
        self._members = np.full((N_FINS, 2), -1, dtype=np.int64)
        self._found = np.zeros(2, dtype=np.int64)
        self._all_rows = np.array([ROBOT_TO_PAPER[pf] for pf in range(N_FINS)], dtype=np.int64)
        self._fin_rows = [self._all_rows[pf:pf + 1] for pf in range(N_FINS)]
        # estimate
        self._attitude = AttitudeEstimator()
        self._q: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
        self._gyro: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self._dvl_v: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self._dvl_t: float | None = None
        self._xy = [0.0, 0.0]
        self._depth = 0.0
        self.distance = 0.0
        # body command and allocation
        self._fx = self._fy = self._yaw = 0.0
        self._v_body = 0.0
        self._targets: tuple[tuple[float, float], ...] = allocate(0.0, 0.0, 0.0, sync=self._sync).targets
        # counters
        self.late_plans = 0
        self.plan_overruns = 0
        self.stroke_timeouts = 0
        self.plans_made = 0
        # timers (counts of ticks done; the next tick is at count / rate)
        self._n_control = self._n_state = self._n_power = self._n_status = 0
        self._generation = 0
        self._owner: list[_Actuator] = [None] * N_FINS  # type: ignore[list-item]
        self._install_actuators(self._new_actuators(self._mode))

    # ------------------------------------------------------------------ public state
    @property
    def time(self) -> float:
        """Simulated time of the last event processed (s)."""
        return self._t

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
        return self._cmd_angle[fin], self._cmd_rate[fin]

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

    def run_until(self, t_end: float) -> None:
        """Process every event up to simulated time ``t_end`` (s)."""
        if not math.isfinite(t_end):
            raise ValueError(f"t_end: expected a finite time, got {t_end!r}")
        self._stop = False
        self.clock.start(self._t)
        io = self.io
        cfg = self.cfg
        p_control, p_state = 1.0 / cfg.control_rate, 1.0 / cfg.state_rate
        p_power, p_status = 1.0 / cfg.power_rate, 1.0 / cfg.status_rate
        commands = self._commands
        while not self._stop:
            if not commands.empty():
                self._drain_commands()
            t_control = self._n_control * p_control
            t_state = self._n_state * p_state
            t_power = self._n_power * p_power
            t_status = self._n_status * p_status
            t_next = min(io.next_reading_time(), t_control, t_state, t_power, t_status)
            for act in self._actuators:
                if act.t_deliver < t_next:
                    t_next = act.t_deliver
            if t_next > t_end + _EPS:
                if t_end > self._t:  # the robot reaches t_end; nothing is due before then
                    readings = io.advance_to(t_end)
                    self._t = t_end
                    if readings:
                        self._on_readings(readings, t_end)
                break
            self.clock.wait_until(t_next)
            readings = io.advance_to(t_next)
            t = t_next if t_next > self._t else self._t
            self._t = t
            lim = t + _EPS
            # 1. plan hand-overs
            for act in self._actuators:
                if act.t_deliver <= lim:
                    self._deliver(act, t)
            # 2. readings
            if readings:
                self._on_readings(readings, t)
            if self._handover:
                self._check_handovers(t)
            # 3. control and telemetry ticks
            if t_control <= lim:
                self._n_control += 1
                self._control(t)
            if t_state <= lim:
                self._n_state += 1
                self._publish_state(t)
            if t_power <= lim:
                self._n_power += 1
                self._publish_power(t)
            if t_status <= lim:
                self._n_status += 1
                self._publish_status(t)

    def _drain_commands(self) -> None:
        while True:
            try:
                fn = self._commands.get_nowait()
            except queue.Empty:
                return
            fn(self._t)

    # ------------------------------------------------------------------ readings
    def _on_readings(self, readings: list, t: float) -> None:
        stream = self.stream
        driving = self._driving()
        for r in readings:
            tp = type(r)
            if tp is FinFeedbacks:
                pos, vel = r.position_rad, r.velocity_rad_s
                self._fb_angle = pos.tolist()
                self._fb_rate = vel.tolist()
                self._power.update_all(r.t, pos, driving)
                self._feedback(self._all_rows, r.t, vel, pos, t)
            elif tp is FinFeedback:
                pf = r.fin
                self._fb_angle[pf] = r.position_rad
                self._fb_rate[pf] = r.velocity_rad_s
                self._power.update(pf, r.t, r.position_rad, driving)
                self._feedback(self._fin_rows[pf], r.t, np.array([r.velocity_rad_s]),
                               np.array([r.position_rad]), t)
            elif tp is ImuReading:
                self.body.on_imu(r)
                self._gyro = r.gyro
                if self.cfg.attitude == "imu" and r.quaternion is not None:
                    self._q = r.quaternion
                else:
                    self._q = self._attitude.update(r).q
                if stream.wants(ch.IMU):
                    stream.publish(ch.IMU, r)
            elif tp is DepthReading:
                self.body.on_depth(r)
                if stream.wants(ch.DEPTH):
                    stream.publish(ch.DEPTH, r)
            elif tp is DvlVelocity:
                self.body.on_dvl(r)
                if r.valid:
                    self._dead_reckon(r, driving)
                if stream.wants(ch.DVL):
                    stream.publish(ch.DVL, r)
            else:
                raise ValueError(f"reading: unexpected type {tp.__name__} from the robot")

    def _feedback(self, rows: np.ndarray, t_fb: float, rates: np.ndarray, angles: np.ndarray, t: float) -> None:
        """Encoder samples of the fins ``rows`` (paper order) taken at ``t_fb``, through the
        compiled stroke-end pass; each executor that saw a stroke end acts at once."""
        t_now = t if t >= t_fb else t_fb
        w = self._watches
        n = rows.shape[0]
        k = 0
        while True:
            k = feedback_kernel(w.table, self._members, rows, t_fb, rates, angles, t_now, k,
                                w.w_th, w.min_time, self._found)
            if k == n:
                return
            if k < 0:
                fin = PAPER_TO_ROBOT[int(rows[BACKWARDS - k])]
                raise ValueError(f"fin {fin}: feedback at t={t_fb!r} is earlier than its last sample")
            owner = self._owner[int(rows[k])]
            actions = owner.executor.stroke_checked(t_now, self._found[:len(owner.fins)].tolist())
            if actions:
                self._handle(owner, actions, t_now)
            k += 1

    def _dead_reckon(self, r: DvlVelocity, driving: bool) -> None:
        if self._dvl_t is not None:
            dt = min(max(r.t - self._dvl_t, 0.0), MAX_DEAD_RECKONING_GAP)
            self._xy[0], self._xy[1] = dead_reckon((self._xy[0], self._xy[1]), self._q, (r.vx, r.vy, r.vz), dt)
            if driving:
                self.distance += dt * math.hypot(r.vx, r.vy)
        self._dvl_t = r.t
        self._dvl_v = (r.vx, r.vy, r.vz)

    # ------------------------------------------------------------------ control
    def _control(self, t: float) -> None:
        cmd = self.body.update(t, self._setpoints, sync=self._sync)
        self._fx, self._fy, self._yaw = cmd.fx, cmd.fy, cmd.yaw
        self._targets = cmd.allocation.targets
        if cmd.velocity is not None:
            self._v_body = cmd.velocity
        if cmd.depth is not None:
            self._depth = cmd.depth
        if self.stream.wants(ch.BODY_COMMAND):
            self.stream.publish(ch.BODY_COMMAND, BodyCommand(t, cmd.fx, cmd.fy, cmd.yaw))
        if not self.body.sensors_reported:
            return  # the first plans wait for the first DVL and depth reports: no stroke from a guess
        for act in self._actuators:
            if not act.requested and act.active:
                angle = self._fb_angle[PAPER_TO_ROBOT[act.fins[0]]]
                if not math.isnan(angle):
                    self._request(act, t, angle)

    def _request(self, act: _Actuator, t: float, theta0: float) -> None:
        inputs = PlanInputs(
            t=t, fins=act.fins, target=self._targets[act.index], v_body=self._v_body,
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
        outcome = job.wait()
        if self._planning.threaded:  # done after the wall-clock hand-over deadline
            late = job.done_wall - self.clock.wall_deadline(deadline)
        else:  # the solve took longer than the hand-over allows
            late = outcome.solve_time - self.cfg.plan_latency
        act.u_prev = outcome.u
        self.plans_made += 1
        if late > 0.0:
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
                self.io.command_fin(pf, a.theta_ref, a.w_ref)
                self._publish_stroke(t, pf, a.theta_ref - self._cmd_angle[pf], a.w_ref)
                self._cmd_angle[pf] = a.theta_ref
                self._cmd_rate[pf] = a.w_ref
            elif tp is PlanRequest:
                if not act.retiring:
                    self._request(act, t, a.theta_start)
            elif tp is CycleComplete:
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
            return BaselineFinPlanner(self._mpc_cfg, self._baseline_cfg)
        if mode == "identify":
            return ManoeuvreFinPlanner(self.cfg.manoeuvre, self._mpc_cfg)
        seed = int(np.random.SeedSequence([self.cfg.planner_seed, self._generation, index]).generate_state(1)[0])
        return MpcFinPlanner(self._mpc_cfg, seed)

    def _apply_mode(self, mode: str, t: float, who: str = "") -> None:
        if mode == self._mode:
            return
        old = self._mode
        self._mode = mode
        self._targets = allocate(self._fx, self._fy, self._yaw, sync=self._sync).targets
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
                a = self._fb_angle[PAPER_TO_ROBOT[n.fins[0]]]
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
        pid = {"velocity": self.body.velocity_pid, "depth": self.body.depth_pid,
               "yaw_rate": self.body.yaw_pid}[loop]
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

    def _publish_state(self, t: float) -> None:
        stream = self.stream
        if stream.wants(ch.BODY_STATE):
            stream.publish(ch.BODY_STATE, BodyState(
                t=t, position=(self._xy[0], self._xy[1], self._depth), orientation=self._q,
                velocity=self._dvl_v, rates=self._gyro, depth=self._depth,
            ))
        ang, rate, ca, cr = self._fb_angle, self._fb_rate, self._cmd_angle, self._cmd_rate
        for pf, channel in enumerate(_FIN_STATE):
            if stream.wants(channel):
                a = ang[pf]
                stream.publish(channel, FinState(t, pf, 0.0 if a != a else a, rate[pf], ca[pf], cr[pf]))

    def _publish_stroke(self, t: float, fin: int, stroke: float, rate: float) -> None:
        if not self.stream.wants(ch.fin_strouhal(fin)):
            return
        m = self._mpc_cfg
        self.stream.publish(ch.fin_strouhal(fin), FinStrouhal(
            t, fin, stroke_strouhal(rate, self._v_body, m), m.st_low, m.st_high, m.st_opt,
            self._v_body, stroke, rate,
        ))

    def _publish_power(self, t: float) -> None:
        if not self.stream.wants(ch.POWER):
            return
        bank = self._power
        per = [bank.p_fin(pf) for pf in range(N_FINS)]
        energy = 0.0
        mean = 0.0
        for pf in range(N_FINS):
            energy += bank.energy(pf)
            m = bank.mean_power(pf)
            mean += m if m is not None else 0.0
        d = self.distance
        self.stream.publish(ch.POWER, Power(
            t=t, per_fin=(per[0], per[1], per[2], per[3]), total=sum(per), mean_total=mean,
            energy=energy, distance=d, energy_per_metre=energy / d if d > 0.0 else math.nan,
        ))

    def _own_status(self, t: float) -> Status:
        return Status(t=t, armed=self._driving(), mode=self._mode, pilot="", failsafes=(),
                      late_plans=self.late_plans, source=self._source)

    def _publish_status(self, t: float) -> None:
        sp = self._setpoints
        self.stream.publish(ch.STATUS, self._status(t))
        self.stream.publish(ch.SETPOINTS, Setpoints(t, sp.velocity, sp.depth, sp.yaw_rate))


def _jsonable(v: Any) -> Any:
    if isinstance(v, tuple):
        return [_jsonable(x) for x in v]
    if isinstance(v, (int, float, str, bool)) or v is None:
        return v
    return str(v)
