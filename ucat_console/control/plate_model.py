"""The simulated fin's plate model as the controller can know it: the thrust per coefficient.

The model the identification fits to a recording (``fit = "plate"``): the controller's copy
of the plant's physics (``backend/sim/plate.py``, docs/fin-plant.md), a flat plate hinged on
the shaft, ``R = sqrt(3) r_c`` long and ``A_f / R`` wide, its line at ``theta + phi``. The
water passes the hinge at ``(u_x, u_y)`` in the fin frame (``x_m`` rearwards in the fin
plane, ``y_m`` up): the hull's motion seen from the fin (:func:`hinge_flow`, the transpose
of the fin-to-body map, as the plant's ``fin_hydro.fin_flow``). In the plate's frame that is
``(U_p, U_n)``, and a strip at radius r meets the water at

    V_p = U_p,  V_n = U_n - r w,    C_L = C_Lmax sin 2a,  C_D = C_D0 + C_D90 sin^2 a,

and the rotational circulation ``Gamma_R = C_R R^2 w / 2`` pushes through the plate's centre.
The force is linear in (C_D0, C_D90, C_Lmax, C_R), so its forward thrust on the hull is

    T = C_D0 c_0 + C_D90 c_90 + C_Lmax c_L + C_R c_R

with regressors from the encoder's angle and rate and the measured flow alone
(:func:`plate_regressors`). (The plate's added mass pushes the hull back and forth over a
cycle and averages out: it is left out, as the plant leaves it out.) A test checks these
against the plant's own force to 1e-9.

The vertical flow matters. The four fins beat together, so each stroke heaves and pitches
the hull (0.05 m/s at the fins in the identification manoeuvre's fast steps), and about a
turned centre the hull climbs or dives. With the flow from the forward speed alone, the
plate at the plant's own coefficients falls 8-9 % short of the plant's thrust in the fast
steps about the centre and 15-24 % in the turned ones (rms 0.24 N over the 5 s windows, on
the paper's plate), and the fit comes out a quarter low; in the flow of the DVL's three
velocities (8 Hz, interpolated) and the IMU's rates the error is 0.05 N rms.

Measured (``identify --fit plate``, ``tests/backend/test_identification.py``): the
identification manoeuvre (``[loop.manoeuvre]`` defaults) recorded on plates calibrated to
(C_D, C_L) with profile drag C_D0, 95 % intervals, rms residual of the windows' surge balance;
the quasi-steady ``coefficients`` fit beside it:

    plate C_D / C_L / C_D0   C_D             C_L             C_D0            rms (N)   coefficients fit: C_D / C_L / rms
    0.7 / 0.25 / 0.05        0.726 +- 0.030  0.259 +- 0.014  0.083 +- 0.045  0.080     0.674 / 0.343 / 0.287
    0.7 / 0.25 / 0.1         0.727 +- 0.031  0.260 +- 0.015  0.139 +- 0.050  0.080     0.649 / 0.341 / 0.285
    0.7 / 0.25 / 0.3         0.732 +- 0.034  0.261 +- 0.017  0.365 +- 0.070  0.080     0.574 / 0.327 / 0.291
    2.1 / 0.75 / 0.3         2.064 +- 0.187  0.738 +- 0.073  0.242 +- 0.075  0.307     1.260 / 0.582 / 1.029

C_D and C_L come within 4 % and the truth lies inside their intervals; C_D0 is 0.03-0.07
high on the paper's plate and 0.06 low on the larger one, inside its interval, which is
wide: the manoeuvre tells a profile drag of 0.05 from 0.3, not from 0.1. The fit starts
from the configured model and finds the same from (3.0, 1.5) or (0.2, 0.05).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ucat_console.robot.fins import fin_signs


@dataclass(frozen=True)
class Plate:
    """The fin as a plate: density, area, radius of gyration, the line of its plate (``phi``,
    rad: ``atan2(C_D, C_L)`` of the still-water model it is calibrated to), strips."""

    rho: float
    area: float
    r_c: float
    phi: float
    strips: int = 8

    @property
    def radius(self) -> float:
        return math.sqrt(3.0) * self.r_c


@dataclass(frozen=True)
class FinMount:
    """Where the fins sit: the fin plane's angle from the body x axis (rad) and the arms of
    the fin-to-body map (m): a fin's vertical force about the roll and pitch axes, its
    force along x_m about the yaw axis (``FinGeometryConfig``)."""

    angle: float
    arm_roll: float
    arm_pitch: float
    arm_yaw: float


def hinge_flow(fin: int, mount: FinMount, u: ArrayLike, v: ArrayLike, w: ArrayLike, p: ArrayLike,
               q: ArrayLike, r: ArrayLike) -> tuple[NDArray, NDArray]:
    """(u_x, u_y): the water passing ``fin``'s hinge in the fin frame (m/s) when the hull moves
    at (u, v, w) (m/s) and turns at (p, q, r) (rad/s), body frame, in still water."""
    s_lat, s_long, s_y = fin_signs(fin)
    ux = (math.cos(mount.angle) * np.asarray(u, dtype=float) - s_y * math.sin(mount.angle) * np.asarray(v, dtype=float)
          - s_lat * mount.arm_yaw * np.asarray(r, dtype=float))
    uy = (np.asarray(w, dtype=float) + s_lat * mount.arm_roll * np.asarray(p, dtype=float)
          - s_long * mount.arm_pitch * np.asarray(q, dtype=float))
    return ux, uy


def plate_regressors(angle: ArrayLike, rate: ArrayLike, ux: ArrayLike, uy: ArrayLike, plate: Plate,
                     mounting_angle: float) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """(c_0, c_90, c_L, c_R) per sample: the forward thrust on the hull per unit of C_D0,
    C_D90, C_Lmax and C_R (N), at fin angle ``angle``, rate ``rate`` and the water passing
    the hinge at (``ux``, ``uy``) (fin frame, :func:`hinge_flow`)."""
    th = np.asarray(angle, dtype=float)
    w = np.asarray(rate, dtype=float)
    ux, uy = np.asarray(ux, dtype=float), np.asarray(uy, dtype=float)
    psi = th + plate.phi
    cp, sp = np.cos(psi), np.sin(psi)
    up, un = ux * cp + uy * sp, -ux * sp + uy * cp  # the water past the hinge, plate frame
    radius = plate.radius
    span = plate.area / radius
    dr = radius / plate.strips
    r = (np.arange(plate.strips) + 0.5)[None, :] * dr
    vp = np.broadcast_to(up[:, None], (up.size, plate.strips))
    vn = un[:, None] - r * w[:, None]
    v = np.hypot(vp, vn)
    inv = np.divide(1.0, v, out=np.zeros_like(v), where=v > 0.0)
    k = 0.5 * plate.rho * span * dr
    parts = [  # plate-frame (p, n) force per unit coefficient, summed over the strips
        (k * (v * vp).sum(axis=1), k * (v * vn).sum(axis=1)),  # C_D0
        (k * (vn * vn * vp * inv).sum(axis=1), k * (vn**3 * inv).sum(axis=1)),  # C_D90
        (k * (-2.0 * vn * vn * vp * inv).sum(axis=1), k * (2.0 * vp * vp * vn * inv).sum(axis=1)),  # C_Lmax
    ]
    # circulation rho span Gamma_R (z x V_c) through the centre, V_c = (-U_p, R w / 2 - U_n)
    g = plate.rho * span * radius * radius / 2.0 * w
    parts.append((-g * (0.5 * radius * w - un), -g * up))  # C_R
    cos_m = math.cos(mounting_angle)
    return tuple(-(fp * cp - fn * sp) * cos_m for fp, fn in parts)  # type: ignore[return-value]
