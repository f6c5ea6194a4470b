"""One fin of the plant beating at a held hull speed: what its strokes and cycles make and cost.

The open-loop view of the plant the efficiency experiment (E7) declares before it runs and
the plant benchmark checks (``bench plant``): a fin driven through the plant's own servo
profile (``robot.servo``) and hydrodynamics (``plate``), the hull held at a surge speed
through the water, with no body dynamics. :func:`stroke` runs one stroke from rest to rest; :func:`cycle` runs symmetric
stroke pairs about a centre until they repeat and measures the last ones. Both return the
mean fin-frame force (N), the mean true shaft power (W, no regeneration), the duration (s)
and the mean battery power of the fin's drive (W, ``robot.motor``), the same quantities the
plant integrates in a closed-loop run.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from numba import njit

from ucat_console.backend.sim.fin_hydro import (
    H_COS_A,
    H_ETA_B,
    H_ETA_G,
    H_I_0,
    H_J_R,
    H_K_T,
    H_N_G,
    H_P_Q,
    H_PLATE,
    H_R_M,
    hydro_params,
)
from ucat_console.backend.sim.params import PlantConfig
from ucat_console.backend.sim.plate import NP, fin_load
from ucat_console.backend.sim.variants import plant_config
from ucat_console.control.baseline import BaselinePlanner
from ucat_console.control.params import BaselineConfig, MpcConfig
from ucat_console.control.stroke_timing import mean_rate_limit, profile_velocity
from ucat_console.robot.motor import battery_power, motor_current
from ucat_console.robot.servo import servo_step


#: fin angle (rad) at the start of every run: the centre of a forward-thrust stroke pair,
#: about which a symmetric pair pushes straight forward under the controller's model (the
#: baseline's oscillation centre for a pure thrust demand)
START_FIN_ANGLE = BaselinePlanner(MpcConfig(), BaselineConfig()).centre(-1.0, 0.0, 0.0)
#: amplitudes (rad, half the stroke) and per-fin St grid of :func:`curve`
AMPLITUDES = tuple(round(0.1 + 0.05 * k, 2) for k in range(11))
ST_GRID = tuple(round(0.05 * k, 2) for k in range(1, 21))
#: the paper's St corridor
CORRIDOR = (0.25, 0.35)


class FinMeans(NamedTuple):
    """Means over a stroke or the measured cycles: fin-frame force, shaft power, time."""

    fx: float  # N, fin frame (x_m rearwards: f_x < 0 pushes the hull forward)
    fy: float  # N, fin frame (y_m up)
    power: float  # W, true shaft power
    duration: float  # s
    electrical: float  # W, battery power of the fin's drive

    def thrust(self, cos_mount: float) -> float:
        """The forward force on the hull (N): ``-f_x cos(mounting angle)``."""
        return -self.fx * cos_mount


@njit(cache=True)
def _run(ph, acc, vmax, inertia, dt, surge, start, targets, vel, n_skip, max_steps):
    """Drive the fin from rest at ``start`` through ``targets`` (each reached at rest before
    the next is sent, at profile velocity ``vel``); integrate force, shaft and battery
    power over every stroke after the first ``n_skip``. Returns (fx, fy, shaft energy, time,
    battery energy) sums."""
    theta = start
    omega = 0.0
    pf = ph[H_PLATE:H_PLATE + NP]
    k_t, r_m, i_0, j_r = ph[H_K_T], ph[H_R_M], ph[H_I_0], ph[H_J_R]
    n_g, eta_g, eta_b, p_q = ph[H_N_G], ph[H_ETA_G], ph[H_ETA_B], ph[H_P_Q]
    flow = surge * ph[H_COS_A]
    sx = sy = se = st_time = sb = 0.0
    k = 0
    steps = 0
    while k < targets.shape[0] and steps < max_steps:
        steps += 1
        theta, omega, al = servo_step(theta, omega, targets[k], vel, acc, vmax, dt)
        fx, fy, torque, p, _ = fin_load(theta, omega, al, flow, 0.0, inertia, dt, pf)
        if k >= n_skip:
            current = motor_current(torque, omega, al, k_t, i_0, j_r, n_g, eta_g)
            sx += fx * dt
            sy += fy * dt
            se += p * dt
            sb += battery_power(current, omega, k_t, r_m, n_g, eta_b, p_q) * dt
            st_time += dt
        if omega == 0.0 and theta == targets[k]:
            k += 1
    return sx, sy, se, st_time, sb


class FinRig:
    """One fin of a plant (its hydrodynamics, servo and fin inertia) at a held hull speed."""

    def __init__(self, plant: PlantConfig) -> None:
        self.plant = plant
        self._ph = hydro_params(plant.hydro, plant.fins, plant.motor)
        self._acc = float(plant.servo.acceleration)
        self._vmax = float(plant.servo.max_rate)
        self._inertia = float(plant.fins.fin_inertia)
        self._dt = float(plant.dt)
        self.cos_mount = math.cos(math.radians(plant.fins.mounting_angle_deg))

    def mean_rate_limit(self, stroke: float) -> float:
        """The fastest mean rate (rad/s) of a stroke of ``|stroke|`` on this plant's servo."""
        return mean_rate_limit(stroke, self._acc, self._vmax)

    def _means(self, surge: float, start: float, targets: np.ndarray, rate: float, n_skip: int) -> FinMeans:
        vel = profile_velocity(abs(targets[0] - start), rate, self._acc, self._vmax)
        budget = int(20.0 * targets.size * (abs(targets[0] - start) / max(rate, 1e-3) + 1.0) / self._dt)
        sx, sy, se, t, sb = _run(self._ph, self._acc, self._vmax, self._inertia, self._dt, float(surge),
                                 float(start), targets, vel, n_skip, budget)
        if t <= 0.0:
            raise ValueError(f"fin rig: the strokes from {start} did not finish (rate {rate})")
        return FinMeans(sx / t, sy / t, se / t, t, sb / t)

    def stroke(self, surge: float, start: float, d: float, rate: float) -> FinMeans:
        """One stroke of ``d`` rad from rest at ``start``, timed for the mean ``rate`` (rad/s;
        the servo's fastest if it cannot), at hull speed ``surge`` (m/s through the water)."""
        return self._means(surge, start, np.array([start + d]), rate, 0)

    def cycle(self, surge: float, centre: float, amplitude: float, rate: float, cycles: int = 3,
              measured: int = 2) -> FinMeans:
        """Symmetric stroke pairs between ``centre -+ amplitude`` at the mean ``rate``, from
        rest at ``centre - amplitude``; the means of the last ``measured`` cycles."""
        targets = np.array([centre + amplitude, centre - amplitude] * cycles)
        return self._means(surge, centre - amplitude, targets, rate, 2 * (cycles - measured))


