"""The Strouhal-aware fin MPC (control.md section 4, paper Algorithm 1).

:class:`FinMpc` plans one fin's next cycle. Two stage-2 implementations share one
sampler contract and one cost definition:

- ``solver="numba"`` (production): one compiled, allocation-free call per solve; stage 1
  draws ``n_samples`` admissible stroke pairs, stage 2 refines the ``refine_starts`` best
  with a projected BFGS method using the analytic gradient.
- ``solver="scipy"`` (the paper's path, kept as the reference): numpy sampling, then
  ``scipy.optimize.minimize(method="L-BFGS-B")`` with finite-difference gradients and
  ``maxiter=max_iter`` from the best sample.

Both keep each stroke's sign from its warm start and never return a plan worse than it.

Beyond the paper, two things make a plan the one that runs. Given the fin drives' timing
(``FinMpc(..., drive=ExecutorConfig)``), the cost caps each stroke's rate at what the drive
can make of it (``control.stroke_timing``), so the solver searches the plans the drive runs,
and the plan's rates are capped the same way. With ``MpcConfig.centre_rate`` > 0 the
cycle that runs is laid about the oscillation centre the target's direction asks for
(:func:`centred_cycle`), and its amplitude and rates are those of least cost (the same
trade-off of force, Strouhal number, amplitude and smoothness) among the centred cycles of
the solver's amplitude and rates and of a grid (``MpcConfig.centre_grid``): the solver
chooses them for a cycle from where the fin is, which, laid about another centre, can make
a fraction of the force. With ``MpcConfig.align`` > 0 and a duration asked (to end with
the fin across the hull), the cycle is the one nearest that duration among those costing at
most that fraction more than the best. The plan returned is the cycle as it runs, with its cost.
The compiled solver also solves the closed-stroke formulation (``formulation =
"closed_stroke"``, see :mod:`ucat_console.control.cost`), with its own compiled entry points.

Time: like the rest of the core, the planner reads no clock. A caller that wants the two
stages timed gives the planner its clock (``FinMpc(cfg, clock=time.perf_counter)``); the
compiled solver then runs as two calls (sampling, then refinement) with the clock read
between them, and :attr:`Plan.sample_time_s` / :attr:`Plan.refine_time_s` hold the stage
times. Without a clock (the loop, which times the whole plan itself, and the benchmark,
which times the whole call) the solve is one compiled call and both times are NaN.
"""

from __future__ import annotations

import functools
import math
import os
from typing import Callable, NamedTuple, Sequence

import numpy as np

from ucat_console.control import mpc_kernels as K
from ucat_console.control.cost import H, CostBreakdown, breakdown_from_terms, cost_terms, timed_rates
from ucat_console.control.fin_model import ForceTable
from ucat_console.control.params import ExecutorConfig, MpcConfig
from ucat_console.control.stroke_timing import mean_rate_limit

#: allowed ranges of the planner's inputs (besides finiteness)
MAX_TARGET_N = 100.0
MAX_SPEED = 10.0
MAX_ANGLE = 4.0 * math.pi
MAX_RATE_PREV = 1000.0


class Plan(NamedTuple):
    """One planned cycle of one fin (a typed named tuple, like :class:`CostBreakdown`:
    one is built for every solve)."""

    u: tuple[float, float, float, float]  # [d_1, d_2, w_1, w_2]
    cost: CostBreakdown
    commands: tuple[float, float, float, float]  # [theta_1, w_1, theta_2, w_2]
    sample_time_s: float  # s by the planner's clock; NaN without one
    refine_time_s: float  # s by the planner's clock; NaN without one
    warm_start: tuple[float, float, float, float]
    warm_start_cost: float

    @property
    def solve_time_s(self) -> float:
        return self.sample_time_s + self.refine_time_s


def _check_finite(name: str, value: float, lo: float, hi: float) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a number in [{lo}, {hi}], got {value!r}") from None
    if not lo <= v <= hi:  # also false for NaN
        raise ValueError(f"{name}: {value!r} is out of range; allowed: finite, in [{lo}, {hi}]")
    return v


