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
from ucat_console.robot.layout import Layout
from ucat_console.robot.motor import FinMotor

#: the fins' parameter vector (``ph``): where the fins sit, their flow and Strouhal filter,
#: the plate's entries (``plate.PLATE``) and their drives' (``FinMotor.constants()``, in its order)
HYDRO = Layout("the fins' parameter vector", [
    ("fin_length", 1, "L_f (m), of the recorded Strouhal number"),
    ("v_floor", 1, "speed floor of the recorded Strouhal number (m/s)"),
    ("tau_rate", 1, "time constant of the mean |rate| (s)"),
    ("cos_mount", 1, "cos of the mounting angle"),
    ("sin_mount", 1, "sin of the mounting angle"),
    ("arm_roll", 1, "roll moment arm (m)"),
    ("arm_pitch", 1, "pitch moment arm (m)"),
    ("arm_yaw", 1, "yaw moment arm (m)"),
    ("plate", NP, "the plate (plate.PLATE)"),
    ("torque_constant", 1, "the drive: motor torque constant (N m/A)"),
    ("resistance", 1, "winding resistance (ohm)"),
    ("no_load_current", 1, "no-load current (A)"),
    ("rotor_inertia", 1, "rotor inertia (kg m2)"),
    ("gear_ratio", 1, "gear ratio"),
    ("gear_efficiency", 1, "gearhead efficiency"),
    ("bridge_efficiency", 1, "bridge efficiency"),
    ("quiescent_power", 1, "quiescent power (W)"),
])
H_LF, H_V_FLOOR, H_TAU, H_COS_A, H_SIN_A, H_ARM_R, H_ARM_P, H_ARM_Y, H_PLATE = (
    HYDRO.at(f) for f in HYDRO.fields[:9])
H_K_T, H_R_M, H_I_0, H_J_R, H_N_G, H_ETA_G, H_ETA_B, H_P_Q = (HYDRO.at(f) for f in HYDRO.fields[9:])
H_MOTOR = H_K_T  # the drive's entries from here (``FinMotor.constants()``)
NPH = HYDRO.size


def hydro_params(hydro: FinHydroConfig, geometry: FinGeometryConfig, motor: FinMotor = FinMotor()) -> np.ndarray:
    """The fins' parameter vector read by the compiled functions (:data:`HYDRO`): their
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
    ph[HYDRO.span("plate")] = plate_params(c.rho, c.area, c.r_c, c.c_d, c.c_l, hydro.c_d0, hydro.lift_ratio,
                                       hydro.added_mass, hydro.strips, hydro.model == "still_water")
    ph[H_MOTOR:NPH] = motor.constants()
    return ph


#: a fin's row of the sign table (``robot.fins.fin_signs``)
SIGNS = Layout("a fin's signs row", [
    ("s_lat", 1, "+1 starboard, -1 port"), ("s_long", 1, "+1 front, -1 rear"),
    ("s_y", 1, "lateral sign of the fin plane's x_m axis"),
])
SG_LAT, SG_LONG, SG_Y = (SIGNS.at(f) for f in SIGNS.fields)


def fin_sign_table() -> np.ndarray:
    """(4, 3) array of a :data:`SIGNS` row per plant fin (see ``robot.fins.fin_signs``)."""
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
