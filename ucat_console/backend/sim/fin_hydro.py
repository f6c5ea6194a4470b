"""Fin hydrodynamics of the plant: instantaneous quasi-steady force, wake factor, body wrench.

Quasi-steady force (same form as the controller's fin model, control.md section 1, made
instantaneous, with the plant's own coefficients). At fin angle theta and rate w:

    v = r_c |w| ;  D = rho C_D A_f v^2 / 2 ;  L = rho C_L A_f v^2 / 2
    thr = theta - theta_s          (opening of the stroke so far; theta_s: where it began)
    fxl = -L cos(thr) - D sin(thr) ;  fyl = -L sin(thr) - D cos(thr)
    (f_x, f_y) = R(theta) (fxl, fyl)

A stroke begins where the fin's rate changes sign or the fin is at rest. Over a stroke at a
steady rate the running opening averages to d/2 and the rotation to the mid-stroke angle, so
the stroke mean reproduces the controller's (d, w) model (to within the servo's
acceleration phases). Zero rate gives zero force. The force is in the fin's 2-D frame
(``x_m`` rearwards, ``y_m`` up; forward propulsion is f_x < 0; see ``params``).

Thrust gain and wake. The propulsive part of the force, its forward component (f_x < 0),
is multiplied by the coefficient set's thrust gain G and, with ``wake = "strouhal_wake"``,
by the wake factor W(St) of the fin's current Strouhal number (:func:`wake_factor`);
backward and vertical components are left quasi-steady. The fin's current Strouhal number
is St = w_bar L_f / (2 max(|u_r|, v_floor)), w_bar the fin's mean |rate| (first-order filter,
time constant ``tau_rate``) and u_r the hull's surge speed through the water; for H = 2
strokes of equal size at mean rate w this is the controller's St = w L_f / (2 V_B).

Wake factor (the plant's own; not the controller's eta_hat): a split Gaussian with a floor,

    W(St) = floor + (1 - floor) exp(-(St - St_peak)^2 / (2 sigma^2)),
    sigma = sigma_low below St_peak, sigma_high above,

defaults St_peak 0.30, sigma_low 0.08, sigma_high 0.20, floor 0.25: W(0.15) = 0.38,
W(0.25) = 0.87, W(0.30) = 1, W(0.35) = 0.98, W(0.50) = 0.71. The shape follows the
efficiency curves of flapping foils (Triantafyllou et al. 1993, peak at St 0.25-0.35;
Floryan et al., PNAS 2018, steep rise below the peak, slow decline above). The floor keeps
thrust far from the optimal wake (a fin beating at standstill has a very high St): with
the soft-fin gain, G x floor = 1.15, i.e. far from the optimal wake the soft fin makes about
what the steady-flow coefficients predict.

Soft-fin thrust gain G = 4.6, fixed before any run (plant.md "What the numbers imply").
Check: with the paper's coefficients and H = 2 a fin at St 0.3 beats at w = 6 V
(L_f = 0.10 m). Its largest mean force (full stroke d = 1.2 rad, force turned forward) is
cos(0.6) rho A_f r_c^2 sqrt(C_L^2 + C_D^2) w^2 / 2 = 0.0613 w^2 = 2.21 V^2 N; four fins at
the 30 deg mounting give 4 cos(30 deg) 2.21 V^2 = 7.65 V^2 N forward, while the hull needs
6.542 V + 2.98 V^2 N. The gain needed to cruise at St 0.3 is therefore 8.94 at 0.1 m/s,
4.67 at 0.2, 3.24 at 0.3 and 2.53 at 0.4 m/s; no constant gain holds St 0.3 at every
speed (at a fixed gain the cruise St grows like sqrt(drag / V^2) towards low speed).
Literature: the authors' own simulator (eeUVsim) gives these fins C_D 3.2 and C_L 1.65,
4.6 and 6.6 times the paper's identified values; flexible flapping foils make more thrust
than rigid ones of the same kinematics (e.g. Heathcote and Gursul, AIAA J. 2007; Quinn,
Lauder and Smits, J. Fluid Mech. 2014); and the quasi-steady form leaves out the
added-mass and wake-vortex forces that carry the thrust near St 0.3. G = 4.6 is the smaller
eeUVsim ratio and, within 2 %, the gain at which four fins at St 0.3 and full stroke hold
0.2 m/s, the geometric middle of the paper's 0.1-0.4 m/s. Stated before any run (with the
wake factor above, full stroke): steady cruise needs St about 0.30 at 0.2 m/s, 0.26 at
0.3 m/s and 0.24 at 0.4 m/s (just below the corridor; the steep low side of W holds St up
at speed), but about 0.49 at 0.1 m/s, well above it: there the hull's linear damping
dominates.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ucat_console.backend.sim.params import FinGeometryConfig, FinHydroConfig
from ucat_console.robot.fins import N_FINS, fin_signs

# hydro parameter vector layout
H_RHO = 0
H_CD = 1
H_CL = 2
H_AREA = 3
H_RC = 4
H_LF = 5
H_GAIN = 6
H_WAKE_ON = 7
H_ST_PEAK = 8
H_SIG_LO = 9
H_SIG_HI = 10
H_FLOOR = 11
H_V_FLOOR = 12
H_TAU = 13
H_COS_A = 14
H_SIN_A = 15
H_ARM_R = 16
H_ARM_P = 17
H_ARM_Y = 18
H_FOIL = 19  # the foil option's entries (``foil.P_*``) start here
NPH = H_FOIL + 10


def hydro_params(hydro: FinHydroConfig, geometry: FinGeometryConfig) -> np.ndarray:
    """The hydro parameter vector read by the compiled functions (layout ``H_*``)."""
    c = hydro.resolved()
    ph = np.zeros(NPH)
    ph[H_RHO] = c.rho
    ph[H_CD] = c.c_d
    ph[H_CL] = c.c_l
    ph[H_AREA] = c.area
    ph[H_RC] = c.r_c
    ph[H_LF] = c.fin_length
    ph[H_GAIN] = c.thrust_gain
    ph[H_WAKE_ON] = 1.0 if hydro.wake == "strouhal_wake" else 0.0
    ph[H_ST_PEAK] = hydro.st_peak
    ph[H_SIG_LO] = hydro.sigma_low
    ph[H_SIG_HI] = hydro.sigma_high
    ph[H_FLOOR] = hydro.floor
    ph[H_V_FLOOR] = hydro.v_floor
    ph[H_TAU] = hydro.tau_rate
    a = math.radians(geometry.mounting_angle_deg)
    ph[H_COS_A] = math.cos(a)
    ph[H_SIN_A] = math.sin(a)
    ph[H_ARM_R] = geometry.arm_roll
    ph[H_ARM_P] = geometry.arm_pitch
    ph[H_ARM_Y] = geometry.arm_yaw
    from ucat_console.backend.sim import foil  # foil imports this module

    ph[H_FOIL:] = foil.foil_params(hydro)
    return ph


def fin_sign_table() -> np.ndarray:
    """(4, 3) array of (s_lat, s_long, s_y) per plant fin (see ``robot.fins.fin_signs``)."""
    return np.array([fin_signs(i) for i in range(N_FINS)], dtype=float)


@njit(cache=True)
def wake_factor(st: float, st_peak: float, sigma_low: float, sigma_high: float, floor: float) -> float:
    """Thrust factor of the fin's wake at Strouhal number ``st`` (module docstring)."""
    sigma = sigma_low if st < st_peak else sigma_high
    z = (st - st_peak) / sigma
    return floor + (1.0 - floor) * math.exp(-0.5 * z * z)