def _check_vector(name: str, value: Sequence[float], n: int, lo: float, hi: float) -> tuple[float, ...]:
    """A length-n vector of finite numbers in [lo, hi] (plain Python: this is on the
    planner's hot path, where numpy's per-call overhead would dominate)."""
    try:
        out = tuple(_check_finite(f"{name}[{i}]", x, lo, hi) for i, x in enumerate(value))
    except TypeError:
        out = ()
    if len(out) != n:
        raise ValueError(f"{name}: expected shape ({n},), got {np.shape(value)}")
    return out


def check_config(cfg: MpcConfig) -> ForceTable | None:
    """The one check of an MPC configuration beyond its fields' (``MpcConfig`` checks those
    when it is made): its force table (None: the analytic model), loaded or built and checked
    to span the decision box; ValueError naming what is wrong. Each configuration (and table
    file version) is checked once: the caller changing it checks it, the planners made of
    it take the result."""
    if cfg.force_model != "table":
        return None
    stamp = None
    if cfg.table_path:
        try:
            st = os.stat(cfg.table_path)
            stamp = (st.st_mtime_ns, st.st_size)
        except OSError:
            pass  # the load names the missing file
    return _checked_table(cfg, stamp)


@functools.lru_cache(maxsize=8)
def _checked_table(cfg: MpcConfig, stamp: tuple[int, int] | None) -> ForceTable:
    table = ForceTable.load(cfg.table_path) if cfg.table_path else ForceTable.from_model(cfg)
    if not table.covers(cfg):
        raise ValueError(
            f"table_path: force table spans d [{table.d[0]}, {table.d[-1]}], "
            f"w [{table.w[0]}, {table.w[-1]}]; it must cover d in "
            f"[-{cfg.d_max}, {cfg.d_max}] and w in [{cfg.w_min}, {cfg.w_max}]"
        )
    return table


