"""E7's oracle: a fin planner that plans with the plant's true force and battery power.

The upper bound of what planning can save on a plant: it knows what the controllers must
identify. Before a run it measures, on the plant itself (``fin_rig.FinRig``: the plant's
servo and hydrodynamics, the hull held at a speed), the mean fin-frame force and the battery
power of its drive (``robot.motor``) for symmetric stroke pairs over a grid of hull speeds, centres, amplitudes and mean
rates (:func:`oracle_table`, cached per process). Each plan picks the grid cycle at the
measured speed (linear between the two nearest grid speeds) that minimises

    J = lam_f (|f_x - f_x*| + |f_y - f_y*|) + lam_e P,

the closed-stroke MPC's force and energy weights on the true force and the battery's power
(no Strouhal term: nothing here needs one), and executes it as the baseline does: the
first stroke to the extreme of the cycle farther from the fin, the second to the other.
"""

from __future__ import annotations

import functools
import math
import time

import numpy as np

from ucat_console.control.baseline import wrap_angle
from ucat_console.control.mpc import FinMpc
from ucat_console.control.params import MpcConfig
from ucat_console.backend.fin_rig import FinMeans, FinRig
from ucat_console.backend.sim.variants import plant_config
from ucat_console.telemetry.messages import FinPlan

ORACLE_SPEEDS = tuple(round(0.05 * k, 2) for k in range(11))  # 0 .. 0.5 m/s
ORACLE_CENTRES = tuple(2.0 * math.pi * k / 36 - math.pi for k in range(36))
ORACLE_AMPLITUDES = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6)
ORACLE_RATES = (0.5, 0.8, 1.2, 1.8, 2.6, 3.6, 5.0, 7.0)


#: each pair of neighbouring grid rates is split into this many steps (linear in between)
RATE_SPLIT = 4


def _force_and_battery(m: FinMeans) -> tuple[float, float, float]:
    return m.fx, m.fy, m.electrical


@functools.lru_cache(maxsize=8)
def oracle_table(plant: str) -> tuple[np.ndarray, np.ndarray]:
    """(cycles (n, 3): centre, amplitude, rate; values (speeds, n, 3): f_x, f_y, battery power) of
    ``plant`` (module docstring): the measured grid, each rate interval split in
    :data:`RATE_SPLIT` (force and power linear in between)."""
    rig = FinRig(plant_config(plant, 0))
    cycles, vals = [], []
    for c in ORACLE_CENTRES:
        for a in ORACLE_AMPLITUDES:
            rates = [w for w in ORACLE_RATES if w <= rig.mean_rate_limit(2.0 * a)]
            m = np.array([[_force_and_battery(rig.cycle(v, c, a, w, cycles=2, measured=1)) for w in rates]
                          for v in ORACLE_SPEEDS])  # (speeds, rates, 3)
            for k in range(len(rates)):
                for s in range(RATE_SPLIT if k + 1 < len(rates) else 1):
                    f = s / RATE_SPLIT
                    cycles.append((c, a, (1.0 - f) * rates[k] + f * rates[min(k + 1, len(rates) - 1)]))
                    vals.append((1.0 - f) * m[:, k] + f * m[:, min(k + 1, len(rates) - 1)])
    return np.asarray(cycles), np.stack(vals, axis=1)


class OraclePlanner:
    """One fin's oracle planner (callable like the loop's planners)."""

    def __init__(self, plant: str, cfg: MpcConfig) -> None:
        self.cfg = cfg
        self._cycles, self._vals = oracle_table(plant)
        self._scorer = FinMpc(cfg)

    def choose(self, target: tuple[float, float], v_body: float) -> tuple[float, float, float, float, float, float]:
        """(centre, amplitude, rate, f_x, f_y, power) of the best grid cycle at ``v_body``."""
        v = min(max(v_body, ORACLE_SPEEDS[0]), ORACLE_SPEEDS[-1])
        i = min(int(v / ORACLE_SPEEDS[1]), len(ORACLE_SPEEDS) - 2)
        s = (v - ORACLE_SPEEDS[i]) / ORACLE_SPEEDS[1]
        vals = (1.0 - s) * self._vals[i] + s * self._vals[i + 1]
        j_cost = self.cfg.lam_f * (np.abs(vals[:, 0] - target[0]) + np.abs(vals[:, 1] - target[1])) \
            + self.cfg.lam_e * vals[:, 2]
        k = int(np.argmin(j_cost))
        c, a, w = self._cycles[k]
        return float(c), float(a), float(w), float(vals[k, 0]), float(vals[k, 1]), float(vals[k, 2])

    def __call__(self, x) -> FinPlan:  # x: backend.loop.planners.PlanInputs
        t0 = time.perf_counter()
        theta = wrap_angle(x.theta0)
        offset = x.theta0 - theta
        if x.target[0] == 0.0 and x.target[1] == 0.0:
            u = (0.0, 0.0, self.cfg.w_min, self.cfg.w_min)
            commands = (x.theta0, self.cfg.w_min, x.theta0, self.cfg.w_min)
            fx = fy = 0.0
        else:
            c, a, w, fx, fy, _ = self.choose(x.target, x.v_body)
            c = theta + wrap_angle(c - theta)  # the centre nearest the fin
            upper, lower = c + a, c - a
            first, second = (lower, upper) if abs(lower - theta) > abs(upper - theta) else (upper, lower)
            u = (first - theta, second - first, w, w)
            commands = (first + offset, w, second + offset, w)
        cost = self._scorer.score(u, x.target, x.v_body, theta, x.u_prev) if abs(u[0]) > 1e-9 else None
        return FinPlan(
            t=x.t, fin=-1, mode="", target=x.target, v_body=x.v_body, theta0=x.theta0, u_prev=x.u_prev,
            late=False, u=u, commands=commands,
            cost_total=cost.total if cost else 0.0,
            cost_force=abs(fx - x.target[0]) + abs(fy - x.target[1]),
            cost_strouhal=cost.strouhal_penalty if cost else 0.0,
            cost_amplitude=cost.amplitude if cost else 0.0,
            cost_smoothness=cost.smoothness if cost else 0.0,
            st=cost.st if cost else 0.0, mean_force=(fx, fy), solve_time=time.perf_counter() - t0,
        )
