"""Where the fins' forces meet the hull: the fins' parameter vector, the fin-to-body map, the
flow past each fin and each fin's recorded Strouhal number.

The force of a fin in the water is the plate's (:mod:`ucat_console.backend.sim.plate`).
This module maps it onto the body (:func:`add_fin_wrench`) and, by the transpose of the same
map, the hull's motion onto the fin (:func:`fin_flow`), so the power a fin delivers to the
hull is exactly its force times its hinge's velocity. It also keeps each fin's Strouhal
number as the plant's truth channel (:func:`fin_strouhal`), which no force reads: St = w_bar
L_f / (2 max(|u_r|, v_floor)), w_bar the fin's mean |rate| (first-order filter, time
constant ``tau_rate``), u_r the hull's surge speed through the water; for H = 2 strokes of
equal size at mean rate w this is the controller's St = w L_f / (2 V_B).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ucat_console.backend.sim.params import FinGeometryConfig, FinHydroConfig
from ucat_console.backend.sim.plate import NP, plate_params
from ucat_console.robot.fins import N_FINS, fin_signs
from ucat_console.robot.motor import FinMotor

# hydro parameter vector layout
H_LF = 0
H_V_FLOOR = 1
H_TAU = 2
H_COS_A = 3
H_SIN_A = 4
H_ARM_R = 5
H_ARM_P = 6
H_ARM_Y = 7
H_PLATE = 8  # the plate's entries (``plate.P_*``) start here
H_MOTOR = H_PLATE + NP  # the drive's (``FinMotor.constants()``) from here
NPH = H_MOTOR + 8


def hydro_params(hydro: FinHydroConfig, geometry: FinGeometryConfig, motor: FinMotor = FinMotor()) -> np.ndarray:
    """The fins' parameter vector read by the compiled functions (layout ``H_*``): their
    hydrodynamics, where they sit, and their drives."""
    c = hydro.resolved()
    ph = np.zeros(NPH)
    ph[H_LF] = c.fin_length
    ph[H_V_FLOOR] = hydro.v_floor
    ph[H_TAU] = hydro.tau_rate
    a = math.radians(geometry.mounting_angle_deg)
    ph[H_COS_A] = math.cos(a)
    ph[H_SIN_A] = math.sin(a)
    ph[H_ARM_R] = geometry.arm_roll
    ph[H_ARM_P] = geometry.arm_pitch
    ph[H_ARM_Y] = geometry.arm_yaw
    ph[H_PLATE:H_MOTOR] = plate_params(c.rho, c.area, c.r_c, c.c_d, c.c_l, hydro.c_d0, hydro.lift_ratio,
                                       hydro.added_mass, hydro.strips, hydro.model == "still_water")
    ph[H_MOTOR:] = motor.constants()
    return ph


def fin_sign_table() -> np.ndarray:
    """(4, 3) array of (s_lat, s_long, s_y) per plant fin (see ``robot.fins.fin_signs``)."""
    return np.array([fin_signs(i) for i in range(N_FINS)], dtype=float)


@njit(cache=True)
def fin_strouhal(mean_abs_rate: float, surge_rel: float, ph: np.ndarray) -> float:
    """The fin's current Strouhal number from its mean |rate| and the relative surge speed."""
    return mean_abs_rate * ph[H_LF] / (2.0 * max(abs(surge_rel), ph[H_V_FLOOR]))


@njit(cache=True)
def add_fin_wrench(
    fx: float, fy: float, s_lat: float, s_long: float, s_y: float, ph: np.ndarray, tau: np.ndarray
) -> None:
    """tau (body X, Y, Z, K, M, N) += the wrench of a fin-frame force (f_x, f_y).

    Force (-f_x cos(alpha), s_y f_x sin(alpha), -f_y); roll s_lat arm_roll F_z; pitch
    -s_long arm_pitch F_z; yaw s_lat arm_yaw f_x (forward thrust on a starboard fin turns the
    nose to port).
    """
    fz = -fy
    tau[0] += -fx * ph[H_COS_A]
    tau[1] += s_y * fx * ph[H_SIN_A]
    tau[2] += fz
    tau[3] += s_lat * ph[H_ARM_R] * fz
    tau[4] += -s_long * ph[H_ARM_P] * fz
    tau[5] += s_lat * ph[H_ARM_Y] * fx


@njit(cache=True)
def fin_flow(nu_r: np.ndarray, s_lat: float, s_long: float, s_y: float, ph: np.ndarray) -> tuple[float, float]:
    """The water passing a fin's hinge (fin frame, m/s) when the hull moves at ``nu_r`` (u, v,
    w, p, q, r through the water, body frame): minus the hinge's velocity, the transpose of
    :func:`add_fin_wrench`'s map, so that ``f . v`` is the fin's power into the hull."""
    vx = (-ph[H_COS_A] * nu_r[0] + s_y * ph[H_SIN_A] * nu_r[1] + s_lat * ph[H_ARM_Y] * nu_r[5])
    vy = (-nu_r[2] - s_lat * ph[H_ARM_R] * nu_r[3] + s_long * ph[H_ARM_P] * nu_r[4])
    return -vx, -vy