class FinMpc:
    """Planner for one fin. Not thread-safe: give each planner thread its own instance."""

    def __init__(
        self, config: MpcConfig | None = None, seed: int | None = None,
        clock: Callable[[], float] | None = None, drive: ExecutorConfig | None = None,
    ) -> None:
        """``clock`` (seconds, e.g. ``time.perf_counter``): time the two stages with it.
        ``drive``: the fin drives' timing; a plan's rates are then at most what the drive
        can make of its strokes (:meth:`plan`)."""
        self.config = config or MpcConfig()
        self._clock = clock
        self._drive = None if drive is None else (float(drive.acceleration), float(drive.max_rate))
        cfg = self.config
        table = check_config(cfg)
        self.table: ForceTable | None = table
        if table is not None:
            self._gx, self._gy = table.stroke_frame()
            axes = (table.d[0], table.d[1] - table.d[0], table.w[0], table.w[1] - table.w[0])
            self._params = K.pack_params(cfg, axes, self._drive)
        else:
            self._gx = self._gy = np.zeros((2, 2))
            self._params = K.pack_params(cfg, None, self._drive)
        (self._plan_kernel, self._sample_kernel, self._finish_kernel,
         self._cost_kernel) = K.KERNELS[(cfg.formulation, cfg.force_model)]
        self._rng = np.zeros(1, dtype=np.uint64)
        self._rng[0] = np.uint64(seed if seed is not None else 0x5EED)
        self._best_u = np.zeros((cfg.refine_starts, 4))
        self._best_j = np.zeros(cfg.refine_starts)
        self._block = np.zeros((5, K.SAMPLE_BLOCK))
        self._work = np.zeros((8, 4))
        self._runs = np.zeros((cfg.refine_starts + 1, K.RUN))
        self._u = np.zeros(4)
        self._terms = np.zeros(K.N_TERMS)
        self._grad = np.zeros(4)
        self._np_rng = np.random.default_rng(seed)
        # the cycles the executable plan is chosen among (``_executable``), and the grid's steps
        w_hi = cfg.w_max if self._drive is None else min(cfg.w_max, max(cfg.w_min, mean_rate_limit(
            cfg.d_max, *self._drive)))
        self._grid, self._steps = cycle_grid(cfg.centre_grid, 0.5 * cfg.d_eps, 0.5 * cfg.d_max, cfg.w_min, w_hi)

    # ------------------------------------------------------------------ validation
    def _inputs(self, f_target, v_body, theta0, u_prev) -> tuple[tuple, float, float, tuple]:
        """The planner's inputs as numbers, each finite and in its range; ValueError naming
        the first that is not (the common case, all good, is checked in one expression)."""
        try:
            fx, fy = f_target
            u0, u1, u2, u3 = u_prev
            f = (float(fx), float(fy))
            v, th = float(v_body), float(theta0)
            up = (float(u0), float(u1), float(u2), float(u3))
        except (TypeError, ValueError):
            pass  # the checks below say what is wrong
        else:
            t, r = MAX_TARGET_N, MAX_RATE_PREV
            if (-t <= f[0] <= t and -t <= f[1] <= t and -MAX_SPEED <= v <= MAX_SPEED
                    and -MAX_ANGLE <= th <= MAX_ANGLE and -r <= up[0] <= r and -r <= up[1] <= r
                    and -r <= up[2] <= r and -r <= up[3] <= r):
                return f, v, th, up
        f = _check_vector("f_target", f_target, 2, -MAX_TARGET_N, MAX_TARGET_N)
        v = _check_finite("v_body", v_body, -MAX_SPEED, MAX_SPEED)
        th = _check_finite("theta0", theta0, -MAX_ANGLE, MAX_ANGLE)
        up = _check_vector("u_prev", u_prev, 2 * H, -MAX_RATE_PREV, MAX_RATE_PREV)
        return f, v, th, up

    def cost(self, u, f_target, v_body, theta0, u_prev) -> CostBreakdown:
        """J and its terms for plan ``u = [d_1, d_2, w_1, w_2]`` (the compiled cost)."""
        f, v, th, up = self._inputs(f_target, v_body, theta0, u_prev)
        cfg = self.config
        uu = _check_vector("u", u, 2 * H, -cfg.d_max - 1e-12, cfg.w_max + 1e-12)
        for k in range(H):
            if not cfg.d_eps - 1e-12 <= abs(uu[k]) <= cfg.d_max + 1e-12:
                raise ValueError(
                    f"u[{k}] (d_{k + 1}): |{uu[k]}| outside [{cfg.d_eps}, {cfg.d_max}] rad"
                )
            if not cfg.w_min - 1e-12 <= uu[H + k] <= cfg.w_max + 1e-12:
                raise ValueError(
                    f"u[{H + k}] (w_{k + 1}): {uu[H + k]} outside [{cfg.w_min}, {cfg.w_max}] rad/s"
                )
        problem = K.pack_problem(f, v, th, up)
        terms = np.zeros(K.N_TERMS)
        self._cost_kernel(
            self._params, problem, self._gx, self._gy, np.asarray(uu), np.zeros(4), terms
        )
        return _breakdown(terms)

    def score(self, u: tuple[float, float, float, float], f_target: tuple[float, float], v_body: float,
              theta0: float, u_prev: tuple[float, float, float, float]) -> CostBreakdown:
        """:meth:`cost` of a plan made elsewhere (the baseline's, the manoeuvre's), which may
        lie outside the MPC's box: no argument checks (the caller's values are its own)."""
        problem = K.pack_problem(f_target, v_body, theta0, u_prev)
        self._cost_kernel(self._params, problem, self._gx, self._gy, np.asarray(u, dtype=float),
                          self._grad, self._terms)
        return _breakdown(self._terms)

    def cost_gradient(self, u, f_target, v_body, theta0, u_prev) -> np.ndarray:
        """Analytic (sub)gradient of J at ``u`` (compiled)."""
        f, v, th, up = self._inputs(f_target, v_body, theta0, u_prev)
        uu = np.asarray(u, dtype=float)
        problem = K.pack_problem(f, v, th, up)
        grad = np.zeros(4)
        self._cost_kernel(self._params, problem, self._gx, self._gy, uu, grad, np.zeros(K.N_TERMS))
        return grad

    # ------------------------------------------------------------------ planning
    def plan(self, f_target, v_body, theta0, u_prev, seed: int | None = None, refine: bool = True,
             duration: float = math.nan) -> Plan:
        """Plan the next cycle from angle ``theta0`` (Algorithm 1).

        ``seed`` makes this solve reproducible; without it the planner's own random
        stream continues. ``refine=False`` runs stage 1 only. ``duration`` (s; NaN: none)
        is how long the cycle would last to end with the partner fin's (``MpcConfig.align``).
        """
        f, v, th, up = self._inputs(f_target, v_body, theta0, u_prev)
        if self.config.solver == "scipy":
            return self._plan_scipy(f, v, th, up, seed, refine)
        if seed is not None:
            self._rng[0] = np.uint64(seed & 0xFFFFFFFFFFFFFFFF)
        problem = K.pack_problem(f, v, th, up)
        cfg = self.config
        max_iter = cfg.max_iter if refine else 0
        clock = self._clock
        if clock is None:
            self._plan_kernel(
                self._params, problem, self._gx, self._gy, cfg.n_samples, max_iter, self._rng,
                self._best_u, self._best_j, self._block, self._work, self._runs, self._u, self._terms,
            )
            t_sample = t_refine = math.nan
        else:
            t0 = clock()
            self._sample_kernel(self._params, problem, self._gx, self._gy, cfg.n_samples, self._rng,
                            self._best_u, self._best_j, self._block, self._u)
            t1 = clock()
            self._finish_kernel(self._params, problem, self._gx, self._gy, max_iter, self._best_u,
                            self._best_j, self._work, self._runs, self._u, self._terms)
            t_sample, t_refine = t1 - t0, clock() - t1
        u = self._u.tolist()
        if not all(map(math.isfinite, u)) or not math.isfinite(self._terms[K.T_TOTAL]):
            raise FloatingPointError(f"planner produced a non-finite plan {u}")
        cost = _breakdown(self._terms)
        if self._drive is not None or cfg.centre_rate > 0.0:
            u, cost = self._executable(u, f, v, th, up, duration)
        return self._make_plan(
            tuple(u), cost, th, t_sample, t_refine,
            tuple(self._best_u[0].tolist()), float(self._best_j[0]),
        )

    def _timed(self, u: Sequence[float]) -> list[float]:
        """``u`` with each rate at most what the drive makes of its stroke."""
        if self._drive is None:
            return u
        a, w_max = self._drive
        return [u[0], u[1], min(u[2], max(self.config.w_min, mean_rate_limit(u[0], a, w_max))),
                min(u[3], max(self.config.w_min, mean_rate_limit(u[1], a, w_max)))]

    def _timed_all(self, u: np.ndarray) -> np.ndarray:
        """:meth:`_timed` of every plan of ``u`` (shape (..., 4))."""
        return u if self._drive is None else timed_rates(u, self.config, self._drive)

    def _bounded(self, duration: np.ndarray, cost: np.ndarray) -> np.ndarray:
        """``cost`` with the cycles longer than ``max_cycle`` out of the running (all of them
        but the shortest when none is within it)."""
        limit = self.config.max_cycle
        if limit <= 0.0:
            return cost
        ok = duration <= limit
        if not ok.any():
            ok = duration <= duration.min()
        return np.where(ok, cost, np.inf)

    def _executable(self, u: list[float], f: tuple, v: float, th: float, up: tuple,
                    duration: float = math.nan) -> tuple[list[float], CostBreakdown]:
        """The solved plan as it will run (beyond the paper; module docstring): centred on
        the oscillation centre the target's direction asks for, with the amplitude and rates
        of least cost among the solver's and the grids' (:func:`cycle_grid`, then
        :func:`fine_grid` about the best), and its rates timed by the drive; with
        ``MpcConfig.align`` and a ``duration``, the one nearest that duration among those
        costing little more. Returns the plan and its cost."""
        cfg = self.config
        if not (cfg.centre_rate > 0.0 and math.hypot(*f) >= 1e-3):
            out = self._timed(u)
            return out, self.score(tuple(out), f, v, th, up)
        rows = np.vstack([np.asarray(u, dtype=float)[None], self._grid])
        cycles = self._timed_all(centred_cycles(rows, f, th, up, cfg))
        raw = cost_terms(cycles, f, v, th, up, cfg, self.table)["total"]
        k = int(np.argmin(self._bounded(_durations(cycles), raw)))
        fine = fine_grid(rows[k], *self._steps)
        if len(fine):  # the fine grid about the best, which stays if none is better
            more = self._timed_all(centred_cycles(fine, f, th, up, cfg))
            cycles = np.vstack([cycles, more])
            raw = np.concatenate([raw, cost_terms(more, f, v, th, up, cfg, self.table)["total"]])
        durations = _durations(cycles)
        cost = self._bounded(durations, raw)
        k = int(np.argmin(cost))
        if cfg.align > 0.0 and math.isfinite(duration):
            near = cost <= cost[k] + cfg.align * abs(cost[k])
            k = int(np.argmin(np.where(near, np.abs(durations - duration), np.inf)))
        out = cycles[k].tolist()
        return out, self.score(tuple(out), f, v, th, up)

    def _plan_scipy(self, f, v, th, up, seed, refine) -> Plan:
        import scipy.optimize  # here only: nothing else of the console imports scipy.optimize

        cfg = self.config
        rng = np.random.default_rng(seed) if seed is not None else self._np_rng
        clock = self._clock or (lambda: math.nan)
        t0 = clock()
        n = cfg.n_samples
        mag = rng.uniform(cfg.d_eps, cfg.d_max, size=(n, H))
        w = rng.uniform(cfg.w_min, cfg.w_max, size=(n, H))
        sign = np.where(rng.random(n) < 0.5, 1.0, -1.0)
        d = np.stack([sign * mag[:, 0], -sign * mag[:, 1]], axis=1)
        samples = np.concatenate([d, w], axis=1)
        j = cost_terms(samples, f, v, th, up, cfg, self.table)["total"]
        best = int(np.argmin(j))
        u0 = samples[best]
        j0 = float(j[best])
        t1 = clock()
        u_best = u0
        if refine and cfg.max_iter > 0:
            bounds = [
                (cfg.d_eps, cfg.d_max) if u0[k] > 0 else (-cfg.d_max, -cfg.d_eps) for k in range(H)
            ] + [(cfg.w_min, cfg.w_max)] * H

            def fun(x: np.ndarray) -> float:
                return float(cost_terms(x, f, v, th, up, cfg, self.table)["total"])

            res = scipy.optimize.minimize(
                fun, u0, method="L-BFGS-B", bounds=bounds, options={"maxiter": cfg.max_iter}
            )
            x = np.clip(res.x, [b[0] for b in bounds], [b[1] for b in bounds])
            jx = fun(x)
            if np.all(np.isfinite(x)) and jx < j0:
                u_best = x
        t2 = clock()
        terms = cost_terms(u_best, f, v, th, up, cfg, self.table)
        return self._make_plan(
            tuple(float(x) for x in u_best), breakdown_from_terms(terms), th,
            t1 - t0, t2 - t1, tuple(float(x) for x in u0), j0,
        )

    @staticmethod
    def _make_plan(u, cost, theta0, t_sample, t_refine, warm, warm_cost) -> Plan:
        theta1 = theta0 + u[0]
        theta2 = theta1 + u[1]
        return Plan(
            u=u,
            cost=cost,
            commands=(theta1, u[2], theta2, u[3]),
            sample_time_s=t_sample,
            refine_time_s=t_refine,
            warm_start=warm,
            warm_start_cost=warm_cost,
        )


