"""The fin as a foil in the flow the hull makes (wake option ``foil_inflow``).

What this option adds to the still-water fin (``fin_hydro.fin_force``, the soft fin's
quasi-steady force with its thrust gain) is what a blade-element model says the water
flowing past the hull changes. Nothing here reads a beat frequency, an amplitude or any
non-dimensional number of them: each strip sees its own relative flow, and thrust and
power follow from it. The values and their sources are in ``docs/foil-plant.md``.

Geometry. The fin is a flat plate hinged at the shaft. Its strips lie along the plate,
at radius r in [0, R] from the shaft, each of width ``span`` (along the shaft):

    R = sqrt(3) r_c,   span = A_f / R,

so that the plate's integral of r^2 dA is A_f r_c^2, the radius of gyration of the
quasi-steady model (a strip moving at r w has the model's speed r_c w on average). The
plate's line in the fin plane is at ``psi = theta + phi``, ``phi = atan2(C_D, C_L)`` (the
plant's still-water coefficients): a flapping plate in still water pushes along its mean
line, towards the shaft, and the quasi-steady model's cycle about a centre ``c`` pushes at
``c + atan2(-C_D, -C_L)``; so the plate's mean line lies opposite, at ``c + phi``. At the
centre where a cycle pushes the hull forward the plate trails straight back in the stream
(``psi = 0``, along the fin plane's rearward axis ``x_m``), as a cruising fin does.

Relative flow. The hull moves forward through the water at u (its surge relative to the
water); in the fin plane the water flows past at ``U = u cos(mounting angle)`` along
``+x_m`` (the component along the shaft runs along the strips' width and is left out).
A strip at radius r moves at ``r w`` normal to the plate, so the water passes it at

    V = U e_x - r w e_n,   e_p = (cos psi, sin psi),  e_n = (-sin psi, cos psi),
    V_p = U cos psi,       V_n = -U sin psi - r w             (plate frame)

at the angle of attack ``alpha = atan2(V_n, V_p)``. Lift (normal to V) and drag (along
V) of a flat plate at any angle of attack:

    C_L = C_Lmax sin(2 alpha),   C_D = C_D0 + C_D90 sin(alpha)^2,
    dF = rho |V|^2 dA / 2 (C_D V/|V| + C_L n(V)),   n(V) = V turned by +90 deg,

written without trigonometry as (sin alpha = V_n/|V|, cos alpha = V_p/|V|)

    dF_p = rho dA / 2 (C_D0 |V| V_p + (C_D90 - 2 C_Lmax) V_n^2 V_p / |V|)
    dF_n = rho dA / 2 (C_D0 |V| V_n + C_D90 V_n^3 / |V| + 2 C_Lmax V_p^2 V_n / |V|).

The still-water force of the blade element (``U = 0``: every strip at 90 degrees, a pure
normal drag ``(C_D0 + C_D90)``) is replaced by the fin's own still-water force, the
quasi-steady model identified on it, so the fin's force is

    F = F_still(theta, w, theta_start) + sum_strips [dF(U) - dF(U = 0)],

and the same for the hydrodynamic moment about the shaft, ``M = sum r dF_n``: at zero
speed the fin is exactly the still-water quasi-steady fin (its force, its thrust gain,
its drag power ``k_D |w|^3``); in a stream the blade element adds the plate's profile
drag, the lift its incidence makes and the load the stream puts on the shaft.

Added mass. A strip of the plate moving normal to itself carries the 2-D added mass of a
plate of width ``span``, ``rho pi span^2 / 4`` per metre of radius (Newman, Marine
Hydrodynamics, 1977, section 4.13), so the plate's added inertia about the shaft is

    I_a = rho pi span^2 R^3 / 12        (times ``foil_added_mass``).

The fluid momentum it stands for is periodic over a cycle, so its force on the hull
averages to zero and is left out; its moment, ``-I_a dw/dt``, loads the shaft.

Shaft power (the motors do not regenerate):

    P = max(0, (k_D w |w| - M_stream + (I + I_a) dw/dt) w),

``k_D |w|^3`` the still-water drag power, ``M_stream`` the moment the stream adds.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from ucat_console.backend.sim.fin_hydro import H_FOIL, H_GAIN, drag_torque_coefficient, quasi_steady_force

if TYPE_CHECKING:
    from ucat_console.backend.sim.params import FinHydroConfig

# foil entries of the hydro parameter vector (``fin_hydro.hydro_params`` fills them)
P_ON = 0  # 1.0: the foil option is on
P_CD0 = 1  # profile drag C_D0
P_CD90 = 2  # drag of the plate across the flow C_D90
P_CLMAX = 3  # largest lift C_Lmax
P_N = 4  # number of strips
P_RADIUS = 5  # R (m)
P_SPAN = 6  # width of the strips (m)
P_PHI = 7  # plate line - fin angle (rad)
P_ADDED_I = 8  # added inertia about the shaft (kg m2)
P_RHO = 9
NP = 10


def foil_params(hydro: FinHydroConfig) -> np.ndarray:
    """The foil entries of the hydro parameter vector (layout ``P_*``; zeros but ``P_ON`` = 0
    unless the wake option is ``foil_inflow``)."""
    pf = np.zeros(NP)
    c = hydro.resolved()
    radius, span = plate_geometry(c.r_c, c.area)
    pf[P_ON] = 1.0 if hydro.wake == "foil_inflow" else 0.0
    pf[P_CD0], pf[P_CD90], pf[P_CLMAX] = hydro.foil_cd0, hydro.foil_cd90, hydro.foil_cl_max
    pf[P_N] = hydro.foil_strips
    pf[P_RADIUS], pf[P_SPAN] = radius, span
    pf[P_PHI] = plate_angle(c.c_d, c.c_l)
    pf[P_ADDED_I] = added_inertia(c.rho, c.r_c, c.area, hydro.foil_added_mass)
    pf[P_RHO] = c.rho
    return pf


def plate_geometry(r_c: float, area: float) -> tuple[float, float]:
    """(R, span) of the plate whose r^2-moment of area is ``area r_c^2`` (module docstring)."""
    radius = math.sqrt(3.0) * r_c
    return radius, area / radius


def added_inertia(rho: float, r_c: float, area: float, factor: float) -> float:
    """The plate's added inertia about the shaft, ``factor rho pi span^2 R^3 / 12`` (kg m2)."""
    radius, span = plate_geometry(r_c, area)
    return factor * rho * math.pi * span * span * radius ** 3 / 12.0


