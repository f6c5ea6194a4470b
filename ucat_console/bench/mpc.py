"""The MPC benchmark: control.md section 11 (paper Table IV) and fixed-case quality.

Protocol: 121 targets f_x in {0, -0.1, ..., -1} N x f_y in {0, 0.1, ..., 1} N; each run
for 5 consecutive cycles at V_B = 0.3 m/s from theta = 0 with u_prev = [0.5, -0.5, 2, 2];
after each cycle theta <- wrap(theta + d_1 + d_2) and u_prev <- u. Each solver, stage
(sampling only / two-stage) and N runs the protocol with its own planner seeded once.
A solve's time is the wall time of the whole ``FinMpc.plan`` call.

Both cost formulations run the same protocol (``MpcConfig.formulation``); the scipy
reference solves the paper's only. Their mean costs are of different functions and are
not compared with each other.

Fixed cases (targets, speeds, angles and previous plans drawn once from a seed) measure
solution quality against an exhaustive search: 20,000 samples, then scipy's L-BFGS-B
from the 8 best, and the production refinement from the same 8, keeping the best.
"""

from __future__ import annotations

import math
import subprocess
import sys
import time
from dataclasses import dataclass, field
from typing import Callable, Iterable

import numpy as np

from ucat_console.control import FinMpc, MpcConfig

PAPER_NS = (250, 500, 1000, 1500, 2000, 5000)
SOLVERS = ("numba", "scipy")
FORMULATIONS = ("paper", "closed_stroke")
STAGES = ("sampling", "two_stage")
V_BODY = 0.3
CYCLES = 5
U_PREV0 = (0.5, -0.5, 2.0, 2.0)


def protocol_targets() -> list[tuple[float, float]]:
    """The 121 targets of Table IV."""
    return [(-0.1 * i, 0.1 * j) for i in range(11) for j in range(11)]


def wrap_angle(a: float) -> float:
    """Wrap to (-pi, pi]."""
    w = math.remainder(a, 2.0 * math.pi)
    return math.pi if w == -math.pi else w


@dataclass
class RunResult:
    n: int
    solver: str
    stage: str
    formulation: str = "paper"
    costs: list[float] = field(default_factory=list)
    times_s: list[float] = field(default_factory=list)

    def merge(self, other: RunResult) -> RunResult:
        return RunResult(self.n, self.solver, self.stage, self.formulation,
                         self.costs + other.costs, self.times_s + other.times_s)

    def row(self) -> dict:
        t = np.asarray(self.times_s) * 1e6
        return {
            "n": self.n,
            "solver": self.solver,
            "stage": self.stage,
            "formulation": self.formulation,
            "mean_cost": float(np.mean(self.costs)),
            "p50_us": float(np.percentile(t, 50)),
            "p99_us": float(np.percentile(t, 99)),
            "solves": len(self.costs),
        }


def run_protocol(
    cfg: MpcConfig, refine: bool, seed: int = 0, on_solve: Callable[[], None] | None = None,
    targets: Iterable[tuple[float, float]] | None = None,
) -> RunResult:
    """Section 11's sequential protocol for one configuration (``targets``: a subset of the
    121, for reduced runs)."""
    mpc = FinMpc(cfg, seed=seed)
    result = RunResult(cfg.n_samples, cfg.solver, "two_stage" if refine else "sampling", cfg.formulation)
    clock = time.perf_counter
    for f_target in protocol_targets() if targets is None else targets:
        theta, u_prev = 0.0, U_PREV0
        for _ in range(CYCLES):
            t0 = clock()
            plan = mpc.plan(f_target, V_BODY, theta, u_prev, refine=refine)
            result.times_s.append(clock() - t0)
            result.costs.append(plan.cost.total)
            theta = wrap_angle(theta + plan.u[0] + plan.u[1])
            u_prev = plan.u
            if on_solve:
                on_solve()
    return result


@dataclass(frozen=True)
class FixedCase:
    f_target: tuple[float, float]
    v_body: float
    theta0: float
    u_prev: tuple[float, float, float, float]


def fixed_cases(count: int, seed: int = 2024, cfg: MpcConfig | None = None) -> list[FixedCase]:
    """Cases drawn like the protocol's: a grid target, V in [0.2, 0.4], any angle, and a
    previous plan that is itself admissible."""
    cfg = cfg or MpcConfig()
    rng = np.random.default_rng(seed)
    cases = []
    for _ in range(count):
        fx = -0.1 * rng.integers(0, 11)
        fy = 0.1 * rng.integers(0, 11)
        s = rng.choice([-1.0, 1.0])
        d = rng.uniform(cfg.d_eps, cfg.d_max, 2) * np.array([s, -s])
        w = rng.uniform(cfg.w_min, cfg.w_max, 2)
        cases.append(
            FixedCase(
                (float(fx), float(fy)),
                float(rng.uniform(0.2, 0.4)),
                float(rng.uniform(-math.pi, math.pi)),
                (float(d[0]), float(d[1]), float(w[0]), float(w[1])),
            )
        )
    return cases