def centred_cycle(u: Sequence[float], f_target: Sequence[float], theta0: float, u_prev: Sequence[float],
                  cfg: MpcConfig) -> list[float]:
    """The plan ``u`` made a cycle about the oscillation centre the target asks for.

    A symmetric stroke pair about a centre ``c`` makes its mean force point at ``c +
    atan2(-C_D, -C_L)`` (``control.baseline``), so the target's direction asks for the
    centre ``c*``. The centre moves there from the last cycle's (the middle of its last
    stroke, ``theta0 - u_prev[1] / 2``) by at most ``centre_rate`` times the plan's duration.
    The cycle keeps the solver's amplitude ``A`` (the mean of its half strokes) and rates:
    its first stroke takes the fin from ``theta0`` across the centre to ``c -+ A``, its second
    sweeps to ``c +- A``; in steady state (the fin at one end of the last cycle) the two
    strokes are the same sweep back and forth about ``c``."""
    return centred_cycles(np.asarray(u, dtype=float), f_target, theta0, u_prev, cfg).tolist()


def centred_cycles(u: np.ndarray, f_target: Sequence[float], theta0: float, u_prev: Sequence[float],
                   cfg: MpcConfig) -> np.ndarray:
    """:func:`centred_cycle` of every plan of ``u`` (shape (..., 4))."""
    want = math.atan2(f_target[1], f_target[0]) - math.atan2(-cfg.c_d, -cfg.c_l)
    prev = theta0 - 0.5 * u_prev[1]
    d = np.abs(u[..., :H])
    limit = cfg.centre_rate * (d[..., 0] / u[..., 2] + d[..., 1] / u[..., 3])
    centre = prev + np.clip(math.remainder(want - prev, 2.0 * math.pi), -limit, limit)
    rel = theta0 - centre  # where the fin is, from the centre (wrapped as math.remainder does, exactly)
    rel = rel - 2.0 * math.pi * np.round(rel / (2.0 * math.pi))
    side = np.where(rel >= 0.0, 1.0, -1.0)
    amplitude = 0.25 * (d[..., 0] + d[..., 1])
    return np.stack([-rel - side * amplitude, 2.0 * side * amplitude, u[..., 2], u[..., 3]], axis=-1)


