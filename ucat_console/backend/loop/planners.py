"""Fin planners behind one interface, and the services that run them.

A planner turns :class:`PlanInputs` (everything a plan depends on, which is also what a
``FinPlan`` message carries so a recording can be replayed) into a ``FinPlan``: the plan, its
cost terms, its inputs and its solve time (measured here, around the solver; the core reads
no clock). The loop publishes it with the hand-over time, the robot fin, the mode and
whether it came late filled in (:func:`dataclasses.replace`):

* :class:`MpcFinPlanner`: the Strouhal-aware MPC (``control.mpc.FinMpc``), for the modes
  "mpc" and "mpc_sync" (``modes`` says which planner each mode uses);
* :class:`BaselineFinPlanner`: the inverse-model baseline (``control.baseline``), whose
  plan is scored with the MPC's cost so St and force error are reported the same way;
* :class:`ManoeuvreFinPlanner`: the identification manoeuvre (``control.manoeuvre``), mode
  "identify", timed from its first plan and scored the same way.

Services decide where a planner runs: :class:`InlinePlanning` calls it at once in the
loop's thread (headless), :class:`ThreadedPlanning` gives each logical fin its own thread
(real time, as the console runs it). Either way the loop collects the result at its
hand-over time; the service only reports whether the solve met its wall-clock deadline.
"""

from __future__ import annotations

import math
import threading
import time
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from typing import Callable, Hashable

from ucat_console.control.baseline import BaselinePlanner, wrap_angle
from ucat_console.control.manoeuvre import ManoeuvrePlanner
from ucat_console.control.mpc import FinMpc
from ucat_console.control.params import BaselineConfig, ExecutorConfig, ManoeuvreConfig, MpcConfig
from ucat_console.telemetry.messages import FinPlan

Vec4 = tuple[float, float, float, float]


@dataclass(frozen=True)
class PlanInputs:
    """What one plan depends on: the replayable inputs of a ``FinPlan``."""

    t: float  # request time, s
    fins: tuple[int, ...]  # paper fin indices driven by this plan
    target: tuple[float, float]  # (f_x*, f_y*) per physical fin, N
    v_body: float  # median-filtered forward speed, m/s
    theta0: float  # angle the plan starts from, rad
    u_prev: Vec4  # the fin's previous plan
    lag: float = 0.0  # s: how long after the other fins' beats this fin's last began
    # s: how long the cycle would last to end when the fin across the hull ends one (NaN: none)
    align: float = math.nan


def _plan(x: PlanInputs, **result: object) -> FinPlan:
    """A FinPlan of ``x``; ``t``, ``fin``, ``mode`` and ``late`` are the loop's to fill in."""
    return FinPlan(t=x.t, fin=-1, mode="", target=x.target, v_body=x.v_body, theta0=x.theta0,
                   u_prev=x.u_prev, late=False, lag=x.lag, align=x.align, **result)  # type: ignore[arg-type]


def _wrapped(theta0: float) -> tuple[float, float]:
    """(theta0 wrapped to (-pi, pi], the whole turns taken off)."""
    w = wrap_angle(theta0)
    return w, theta0 - w


def _shift(commands: Vec4, offset: float) -> Vec4:
    return (commands[0] + offset, commands[1], commands[2] + offset, commands[3])


class MpcFinPlanner:
    """One fin's MPC (not thread-safe: one planner per logical fin).

    The fin may turn through whole revolutions; the plan is made from ``theta0`` wrapped to
    (-pi, pi] (the force model is periodic in the angle, and the solver's inputs are
    bounded) and its commands are shifted back by the whole turns, so the servo never
    makes an extra revolution. The baseline does the same.
    """

    def __init__(self, cfg: MpcConfig, seed: int, drive: ExecutorConfig | None = None) -> None:
        self.cfg = cfg
        self._mpc = FinMpc(cfg, drive=drive)
        self._seed_base = seed << 32
        self._count = 0

    def __call__(self, x: PlanInputs) -> FinPlan:
        t0 = time.perf_counter()
        theta, offset = _wrapped(x.theta0)
        # every plan gets its own seed (recorded in FinPlan), so a recording replays exactly
        seed = self._seed_base + self._count
        self._count += 1
        p = self._mpc.plan(x.target, x.v_body, theta, x.u_prev, seed=seed, duration=x.align)
        c = p.cost
        return _plan(
            x, u=p.u, commands=_shift(p.commands, offset), cost_total=c.total, cost_force=c.force,
            cost_strouhal=c.strouhal_penalty, cost_amplitude=c.amplitude,
            cost_smoothness=c.smoothness, st=c.st, mean_force=c.mean_force,
            solve_time=time.perf_counter() - t0, seed=seed,
        )


