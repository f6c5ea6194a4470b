"""What a fin's executed cycle delivered, by the controller's fin model.

A cycle is the strokes of one plan as the fin executed them: the measured angle and the
time at each stroke's start and at the last stroke's end. Each executed stroke ``k`` moved
``d_k = a_{k+1} - a_k`` in ``T_k = t_{k+1} - t_k``, i.e. at the mean rate ``w_k = |d_k| / T_k``;
its mean force is the fin model's (control.md section 1, eqs 2-8) for that stroke from
``a_k``, and the cycle's mean force weighs the strokes by their durations (eq 14's W_k).

Comparing it with the force the fin was asked for says how well the planner and the
execution together deliver the allocation's request: the direction error (the angle
between the two forces) and the magnitude error (the difference of their sizes). The
model cannot see what the water does beyond it; the simulator's true force is the
benchmark's business (``bench tracking``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from ucat_console.control.params import MpcConfig

#: forces smaller than this (N) have no direction
MIN_FORCE = 1e-3


@dataclass(frozen=True)
class CycleForce:
    """An executed cycle against what was asked (forces in the fin model's frame, N)."""

    target: tuple[float, float]
    delivered: tuple[float, float]
    duration: float  # s, executed
    planned_duration: float  # s

    @property
    def direction_error(self) -> float:
        """Angle between the asked and the delivered force (rad, in [0, pi]); NaN when either
        is smaller than :data:`MIN_FORCE`."""
        return direction_error(self.target, self.delivered)

    @property
    def magnitude_error(self) -> float:
        """|delivered| - |asked| (N)."""
        return math.hypot(*self.delivered) - math.hypot(*self.target)


def direction_error(asked: tuple[float, float], delivered: tuple[float, float]) -> float:
    """The angle between two forces (rad, in [0, pi]); NaN when either is below MIN_FORCE."""
    na, nd = math.hypot(*asked), math.hypot(*delivered)
    if na < MIN_FORCE or nd < MIN_FORCE:
        return math.nan
    dot = (asked[0] * delivered[0] + asked[1] * delivered[1]) / (na * nd)
    return math.acos(max(-1.0, min(1.0, dot)))


def executed_force(angles: Sequence[float], times: Sequence[float], cfg: MpcConfig) -> tuple[float, float]:
    """Cycle-mean force (N, fin model frame) of the strokes between the measured ``angles``
    (rad) at ``times`` (s): one more of each than there are strokes. Zero when the cycle
    took no time."""
    if len(angles) != len(times) or len(angles) < 2:
        raise ValueError(f"angles, times: expected equal lengths >= 2, got {len(angles)} and {len(times)}")
    q = 0.5 * cfg.rho * cfg.fin_area * cfg.r_c ** 2
    fx = fy = total = 0.0
    for k in range(len(angles) - 1):
        d = angles[k + 1] - angles[k]
        span = times[k + 1] - times[k]
        if span <= 0.0:
            continue
        total += span
        w = abs(d) / span
        lift, drag = q * cfg.c_l * w * w, q * cfg.c_d * w * w
        half = 0.5 * d
        fxl = -lift * math.cos(half) - drag * math.sin(half)
        fyl = -lift * math.sin(half) - drag * math.cos(half)
        mid = angles[k] + half
        c, s = math.cos(mid), math.sin(mid)
        fx += span * (c * fxl - s * fyl)
        fy += span * (s * fxl + c * fyl)
    if total <= 0.0:
        return 0.0, 0.0
    return fx / total, fy / total


def planned_duration(u: Sequence[float]) -> float:
    """The duration of a plan ``u = [d_1, d_2, w_1, w_2]`` (s): sum of |d_k| / w_k."""
    half = len(u) // 2
    return sum(abs(u[k]) / u[half + k] for k in range(half) if u[half + k] > 0.0)