def _durations(cycles: np.ndarray) -> np.ndarray:
    """Each cycle's duration (s; shape (n, 4) -> (n,))."""
    return np.abs(cycles[:, 0]) / cycles[:, 2] + np.abs(cycles[:, 1]) / cycles[:, 3]


def cycle_grid(n: int, a_lo: float, a_hi: float, w_lo: float, w_hi: float
               ) -> tuple[np.ndarray, tuple[float, float, float, float, float, float]]:
    """The symmetric cycles ``[2 A, -2 A, w, w]`` of ``n`` amplitudes A in [a_lo, a_hi] by ``n``
    rates w in [w_lo, w_hi] (shape (n * n, 4); none for n = 0), and the grid's (amplitude
    step, rate step, the four bounds) for :func:`fine_grid`."""
    if n == 0:
        return np.zeros((0, 4)), (0.0, 0.0, a_lo, a_hi, w_lo, w_hi)
    a, w = np.meshgrid(np.linspace(a_lo, a_hi, n), np.linspace(w_lo, w_hi, n), indexing="ij")
    a, w = a.ravel(), w.ravel()
    steps = ((a_hi - a_lo) / max(1, n - 1), (w_hi - w_lo) / max(1, n - 1), a_lo, a_hi, w_lo, w_hi)
    return np.stack([2.0 * a, -2.0 * a, w, w], axis=-1), steps


