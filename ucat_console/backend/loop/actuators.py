"""The closed loop's actuators: each logical fin's executor and planner, and the plan hand-over.

An :class:`Actuator` is one logical fin of the mode in force (one fin, or the rear pair
synchronised): its executor (``control.executor``, Algorithm 2), its planner (made by its
mode, ``modes``), and the state of its plans: the one being made (requested at ``t``,
handed over at ``t + plan_latency``), the running and the loaded one's end angles.
:class:`Actuators` holds the mode's actuators and does everything between a plan request
and a servo command:

* requests the first plans (after a control tick) and the next ones (an executor's
  PlanRequest), collects each at its hand-over (:meth:`Actuators.deliver_due`), counting
  overruns, and loads it into its executor;
* carries out the executors' actions: a stroke to the servo (``command_fin``, with the
  profile velocity of ``control.stroke_timing``), a cycle completed, a late plan, a stroke
  timeout (none while the fins are not driven: disarmed, no stroke was sent, or the fins
  were stopped under it); and follows each cycle from its first stroke to its last to
  publish what it delivered (and tells the body layer's feed-forward of each: ``on_cycle``
  when one begins, ``on_executed`` when one ends), and judges each fin's pace (``fin_slow``: a cycle taking
  longer than planned, a weak or lagging drive);
* switches the mode bumplessly (:meth:`Actuators.switch`): the old executors finish the
  plans they hold, the new ones' first plans are made at once from where their fins will
  be, and each new executor takes over when the old ones of its fins are idle
  (:meth:`Actuators.check_handovers`);
* rebuilds the planners when a configuration block they are made from changes;
* keeps, in the core's state row, the set-point each fin was actually sent
  (:meth:`Actuators.sent`, told by the loop): the fin states carry it.

Its collaborators are narrow: the core's state row ``s`` (targets, forward speed, fin
feedback and set-points sent) and its members table, the planning service, the robot's
``command_fin``, the outbox, the clock's wall deadline and whether the fins are driven.
"""

from __future__ import annotations

import math
import time
from typing import Any, Callable

import numpy as np

from ucat_console.backend.loop.config import LoopConfig
from ucat_console.backend.loop.modes import MODES, PlannerSetting
from ucat_console.backend.loop.outbox import Outbox
from ucat_console.backend.loop.planners import PlanInputs, PlanJob, PlanningService, Planner
from ucat_console.control import loop_core as lc
from ucat_console.control.executor import (
    CycleComplete,
    FinExecutor,
    LatePlan,
    PlanRequest,
    SendToServo,
    StrokeTimeout,
)
from ucat_console.control.fin_cycle import CycleForce, executed_force, planned_duration
from ucat_console.control.stroke_timing import profile_velocity
from ucat_console.control.stroke_watch import StrokeWatches
from ucat_console.robot.fins import N_FINS, PAPER_TO_ROBOT
from ucat_console.telemetry.messages import FinPlan


def kept_waiting(done: float, arrived: float, deadline: float) -> float:
    """How long past its hand-over deadline a plan kept the loop waiting (s of wall time;
    > 0: an overrun): ``done`` when the plan was made, ``arrived`` when the loop reached its
    hand-over, ``deadline`` when the hand-over was due. A loop that came late to a plan
    done in time, or a plan done before the loop came, is no overrun."""
    return done - max(arrived, deadline)


#: fins whose cycles differ in length by at most this share beat together (``Actuators.lag``)
SAME_BEAT = 0.1
#: the cycles over which a fin's pace is judged (``Actuators._judge_pace``)
PACE_CYCLES = 5


PARTNER = (1, 0, 3, 2)  # paper fin -> the fin across the hull from it


class Actuator:
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
        self.predecessors: list[Actuator] = []
        self.ready: tuple[PlanInputs, FinPlan] | None = None
        self.requested = False
        self.retiring = False
        # the last plan's target, duration and force by the fin model
        self.loaded: tuple[tuple[float, float], float, tuple[float, float]] = ((0.0, 0.0), 0.0, (0.0, 0.0))

    @property
    def idle(self) -> bool:
        return not self.executor.running and not self.executor.has_pending

    def end_angle(self) -> float | None:
        return self.pending_end if self.pending_end is not None else self.running_end

    def drop_job(self) -> None:
        """The plan being made is not wanted any more."""
        self.job = None
        self.t_deliver = math.inf