@njit(cache=True)
def fin_strouhal(mean_abs_rate: float, surge_rel: float, ph: np.ndarray) -> float:
    """The fin's current Strouhal number from its mean |rate| and the relative surge speed."""
    return mean_abs_rate * ph[H_LF] / (2.0 * max(abs(surge_rel), ph[H_V_FLOOR]))


@njit(cache=True)
def quasi_steady_force(theta: float, omega: float, theta_start: float, ph: np.ndarray) -> tuple[float, float]:
    """(f_x, f_y) of one fin in its 2-D frame by the quasi-steady model alone (module
    docstring), before the thrust gain."""
    v = ph[H_RC] * omega
    q = 0.5 * ph[H_RHO] * ph[H_AREA] * v * v
    lift = ph[H_CL] * q
    drag = ph[H_CD] * q
    thr = theta - theta_start
    ct, s_thr = math.cos(thr), math.sin(thr)
    fxl = -lift * ct - drag * s_thr
    fyl = -lift * s_thr - drag * ct
    c, s = math.cos(theta), math.sin(theta)
    return c * fxl - s * fyl, s * fxl + c * fyl


@njit(cache=True)
def drag_torque_coefficient(ph: np.ndarray) -> float:
    """k_D = rho C_D A_f r_c^3 / 2: the still-water drag power is k_D |w|^3."""
    return 0.5 * ph[H_RHO] * ph[H_CD] * ph[H_AREA] * ph[H_RC] ** 3


@njit(cache=True)
def fin_force(
    theta: float, omega: float, theta_start: float, st: float, ph: np.ndarray
) -> tuple[float, float, float]:
    """(f_x, f_y, thrust factor) of one fin in its 2-D frame (module docstring)."""
    fx, fy = quasi_steady_force(theta, omega, theta_start, ph)
    scale = ph[H_GAIN]
    if ph[H_WAKE_ON] > 0.5:
        scale *= wake_factor(st, ph[H_ST_PEAK], ph[H_SIG_LO], ph[H_SIG_HI], ph[H_FLOOR])
    if fx < 0.0:
        fx *= scale
    return fx, fy, scale


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