def fine_grid(about: np.ndarray, da: float, dw: float, a_lo: float, a_hi: float, w_lo: float, w_hi: float
              ) -> np.ndarray:
    """Symmetric cycles a quarter of a coarse step (``da``, ``dw``) apart, to one step either
    side of the amplitude and first rate of the cycle ``about``, within the bounds (none if
    ``da`` is 0): the force grows with the rate squared, and half a step of the rate (some
    12 % of the force) left the fins' forward forces unequal enough to turn the robot."""
    if da == 0.0:
        return np.zeros((0, 4))
    a0, w0 = 0.25 * (abs(about[0]) + abs(about[1])), about[2]
    a = np.clip(a0 + da * np.linspace(-1.0, 1.0, 9), a_lo, a_hi)
    w = np.clip(w0 + dw * np.linspace(-1.0, 1.0, 9), w_lo, w_hi)
    aa, ww = np.meshgrid(a, w, indexing="ij")
    aa, ww = aa.ravel(), ww.ravel()
    return np.stack([2.0 * aa, -2.0 * aa, ww, ww], axis=-1)


def _breakdown(terms: np.ndarray) -> CostBreakdown:
    t = terms.tolist()
    return CostBreakdown(
        total=t[K.T_TOTAL],
        force=t[K.T_FORCE],
        strouhal_penalty=t[K.T_ST_PEN],
        amplitude=t[K.T_AMP],
        smoothness=t[K.T_DIFF],
        st=t[K.T_ST],
        mean_force=(t[K.T_FBX], t[K.T_FBY]),
        closure=t[K.T_CLOSE],
        energy=t[K.T_ENERGY],
    )