def plate_angle(c_d: float, c_l: float) -> float:
    """``phi``: the plate's line minus the fin angle, ``atan2(C_D, C_L)`` (rad)."""
    return math.atan2(c_d, c_l)


@njit(cache=True)
def lift_drag(alpha: float, cd0: float, cd90: float, clmax: float) -> tuple[float, float]:
    """(C_L, C_D) of the plate at angle of attack ``alpha`` (rad)."""
    s = math.sin(alpha)
    return clmax * math.sin(2.0 * alpha), cd0 + cd90 * s * s


@njit(cache=True)
def strip_force(vp: float, vn: float, cd0: float, cd90: float, clmax: float) -> tuple[float, float]:
    """The plate-frame force of a strip in the relative flow (vp, vn), per rho dA / 2."""
    speed = math.sqrt(vp * vp + vn * vn)
    if speed == 0.0:
        return 0.0, 0.0
    inv = 1.0 / speed
    fp = cd0 * speed * vp + (cd90 - 2.0 * clmax) * vn * vn * vp * inv
    fn = cd0 * speed * vn + cd90 * vn * vn * vn * inv + 2.0 * clmax * vp * vp * vn * inv
    return fp, fn


@njit(cache=True)
def stream_force(theta: float, omega: float, flow: float, pf) -> tuple[float, float, float]:
    """What the stream ``flow`` (m/s along +x_m) adds to the fin's force and moment:
    (f_x, f_y) in the fin frame (N) and the moment about the shaft in the sense of
    positive ``omega`` (N m). Zero when ``flow`` is zero."""
    if flow == 0.0:
        return 0.0, 0.0, 0.0
    psi = theta + pf[P_PHI]
    cp = math.cos(psi)
    sp = math.sin(psi)
    cd0, cd90, clmax = pf[P_CD0], pf[P_CD90], pf[P_CLMAX]
    n = int(pf[P_N])
    dr = pf[P_RADIUS] / n
    vp = flow * cp
    un = -flow * sp
    sum_p = 0.0
    sum_n = 0.0
    moment = 0.0
    for k in range(n):
        r = (k + 0.5) * dr
        vn0 = -r * omega
        ap, an = strip_force(vp, un + vn0, cd0, cd90, clmax)
        bp, bn = strip_force(0.0, vn0, cd0, cd90, clmax)
        sum_p += ap - bp
        sum_n += an - bn
        moment += r * (an - bn)
    k_area = 0.5 * pf[P_RHO] * pf[P_SPAN] * dr
    return (k_area * (sum_p * cp - sum_n * sp), k_area * (sum_p * sp + sum_n * cp), k_area * moment)


@njit(cache=True)
def foil_fin(theta: float, omega: float, theta_start: float, alpha: float, flow: float, fin_inertia: float,
             ph: np.ndarray) -> tuple[float, float, float, float]:
    """(f_x, f_y, thrust gain, shaft power) of one fin of the foil plant: the still-water
    force with its thrust gain, what the stream ``flow`` adds, and the shaft power at the
    angular acceleration ``alpha`` (module docstring). ``ph``: the whole hydro vector."""
    fx, fy = quasi_steady_force(theta, omega, theta_start, ph)
    gain = ph[H_GAIN]
    if fx < 0.0:
        fx *= gain
    pf = ph[H_FOIL:]
    ax, ay, moment = stream_force(theta, omega, flow, pf)
    torque = drag_torque_coefficient(ph) * omega * abs(omega) - moment + (fin_inertia + pf[P_ADDED_I]) * alpha
    return fx + ax, fy + ay, gain, max(0.0, torque * omega)
