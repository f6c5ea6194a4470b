"""The fin in the water: a plate hinged at its leading edge, with forces that conserve energy.

Model (docs/fin-plant.md has the sources and every value). The fin is a flat plate hinged
on its shaft: it reaches ``R`` from the shaft (its chord in the fin plane) and is ``span``
wide along the shaft. Its forces are those of the quasi-steady plate of Andersen,
Pesavento and Wang (J. Fluid Mech. 541:65, 2005), the model Berman and Wang (J. Fluid
Mech. 582:153, 2007) used for flapping wings, made for a plate that turns about its edge:

* **Translation** (lift and drag at any angle of attack): blade-element strips along the
  plate, each in its own relative flow, with the flat plate's coefficients of Wang, Birch
  and Dickinson (J. Exp. Biol. 207:449, 2004)

      C_L = C_Lmax sin(2 a),   C_D = C_D0 + C_D90 sin^2(a),

  drag along the relative flow, lift across it. At zero flow past the hull every strip
  meets the water at 90 degrees: the plate's normal force ``C_N = C_D0 + C_D90``.
* **Rotational circulation** (Andersen et al.'s ``Gamma_R = C_R c^2 Omega / 2``): a
  circulation proportional to the plate's rate of turn, acting through the plate's centre
  with the Kutta-Joukowski force ``rho Gamma_R z x V_c`` (``V_c`` the centre's velocity
  through the water). In still water it pushes along the plate towards the shaft, whichever
  way the plate turns: a beating fin's thrust along its mean line.
* **Added mass**: strips across the plate carry the 2-D added mass of a plate of width
  ``span`` (Newman, *Marine Hydrodynamics*, 1977, section 4.13): added inertia
  ``I_a = rho pi span^2 R^3 / 12`` about the shaft (``robot.fin_plate``, the plate's size
  and this inertia's one definition); its force on the hull is periodic and left out.

Why it conserves energy. Work the water does on the plate: the strips' drag opposes their
motion through the water (``dF . V <= 0``), their lift is across it (no work), the
circulatory force is across the centre's velocity (no work), and the added mass stores
kinetic energy and gives it back over a cycle. So the shaft's power ``P = tau w`` equals
the power the fin delivers to the hull plus what it leaves in the water plus the change of
stored energy: over a cycle the useful power never exceeds the shaft's. The motors do not
regenerate: the shaft power reported is ``max(0, tau w)``.

The flow past the fin. The fin's hinge moves with the hull; in the fin plane (``x_m``
rearwards, ``y_m`` up) its velocity through the water is the transpose of the map from the
fin's force to the body wrench (``fin_hydro.add_fin_wrench``), so the power the fin
delivers to the hull is exactly ``f . v``. The water passes the fin at ``(u_x, u_y) = -v``.

Calibration (the U-CAT's still-water thrust). A plant is calibrated to a still-water model
``(C_D, C_L)`` of the controller's form: the normal force equals its drag (``C_N = C_D``,
so ``C_D90 = C_D - C_D0``), the plate's lift keeps Wang et al.'s ratio to its normal force
(``C_Lmax = lift_ratio C_N``), and the rotational circulation makes the model's mean force
of a symmetric stroke pair, ``q w^2 sqrt(C_L^2 + C_D^2)``. Nothing in this module reads a
Strouhal number, a beat frequency or an amplitude.

The null plant (``still_water``): the same plate in still water whatever the hull does
(its forces from its own motion alone), with the work its force does on the hull paid
through the shaft (``P = max(0, tau w + f . v)``), so that it too conserves energy; at a
given force and hull speed it costs the same whatever the stroke's frequency.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ucat_console.robot.fin_plate import added_inertia, plate_geometry
from ucat_console.robot.layout import Layout

#: the plate's entries of the hydro parameter vector (``fin_hydro.HYDRO``'s ``plate`` field
#: holds them), and their columns as constants
PLATE = Layout("the plate's parameters", [
    ("null", 1, "1.0: the still-water null plant"),
    ("c_d0", 1, "profile drag C_D0"),
    ("c_d90", 1, "C_D90: the normal force at 90 degrees is C_D0 + C_D90"),
    ("c_lmax", 1, "largest lift C_Lmax"),
    ("rot", 1, "rho span C_R R^2 / 2: the circulation term's rho span Gamma_R per unit rate (kg/m)"),
    ("strips", 1, "number of strips"),
    ("radius", 1, "R (m)"),
    ("span", 1, "span along the shaft (m)"),
    ("phi", 1, "plate line - fin angle (rad)"),
    ("added_inertia", 1, "added inertia about the shaft (kg m2)"),
    ("rho", 1, "water density (kg/m3)"),
])
P_NULL, P_CD0, P_CD90, P_CLMAX, P_ROT, P_N, P_RADIUS, P_SPAN, P_PHI, P_ADDED_I, P_RHO = (
    PLATE.at(f) for f in PLATE.fields)
NP = PLATE.size


def plate_angle(c_d: float, c_l: float) -> float:
    """``phi``: the plate's line minus the fin angle, ``atan2(C_D, C_L)`` of the still-water
    model the plant is calibrated to (rad): the model's mean force of a cycle about a centre
    ``c`` points along ``c + atan2(-C_D, -C_L)``, opposite the plate's mean line ``c + phi``."""
    return math.atan2(c_d, c_l)


def rotational_coefficient(c_d: float, c_l: float) -> float:
    """``C_R`` for which the plate's still-water force along its line, ``rho span C_R R^3 w^2
    / 4``, is the model's mean force of a symmetric stroke pair at a steady rate, ``q w^2
    sqrt(C_L^2 + C_D^2)`` with ``q = rho A_f r_c^2 / 2``, ``A_f = span R``, ``r_c^2 = R^2 / 3``:
    ``C_R = 2 sqrt(C_L^2 + C_D^2) / 3``."""
    return 2.0 * math.hypot(c_l, c_d) / 3.0