class BaselineFinPlanner:
    """The inverse-model baseline; its plan is scored with the MPC cost of ``cfg``."""

    def __init__(self, cfg: MpcConfig, bcfg: BaselineConfig, executor: ExecutorConfig | None = None) -> None:
        self.cfg = cfg
        self._planner = BaselinePlanner(cfg, bcfg, executor)
        self._scorer = FinMpc(cfg)

    def __call__(self, x: PlanInputs) -> FinPlan:
        t0 = time.perf_counter()
        theta, offset = _wrapped(x.theta0)
        b = self._planner.plan(x.target[0], x.target[1], theta, x.lag)
        return _scored(self._scorer, x, theta, b.u, _shift(b.commands, offset), t0,
                       amplitude=b.amplitude, centre=b.centre)


def _scored(scorer: FinMpc, x: PlanInputs, theta: float, u: Vec4, commands: Vec4, t0: float,
            **extra: float) -> FinPlan:
    """The FinPlan of a plan made without the MPC, scored with the MPC's (compiled) cost
    (``t0``: ``time.perf_counter()`` when the plan was begun)."""
    if min(abs(u[0]), abs(u[1])) < 1e-9:  # holding still: no stroke, no frequency
        force = abs(x.target[0]) + abs(x.target[1])
        return _plan(x, u=u, commands=commands, cost_total=scorer.config.lam_f * force, cost_force=force,
                     cost_strouhal=0.0, cost_amplitude=0.0, cost_smoothness=0.0, st=0.0,
                     mean_force=(0.0, 0.0), solve_time=time.perf_counter() - t0, **extra)
    c = scorer.score(u, x.target, x.v_body, theta, x.u_prev)
    return _plan(
        x, u=u, commands=commands, cost_total=c.total, cost_force=c.force,
        cost_strouhal=c.strouhal_penalty, cost_amplitude=c.amplitude, cost_smoothness=c.smoothness,
        st=c.st, mean_force=c.mean_force, solve_time=time.perf_counter() - t0, **extra,
    )


class ManoeuvreFinPlanner:
    """The identification manoeuvre for one fin; its clock starts at its first plan."""

    def __init__(self, cfg: ManoeuvreConfig, mpc: MpcConfig) -> None:
        self.cfg = mpc
        self._planner = ManoeuvrePlanner(cfg, mpc)
        self._scorer = FinMpc(mpc)
        self._t0: float | None = None

    def __call__(self, x: PlanInputs) -> FinPlan:
        t0 = time.perf_counter()
        if self._t0 is None:
            self._t0 = x.t
        theta, offset = _wrapped(x.theta0)
        u, commands = self._planner.plan(x.t - self._t0, theta)
        return _scored(self._scorer, x, theta, u, _shift(commands, offset), t0)


Planner = Callable[[PlanInputs], FinPlan]


class PlanJob:
    """One submitted plan: its result once done, and when it was done (wall clock)."""

    __slots__ = ("inputs", "outcome", "error", "done_wall", "_future")

    def __init__(self, inputs: PlanInputs) -> None:
        self.inputs = inputs
        self.outcome: FinPlan | None = None
        self.error: BaseException | None = None
        self.done_wall = math.inf
        self._future: Future | None = None

    def run(self, planner: Planner) -> None:
        try:
            self.outcome = planner(self.inputs)
        except BaseException as e:  # handed to the loop's thread by wait()
            self.error = e
        self.done_wall = time.perf_counter()

    def wait(self) -> FinPlan:
        """The outcome (blocking until the planner is done); a planner error is raised here."""
        if self._future is not None:
            self._future.result()
        if self.error is not None:
            raise self.error
        assert self.outcome is not None
        return self.outcome


class PlanningService:
    """Runs planners: inline (headless) or one thread per logical fin (real time)."""

    threaded = False

    def submit(self, key: Hashable, planner: Planner, inputs: PlanInputs) -> PlanJob:
        job = PlanJob(inputs)
        job.run(planner)
        return job

    def close(self) -> None:
        pass


InlinePlanning = PlanningService


class ThreadedPlanning(PlanningService):
    """One worker thread per logical fin (``key``); jobs of one fin run in order."""

    threaded = True

    def __init__(self) -> None:
        self._pools: dict[Hashable, ThreadPoolExecutor] = {}
        self._lock = threading.Lock()

    def submit(self, key: Hashable, planner: Planner, inputs: PlanInputs) -> PlanJob:
        with self._lock:
            pool = self._pools.get(key)
            if pool is None:
                pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix=f"planner-{key}")
                self._pools[key] = pool
        job = PlanJob(inputs)
        job._future = pool.submit(job.run, planner)
        return job

    @property
    def threads(self) -> int:
        return len(self._pools)

    def close(self) -> None:
        with self._lock:
            pools, self._pools = list(self._pools.values()), {}
        for pool in pools:
            pool.shutdown(wait=True, cancel_futures=True)