def exhaustive_best(case: FixedCase, cfg: MpcConfig, seed: int = 7) -> float:
    """The best cost an exhaustive search finds (see the module docstring)."""
    import scipy.optimize

    from ucat_console.control.cost import cost_terms

    rng = np.random.default_rng(seed)
    n = 20_000
    mag = rng.uniform(cfg.d_eps, cfg.d_max, (n, 2))
    sign = np.where(rng.random(n) < 0.5, 1.0, -1.0)
    u = np.column_stack([sign * mag[:, 0], -sign * mag[:, 1], rng.uniform(cfg.w_min, cfg.w_max, (n, 2))])
    f = np.asarray(case.f_target)
    up = np.asarray(case.u_prev)
    j = cost_terms(u, f, case.v_body, case.theta0, up, cfg)["total"]
    best = float(j.min())
    refiner = FinMpc(cfg.replace(n_samples=1, refine_starts=1))
    for i in np.argsort(j)[:8]:
        u0 = u[i]
        bounds = [
            (cfg.d_eps, cfg.d_max) if u0[k] > 0 else (-cfg.d_max, -cfg.d_eps) for k in range(2)
        ] + [(cfg.w_min, cfg.w_max)] * 2
        res = scipy.optimize.minimize(
            lambda x: float(cost_terms(x, f, case.v_body, case.theta0, up, cfg)["total"]),
            u0, method="L-BFGS-B", bounds=bounds, options={"maxiter": 200},
        )
        best = min(best, float(res.fun))
        best = min(best, _refine_from(refiner, case, u0))
    return best


def _refine_from(mpc: FinMpc, case: FixedCase, u0: np.ndarray) -> float:
    """The production stage 2 run from a given start (no sampling)."""
    from ucat_console.control import mpc_kernels as K

    problem = K.pack_problem(case.f_target, case.v_body, case.theta0, case.u_prev)
    x = np.array(u0, dtype=float)
    return K.refine_kernel(mpc._params, problem, mpc._gx, mpc._gy, x, 200, np.zeros((8, 4)), np.zeros((1, K.RUN)))


def quality_gap(
    cfgs: dict[str, MpcConfig], cases: list[FixedCase], seeds: Iterable[int] = (0, 1, 2)
) -> dict[str, dict]:
    """Mean (and worst) cost above the exhaustive best on fixed cases, per solver."""
    base = next(iter(cfgs.values()))
    best = np.array([exhaustive_best(c, base) for c in cases])
    out = {}
    for name, cfg in cfgs.items():
        gaps = []
        for seed in seeds:
            mpc = FinMpc(cfg)
            for c, b in zip(cases, best):
                plan = mpc.plan(c.f_target, c.v_body, c.theta0, c.u_prev, seed=seed * 1000 + 1)
                gaps.append(plan.cost.total - b)
        g = np.asarray(gaps)
        out[name] = {
            "mean_gap": float(g.mean()),
            "p90_gap": float(np.percentile(g, 90)),
            "max_gap": float(g.max()),
            "cases": len(cases),
            "seeds": len(tuple(seeds)),
        }
    return out


def first_call_latency() -> dict[str, float]:
    """Time of the first plan in a fresh process: with the on-disk cache, and cold
    (an empty cache directory, so every kernel compiles)."""
    import tempfile

    code = (
        "import time; t0 = time.perf_counter();"
        "from ucat_console.control import FinMpc, MpcConfig; t1 = time.perf_counter();"
        "m = FinMpc(MpcConfig()); m.plan((-0.5, 0.5), 0.3, 0.0, (0.5, -0.5, 2.0, 2.0));"
        "t2 = time.perf_counter(); print(t1 - t0, t2 - t1)"
    )
    out = {}
    subprocess.run([sys.executable, "-c", code], check=True, capture_output=True)  # warm cache
    r = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True)
    out["cached_first_plan_s"] = float(r.stdout.split()[1])
    with tempfile.TemporaryDirectory() as tmp:
        import os

        env = dict(os.environ, NUMBA_CACHE_DIR=tmp)
        r = subprocess.run(
            [sys.executable, "-c", code], check=True, capture_output=True, text=True, env=env
        )
    out["cold_first_plan_s"] = float(r.stdout.split()[1])
    return out


def format_table(rows: list[dict]) -> str:
    """Rows as a Table-IV-like text table with numba/scipy speed-up ratios."""
    by = {(r["n"], r["solver"], r["stage"], r.get("formulation", "paper")): r for r in rows}
    ns = sorted({r["n"] for r in rows})
    lines = [
        f"{'N':>6} | {'solver':>6} | {'formulation':>13} | {'sampling: cost':>14} {'p50 us':>9} {'p99 us':>9} "
        f"| {'two-stage: cost':>15} {'p50 us':>9} {'p99 us':>9}"
    ]
    lines.append("-" * len(lines[0]))
    for n in ns:
        for solver, form in [(s, f) for f in FORMULATIONS for s in SOLVERS]:
            s = by.get((n, solver, "sampling", form))
            t = by.get((n, solver, "two_stage", form))
            if not s and not t:
                continue
            cells = []
            for r, w in ((s, 14), (t, 15)):
                if r:
                    cells.append(f"{r['mean_cost']:>{w}.4f} {r['p50_us']:>9.1f} {r['p99_us']:>9.1f}")
                else:
                    cells.append(f"{'-':>{w}} {'-':>9} {'-':>9}")
            lines.append(f"{n:>6} | {solver:>6} | {form:>13} | {cells[0]} | {cells[1]}")
        for stage in STAGES:
            a, b = by.get((n, "numba", stage, "paper")), by.get((n, "scipy", stage, "paper"))
            if a and b:
                lines.append(
                    f"{'':>6}   speed-up {stage}: p50 x{b['p50_us'] / a['p50_us']:.0f}, "
                    f"mean cost numba/scipy {a['mean_cost'] / b['mean_cost']:.4f}"
                )
    return "\n".join(lines)
