"""What the flow past the hull adds to a fin's thrust: the controller's blade-element model.

The model the identification fits to a recording (``fit = "inflow"``), the controller's own
copy of the foil plant's physics (docs/foil-plant.md): the fin is a flat plate of ``strips``
blade elements along ``R = sqrt(3) r_c`` (strip width ``A_f / R``), its line at
``theta + atan2(C_D, C_L)``; the hull's forward speed u gives a stream ``U = u cos(mounting
angle)`` along the fin plane's rearward axis; a strip at radius r moving at ``r w`` sees

    V_p = U cos psi,  V_n = -U sin psi - r w,    C_L = C_Lmax sin 2 alpha,  C_D = C_D0 + C_D90 sin^2 alpha,

and what the stream adds is the strip force at U minus that at U = 0. The added force is
linear in (C_D0, C_D90, C_Lmax), so its forward thrust is

    T_stream = C_D0 c_0 + C_D90 c_90 + C_Lmax c_L

with regressors from the encoder's angle and rate and the measured speed alone
(:func:`stream_regressors`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray


@dataclass(frozen=True)
class Plate:
    """The fin as a plate: density, area, radius of gyration, still-water C_D and C_L (its
    line), number of strips."""

    rho: float
    area: float
    r_c: float
    c_d: float
    c_l: float
    strips: int = 8

    @property
    def radius(self) -> float:
        return math.sqrt(3.0) * self.r_c

    @property
    def phi(self) -> float:
        return math.atan2(self.c_d, self.c_l)


def stream_regressors(angle: ArrayLike, rate: ArrayLike, speed: ArrayLike, plate: Plate,
                      mounting_angle: float) -> tuple[NDArray, NDArray, NDArray]:
    """(c_0, c_90, c_L) per sample: the forward thrust the stream adds per unit of C_D0,
    C_D90 and C_Lmax (N), at fin angle ``angle``, rate ``rate`` and hull speed ``speed``."""
    th = np.asarray(angle, dtype=float)[:, None]
    w = np.asarray(rate, dtype=float)[:, None]
    flow = np.asarray(speed, dtype=float)[:, None] * math.cos(mounting_angle)
    psi = th + plate.phi
    cp, sp = np.cos(psi), np.sin(psi)
    dr = plate.radius / plate.strips
    r = (np.arange(plate.strips) + 0.5)[None, :] * dr
    vp = flow * cp
    vn0 = -r * w
    vn = -flow * sp + vn0
    v = np.hypot(vp, vn)
    inv = np.divide(1.0, v, out=np.zeros_like(v), where=v > 0.0)
    a0 = np.abs(vn0)
    # plate-frame (p, n) force per unit coefficient, at U minus at U = 0
    parts = (
        (v * vp, v * vn - a0 * vn0),  # C_D0
        (vn * vn * vp * inv, vn**3 * inv - a0 * vn0),  # C_D90 (at U = 0: |vn0| vn0)
        (-2.0 * vn * vn * vp * inv, 2.0 * vp * vp * vn * inv),  # C_Lmax (no lift at U = 0)
    )
    k = 0.5 * plate.rho * (plate.area / plate.radius) * dr * math.cos(mounting_angle)
    out = []
    for fp, fn in parts:
        p, n = fp.sum(axis=1, keepdims=True), fn.sum(axis=1, keepdims=True)
        fx = p * cp - n * sp
        out.append(-k * fx[:, 0])
    return out[0], out[1], out[2]