def hull_thrust(plant: PlantConfig, v: float) -> float:
    """The surge force (N) the hull needs to hold ``v`` (its damping)."""
    return -plant.vehicle.x_u * v - plant.vehicle.x_uu * v * v


def curve(plant_name: str, v: float) -> dict[str, Any]:
    """The efficiency-against-St curve of the plant variant ``plant_name`` at ``v`` (module
    docstring)."""
    plant = plant_config(plant_name, 0)
    rig = FinRig(plant)
    l_f = plant.hydro.resolved().fin_length
    need = hull_thrust(plant, v) / 4.0
    eta, amp, feasible = [], [], []
    for st in ST_GRID:
        w = st * 2.0 * v / l_f
        best, best_a, ok = math.nan, math.nan, False
        for a in AMPLITUDES:
            if w > rig.mean_rate_limit(2.0 * a):
                continue
            m = rig.cycle(v, START_FIN_ANGLE, a, w)
            t = m.thrust(rig.cos_mount)
            ok = ok or t >= need
            if t > 0.0 and m.power > 0.0 and not (t * v / m.power <= best):
                best, best_a = t * v / m.power, a
        eta.append(best)
        amp.append(best_a)
        feasible.append(ok)
    e = np.asarray(eta)
    i = int(np.nanargmax(e)) if np.any(np.isfinite(e)) else -1
    sts = [s for s, ok in zip(ST_GRID, feasible) if ok]
    return {"plant": plant_name, "v": v, "st": list(ST_GRID), "eta": eta, "amplitude": amp,
            "feasible": feasible, "thrust_needed_per_fin": need,
            "peak_st": ST_GRID[i] if i >= 0 else math.nan, "peak_eta": float(e[i]) if i >= 0 else math.nan,
            "feasible_st": [min(sts), max(sts)] if sts else None}