class Actuators:
    """The actuators of the mode in force, and those of the mode before until they are idle
    (module docstring)."""

    def __init__(self, cfg: LoopConfig, s: np.ndarray, members: np.ndarray, watches: StrokeWatches,
                 planning: PlanningService, outbox: Outbox, command_fin: Callable[[int, float, float], None],
                 wall_deadline: Callable[[float], float], driving: Callable[[], bool],
                 mpc_planner: Callable[[int], Planner] | None = None,
                 on_cycle: Callable[[int, tuple[float, float], tuple[float, float]], None] | None = None,
                 on_executed: Callable[[int, tuple[float, float], tuple[float, float]], None] | None = None) -> None:
        self.cfg = cfg
        # told when a fin begins a cycle: (paper fin, its target, its plan's force by the fin model)
        self._on_cycle = on_cycle
        # told when a fin ends a cycle: (paper fin, its plan's force, its executed strokes' force by the fin model)
        self._on_executed = on_executed
        # each paper fin's last executed / planned cycle durations, and whether it is reported slow
        self._ratios: list[list[float]] = [[] for _ in range(N_FINS)]
        self._slow = [False] * N_FINS
        # an experiment's own planner for the MPC modes (by actuator index), e.g. E7's oracle
        self._mpc_planner = mpc_planner
        self.blocks: dict[str, Any] = {"mpc": cfg.mpc, "baseline": cfg.baseline, "manoeuvre": cfg.manoeuvre}
        self._s = s
        self._members = members
        self._watches = watches
        self._planning = planning
        self._outbox = outbox
        self._command_fin = command_fin
        self._wall_deadline = wall_deadline
        self._driving = driving
        self.late_plans = 0
        self.plan_overruns = 0
        self.stroke_timeouts = 0
        self.plans_made = 0
        self.handover = False  # a new mode's actuators wait for the old ones
        self._generation = 0
        self._owner: list[Actuator] = [None] * N_FINS  # type: ignore[list-item]
        # each fin's cycle being executed (paper order): its plan's mode, target and duration,
        # and the measured angle and time at each stroke's start
        self._cycles: list[tuple[str, tuple[float, float], float, list[float], list[float], tuple[float, float]]
                           | None] = [None] * N_FINS
        # each paper fin's last beat (a stroke towards larger angles) began, and its cycle's
        # planned length: how far a fin lags the others (``lag``)
        self._beat = [math.nan] * N_FINS
        self._length = [math.nan] * N_FINS
        # each robot fin's last stroke target the executors asked for (sent or not): a stroke's
        # start while the fin has no feedback, and its size for the Strouhal number
        self._asked = [0.0] * N_FINS
        self.current: list[Actuator] = []
        self._install(self._new(cfg.mode))

    @property
    def mpc(self) -> Any:
        return self.blocks["mpc"]

    def owner(self, fin: int) -> Actuator:
        """The actuator driving paper fin ``fin``."""
        return self._owner[fin]

    # ------------------------------------------------------------------ the core's inputs
    def next_delivery(self) -> tuple[float, bool]:
        """(the next hand-over time, whether an active actuator still has to request its
        first plan)."""
        t_deliver = math.inf
        requests = False
        for act in self.current:
            if act.t_deliver < t_deliver:
                t_deliver = act.t_deliver
            if not act.requested and act.active:
                requests = True
        return t_deliver, requests

    # ------------------------------------------------------------------ plans
    def request_first(self, t: float) -> None:
        """Each active actuator that has not asked for a plan asks for its first one, from
        its fin's measured angle (none yet: later)."""
        for act in self.current:
            if not act.requested and act.active:
                angle = float(self._s[lc.C_FB_ANGLE + PAPER_TO_ROBOT[act.fins[0]]])
                if not math.isnan(angle):
                    self._request(act, t, angle)

    def _request(self, act: Actuator, t: float, theta0: float) -> None:
        s = self._s
        k = lc.C_TARGETS + 2 * act.index
        inputs = PlanInputs(
            t=t, fins=act.fins, target=(float(s[k]), float(s[k + 1])), v_body=float(s[lc.C_V_BODY]),
            theta0=theta0, u_prev=act.u_prev, lag=self.lag(act.fins[0], t), align=self.align(act, t),
        )
        act.job = self._planning.submit(act.key, act.planner, inputs)
        act.t_deliver = t + self.cfg.plan_latency
        act.requested = True

    def align(self, act: Actuator, t: float) -> float:
        """How long ``act``'s next cycle (requested at ``t``, as its last stroke begins) would
        last to end when the fin across the hull ends one (s): the partner's cycle boundary
        half to one and a half of its cycle length after the next cycle begins. NaN when the
        MPC does not plan it with ``align``, ``act`` drives a pair, or the partner runs no
        cycle of its own."""
        if len(act.fins) != 1 or not MODES[act.mode].mpc or not self.mpc.align > 0.0:
            return math.nan
        fin = PARTNER[act.fins[0]]
        other, cycle = self._owner[fin], self._cycles[fin]
        length = self._length[fin]
        if other is None or len(other.fins) != 1 or cycle is None or not length > 0.0:
            return math.nan
        u = act.u_prev
        begins = t + (abs(u[1]) / u[3] if u[3] > 0.0 else 0.0)
        ends = cycle[4][0] + length  # the partner's running cycle
        return length + math.remainder(ends - begins - length, length)

    def lag(self, fin: int, t: float) -> float:
        """How long after the other fins' last beats paper fin ``fin``'s began (s, at ``t``: the
        median over the others beating with it, each wrapped to within half of ``fin``'s cycle;
        < 0: before them; 0 when none is). A beat begins with a stroke towards larger angles,
        the same motion on every fin whichever extreme its cycle starts from. The others beat
        with it while their cycles are within :data:`SAME_BEAT` of its own in length (a fin
        whose strokes are floored at the slowest rate beats faster: no common beat to keep)."""
        beat, length = self._beat[fin], self._length[fin]
        if not (length > 0.0) or beat != beat:  # no cycle, or no beat yet (NaN)
            return 0.0
        offsets = sorted(math.remainder(beat - b, length) for q, b in enumerate(self._beat)
                         if q != fin and t - b <= 2.0 * self._length[q]  # NaN: never began
                         and abs(self._length[q] - length) <= SAME_BEAT * length)
        return offsets[(len(offsets) - 1) // 2] if offsets else 0.0

    def deliver_due(self, t: float) -> None:
        """Hand over every plan due at ``t``."""
        lim = t + lc.EPS
        for act in self.current:
            if act.t_deliver <= lim:
                self._deliver(act, t)

    def _deliver(self, act: Actuator, t: float) -> None:
        job = act.job
        assert job is not None
        deadline = act.t_deliver
        act.drop_job()
        if self._planning.threaded:  # the loop waited for it, past the wall-clock deadline
            arrived = time.perf_counter()
            outcome = job.wait()
            late = kept_waiting(job.done_wall, arrived, self._wall_deadline(deadline))
        else:  # the solve took longer than the hand-over allows
            outcome = job.wait()
            late = outcome.solve_time - self.cfg.plan_latency
        act.u_prev = outcome.u
        self.plans_made += 1
        if late > 0.0 and act.active and self._driving():  # a plan the fins were waiting for
            self.plan_overruns += 1
            latency = self.cfg.plan_latency
            self._outbox.event(t, "plan_overrun", f"plan for fins {list(act.fins)} ready {late * 1e3:.1f} ms after "
                               f"its hand-over deadline ({latency * 1e3:.1f} ms after the request; "
                               f"solve {outcome.solve_time * 1e3:.2f} ms)",
                               "warning", {"fins": list(act.fins), "solve_time": outcome.solve_time,
                                           "plan_latency": latency, "late": late})
        if not act.active:
            act.ready = (job.inputs, outcome)
            return
        self._load(act, job.inputs, outcome, t)

    def _load(self, act: Actuator, inputs: PlanInputs, outcome: FinPlan, t: float) -> None:
        was_running = act.executor.running
        act.loaded = (inputs.target, planned_duration(outcome.u), outcome.mean_force)
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
        for p in act.fins:
            self._outbox.fin_plan(PAPER_TO_ROBOT[p], outcome, t, act.mode, late)
        self.handle(act, actions, t)

    # ------------------------------------------------------------------ the executors' actions
    def stroke_checked(self, row: int, t: float, found: np.ndarray) -> None:
        """The core saw a stroke end on ``row`` of the stroke-end table at ``t`` (``found``:
        the rows of its executor that ended)."""
        owner = self._owner[row]
        actions = owner.executor.stroke_checked(t, found[:len(owner.fins)].tolist())
        if actions:
            self.handle(owner, actions, t)

    def handle(self, act: Actuator, actions: list, t: float) -> None:
        s = self._s
        for a in actions:
            tp = type(a)
            if tp is SendToServo:
                pf = PAPER_TO_ROBOT[a.fin]
                self._stroke_begins(act, a.fin, a.stroke, t)
                if a.theta_ref > self._asked[pf]:
                    self._beat[a.fin] = t
                angle = float(s[lc.C_FB_ANGLE + pf])
                if angle != angle:  # no feedback yet: from the last command
                    angle = self._asked[pf]
                ex = self.cfg.executor
                v = profile_velocity(a.theta_ref - angle, a.w_ref, ex.acceleration, ex.max_rate)
                self._command_fin(pf, a.theta_ref, v)
                self._outbox.stroke(t, pf, a.theta_ref - self._asked[pf], a.w_ref, float(s[lc.C_V_BODY]), self.mpc)
                self._asked[pf] = a.theta_ref
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
                    self.handover = True
            elif tp is LatePlan:
                self.late_plans += 1
                self._outbox.event(t, "late_plan", f"plan for fins {list(a.fins)} arrived "
                                   f"{a.lateness * 1e3:.1f} ms after the fin went idle", "warning",
                                   {"fins": list(a.fins), "lateness": a.lateness})
            elif tp is StrokeTimeout:
                if not self._driving():  # no stroke was sent, or the fins were stopped under it
                    continue
                self.stroke_timeouts += 1
                self._outbox.event(t, "stroke_timeout", f"fin {a.fin} stroke ended by its timeout",
                                   "info", {"fin": a.fin, "elapsed": a.elapsed, "planned": a.planned})

    def sent(self, fin: int, target: float, rate: float) -> None:
        """Robot fin ``fin`` was sent the set-point (``target`` rad, profile velocity
        ``rate`` rad/s): the one its fin states carry from now on."""
        self._s[lc.C_CMD_ANGLE + fin] = target
        self._s[lc.C_CMD_RATE + fin] = rate

    def _stroke_begins(self, act: Actuator, fin: int, stroke: int, t: float) -> None:
        """Paper fin ``fin`` starts stroke ``stroke`` of its plan: a stroke boundary of the
        cycle being executed (the first stroke begins a cycle)."""
        angle = float(self._s[lc.C_FB_ANGLE + PAPER_TO_ROBOT[fin]])
        cycle = self._cycles[fin]
        if stroke == 0:
            target, duration, force = act.loaded
            self._cycles[fin] = (act.mode, target, duration, [angle], [t], force)
            self._length[fin] = duration
            if self._on_cycle is not None:
                self._on_cycle(fin, target, force)
        elif cycle is not None:
            cycle[3].append(angle)
            cycle[4].append(t)

    def _cycle_ends(self, fin: int, t: float) -> None:
        """Paper fin ``fin`` finished its plan's last stroke: publish what the cycle delivered."""
        cycle, self._cycles[fin] = self._cycles[fin], None
        pf = PAPER_TO_ROBOT[fin]
        if cycle is None:
            return
        mode, target, duration, angles, times, planned = cycle
        angles.append(float(self._s[lc.C_FB_ANGLE + pf]))
        times.append(t)
        if any(a != a for a in angles):
            return  # a fin without feedback yet
        executed = executed_force(angles, times, self.mpc)
        if self._on_executed is not None:
            self._on_executed(fin, planned, executed)
        self._judge_pace(fin, t, t - times[0], duration)
        if self._outbox.wants_cycle(pf):
            self._outbox.fin_cycle(t, pf, mode, CycleForce(target, executed, t - times[0], duration))

    def _judge_pace(self, fin: int, t: float, executed: float, planned: float) -> None:
        """Paper fin ``fin``'s cycle took ``executed`` s of its plan's ``planned``: over its last
        :data:`PACE_CYCLES` cycles, a median ratio above ``executor.slow_fin_ratio`` reports the
        fin slow (a weak or lagging drive: an event, the allocation's feed-forward shares its
        work out), one back under the ratio's midpoint to 1 reports it recovered. A cycle that
        ends while the fins are not driven (disarmed: the drives do not follow) is not judged."""
        if planned <= 0.0 or not self._driving():
            return
        ratios = self._ratios[fin]
        ratios.append(executed / planned)
        del ratios[:-PACE_CYCLES]
        if len(ratios) < PACE_CYCLES:
            return
        limit = self.cfg.executor.slow_fin_ratio
        pace = float(np.median(ratios))
        if not self._slow[fin] and pace > limit:
            self._slow[fin] = True
            self._outbox.event(t, "fin_slow", f"fin {fin}'s cycles take {pace:.2f} times their plans' "
                               "duration: a weak or lagging drive", "warning", {"fin": fin, "ratio": pace})
        elif self._slow[fin] and pace < 0.5 * (1.0 + limit):
            self._slow[fin] = False
            self._outbox.event(t, "fin_slow_cleared", f"fin {fin}'s cycles keep their plans' pace again "
                               f"({pace:.2f})", "info", {"fin": fin, "ratio": pace})

    # ------------------------------------------------------------------ modes and tuning
    def _planner(self, mode: str, index: int) -> Planner:
        if self._mpc_planner is not None and MODES[mode].mpc:
            return self._mpc_planner(index)
        b = self.blocks
        seed = int(np.random.SeedSequence([self.cfg.planner_seed, self._generation, index]).generate_state(1)[0])
        return MODES[mode].planner(PlannerSetting(b["mpc"], b["baseline"], self.cfg.executor, b["manoeuvre"], seed))

    def force_limit(self, mode: str) -> float | None:
        """The largest mean force (N) a fin's planner of ``mode`` makes with the blocks in
        force (``Mode.fin_force``; None: the fin model's deliverable force)."""
        limit = MODES[mode].fin_force
        if limit is None:
            return None
        b = self.blocks
        return float(limit(PlannerSetting(b["mpc"], b["baseline"], self.cfg.executor, b["manoeuvre"], 0)))

    def _new(self, mode: str) -> list[Actuator]:
        self._generation += 1
        out = []
        for i, fins in enumerate(MODES[mode].fins):
            ex = (FinExecutor.synced(self.cfg.executor, fins, watches=self._watches) if len(fins) == 2
                  else FinExecutor(self.cfg.executor, fins[0], watches=self._watches))
            out.append(Actuator(i, fins, ex, self._planner(mode, i), mode, self.cfg.initial_u_prev))
        return out

    def _install(self, actuators: list[Actuator]) -> None:
        self.current = actuators
        for act in actuators:
            self._take_over(act)
        self.handover = False

    def _take_over(self, act: Actuator) -> None:
        """``act`` drives its fins from now on: their feedback goes to its executor."""
        rows = act.executor.rows
        for p in act.fins:
            self._owner[p] = act
            self._members[p, :] = -1
            self._members[p, :len(rows)] = rows
        act.executor.take_over()

    def restart(self, mode: str) -> None:
        """Every fin afresh in ``mode``: plans being made are dropped, each new actuator
        requests its first plan at the next control tick."""
        for act in self.current:  # plans still being made are not wanted any more
            act.drop_job()
        news = self._new(mode)
        for n in news:
            n.u_prev = self._owner[n.fins[0]].u_prev
        self._install(news)

    def switch(self, mode: str, t: float) -> None:
        """Switch to ``mode`` at ``t``, bumplessly (module docstring)."""
        for act in self.current:  # no more plans for the old controller
            act.retiring = True
            act.drop_job()
        news = self._new(mode)
        for n in news:
            preds: list[Actuator] = []
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
        self.current = news
        self.handover = True

    def check_handovers(self, t: float) -> None:
        """Each new actuator whose fins' old actuators are idle takes over (and loads the
        plan it holds)."""
        waiting = False
        for n in self.current:
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
        self.handover = waiting

    def retune(self, block: str, value: Any) -> None:
        """Configuration block ``block`` is ``value`` from the next plan: the planners made
        from it are made anew (a new MPC configuration: a new generation of seeds)."""
        self.blocks[block] = value
        if block == "mpc":
            self._generation += 1
        for act in self.current:
            if block in MODES[act.mode].reads:
                act.planner = self._planner(act.mode, act.index)
