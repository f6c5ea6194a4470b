"""The simulated fin's plate model as the controller can know it: the thrust per coefficient.

The model the identification fits to a recording (``fit = "plate"``): the controller's copy
of the plant's physics (``backend/sim/plate.py``, docs/fin-plant.md), a flat plate hinged on
the shaft, ``R = sqrt(3) r_c`` long and ``A_f / R`` wide, its line at ``theta + phi``. The
hull's forward speed u makes a stream ``U = u cos(mounting angle)`` along the fin plane's
rearward axis; a strip at radius r meets the water at

    V_p = U cos psi,  V_n = -U sin psi - r w,    C_L = C_Lmax sin 2a,  C_D = C_D0 + C_D90 sin^2 a,

and the rotational circulation ``Gamma_R = C_R R^2 w / 2`` pushes through the plate's centre.
The force is linear in (C_D0, C_D90, C_Lmax, C_R), so its forward thrust on the hull is

    T = C_D0 c_0 + C_D90 c_90 + C_Lmax c_L + C_R c_R

with regressors from the encoder's angle and rate and the measured speed alone
(:func:`plate_regressors`). (The plate's added mass pushes the hull back and forth over a
cycle and averages out: it is left out, as the plant leaves it out.) A test checks these
against the plant's own force to 1e-9.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray


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


def plate_regressors(angle: ArrayLike, rate: ArrayLike, speed: ArrayLike, plate: Plate,
                     mounting_angle: float) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """(c_0, c_90, c_L, c_R) per sample: the forward thrust on the hull per unit of C_D0,
    C_D90, C_Lmax and C_R (N), at fin angle ``angle``, rate ``rate`` and hull speed ``speed``."""
    th = np.asarray(angle, dtype=float)[:, None]
    w = np.asarray(rate, dtype=float)[:, None]
    flow = np.asarray(speed, dtype=float)[:, None] * math.cos(mounting_angle)
    psi = th + plate.phi
    cp, sp = np.cos(psi), np.sin(psi)
    radius = plate.radius
    span = plate.area / radius
    dr = radius / plate.strips
    r = (np.arange(plate.strips) + 0.5)[None, :] * dr
    vp = flow * cp
    vn = -flow * sp - r * w
    v = np.hypot(vp, vn)
    inv = np.divide(1.0, v, out=np.zeros_like(v), where=v > 0.0)
    k = 0.5 * plate.rho * span * dr
    parts = [  # plate-frame (p, n) force per unit coefficient, summed over the strips
        (k * (v * vp).sum(axis=1), k * (v * vn).sum(axis=1)),  # C_D0
        (k * (vn * vn * vp * inv).sum(axis=1), k * (vn**3 * inv).sum(axis=1)),  # C_D90
        (k * (-2.0 * vn * vn * vp * inv).sum(axis=1), k * (2.0 * vp * vp * vn * inv).sum(axis=1)),  # C_Lmax
    ]
    # circulation rho span Gamma_R (z x V_c) through the centre, V_c = (-U cos psi, R w/2 + U sin psi)
    g = plate.rho * span * radius * radius / 2.0 * w[:, 0]
    up, un = flow[:, 0] * cp[:, 0], -flow[:, 0] * sp[:, 0]
    parts.append((-g * (0.5 * radius * w[:, 0] - un), g * (-up)))  # C_R
    c, s = cp[:, 0], sp[:, 0]
    cos_m = math.cos(mounting_angle)
    return tuple(-(fp * c - fn * s) * cos_m for fp, fn in parts)  # type: ignore[return-value]