def plate_params(rho: float, area: float, r_c: float, c_d: float, c_l: float, c_d0: float, lift_ratio: float,
                 added_mass: float, strips: int, null: bool) -> np.ndarray:
    """The plate entries of the hydro parameter vector (:data:`PLATE`), calibrated to the
    still-water model ``(C_D, C_L)`` (module docstring)."""
    if c_d0 > c_d:
        raise ValueError(f"c_d0: the profile drag {c_d0} exceeds the normal force {c_d} it is part of")
    radius, span = plate_geometry(r_c, area)
    pf = np.zeros(NP)
    pf[P_NULL] = 1.0 if null else 0.0
    pf[P_CD0] = c_d0
    pf[P_CD90] = c_d - c_d0
    pf[P_CLMAX] = lift_ratio * c_d
    pf[P_ROT] = rho * span * rotational_coefficient(c_d, c_l) * radius * radius / 2.0
    pf[P_N] = strips
    pf[P_RADIUS], pf[P_SPAN] = radius, span
    pf[P_PHI] = plate_angle(c_d, c_l)
    pf[P_ADDED_I] = added_inertia(rho, r_c, area, added_mass)
    pf[P_RHO] = rho
    return pf


@njit(cache=True)
def strip_force(vp: float, vn: float, cd0: float, cd90: float, clmax: float) -> tuple[float, float]:
    """The plate-frame force of a strip in the relative flow (vp, vn) of the water past it,
    per rho dA / 2: drag ``C_D |V| V``, lift ``C_L |V|`` across V, with
    ``sin a = vn/|V|, cos a = vp/|V|``."""
    speed = math.sqrt(vp * vp + vn * vn)
    if speed == 0.0:
        return 0.0, 0.0
    inv = 1.0 / speed
    fp = cd0 * speed * vp + (cd90 - 2.0 * clmax) * vn * vn * vp * inv
    fn = cd0 * speed * vn + cd90 * vn * vn * vn * inv + 2.0 * clmax * vp * vp * vn * inv
    return fp, fn


@njit(cache=True)
def plate_force(theta: float, omega: float, ux: float, uy: float, pf: np.ndarray) -> tuple[float, float, float]:
    """The water's force on the plate, fin frame (N), and its moment about the shaft in the
    sense of positive ``omega`` (N m), at fin angle ``theta`` and rate ``omega`` with the
    water passing the hinge at ``(ux, uy)`` (m/s, fin frame)."""
    psi = theta + pf[P_PHI]
    cp = math.cos(psi)
    sp = math.sin(psi)
    cd0, cd90, clmax = pf[P_CD0], pf[P_CD90], pf[P_CLMAX]
    n = int(pf[P_N])
    radius = pf[P_RADIUS]
    dr = radius / n
    up = ux * cp + uy * sp  # the water past the hinge, plate frame
    un = -ux * sp + uy * cp
    sum_p = 0.0
    sum_n = 0.0
    moment = 0.0
    for k in range(n):
        r = (k + 0.5) * dr
        fp, fn = strip_force(up, un - r * omega, cd0, cd90, clmax)
        sum_p += fp
        sum_n += fn
        moment += r * fn
    k_area = 0.5 * pf[P_RHO] * pf[P_SPAN] * dr
    fp = k_area * sum_p
    fn = k_area * sum_n
    moment *= k_area
    # rotational circulation through the centre: rho span Gamma_R (z x V_c), V_c the centre's
    # velocity through the water, plate frame (-up, R w / 2 - un); z x (a e_p + b e_n) = a e_n - b e_p
    g = pf[P_ROT] * omega
    vcp = -up
    vcn = 0.5 * radius * omega - un
    fp -= g * vcn
    fn += g * vcp
    moment += 0.5 * radius * g * vcp
    return fp * cp - fn * sp, fp * sp + fn * cp, moment


@njit(cache=True)
def fin_load(theta: float, omega: float, alpha: float, ux: float, uy: float, fin_inertia: float, dt: float,
             pf: np.ndarray) -> tuple[float, float, float, float, float]:
    """One fin's (f_x, f_y) on the hull (fin frame, N), the torque its shaft gives (N m), its
    shaft power (W, no regeneration) and the power it delivers to the hull (W), at the end of
    a step of ``dt`` in which the fin
    reached angle ``theta`` and rate ``omega`` at the constant angular acceleration ``alpha``,
    with the water passing the hinge at ``(ux, uy)`` (module docstring; ``pf`` the plate
    entries). The inertia's power is taken at the step's mean rate, so that over the step it
    is exactly the change of the fin's kinetic energy (the servo moves the angle by the mean
    rate, trapezoidal rule)."""
    null = pf[P_NULL] > 0.5
    if null:
        fx, fy, moment = plate_force(theta, omega, 0.0, 0.0, pf)
    else:
        fx, fy, moment = plate_force(theta, omega, ux, uy, pf)
    useful = -(fx * ux + fy * uy)  # f . v, v = -(ux, uy) the hinge's velocity through the water
    inertia = fin_inertia + pf[P_ADDED_I]
    torque = inertia * alpha - moment
    power = inertia * alpha * (omega - 0.5 * alpha * dt) - moment * omega
    if null:
        power += useful
        if omega != 0.0:  # the null plant's thrust work reaches the shaft as a torque
            torque += useful / omega
    return fx, fy, torque, max(0.0, power), useful
