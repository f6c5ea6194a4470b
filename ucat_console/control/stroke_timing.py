"""How long a stroke takes on the fin drive, and the force a fin can deliver at all.

A fin drive in profile-position mode (``robot.servo``) runs each stroke from rest to rest
on a trapezoidal velocity profile: it speeds up at the profile acceleration ``a``, cruises
at the profile velocity ``v`` (at most the drive's largest rate) and slows down at ``a``. A
stroke of ``|d|`` then lasts ``T = |d| / v + v / a`` when ``v^2 <= a |d|``, and at best
``2 sqrt(|d| / a)`` (a triangle) when it never reaches ``v``. Sending the planned mean rate
``w`` as the profile velocity makes every stroke slower than planned; :func:`profile_velocity`
gives the ``v`` whose stroke takes the planned ``|d| / w``:

    v = (a T - sqrt((a T)^2 - 4 a |d|)) / 2,     T = |d| / w,

possible when ``w <= sqrt(a |d|) / 2`` (:func:`mean_rate_limit`: the triangle's mean rate,
or the trapezoid's at the largest rate when that is lower). A plan asking for a faster
stroke gets the fastest the drive can make.

:func:`deliverable_force` is the largest cycle-mean force the controller's fin model gives
a fin whose strokes are timed so (the allocation's per-fin limit): a symmetric stroke pair
of ``d`` at mean rate ``w`` makes ``q sqrt(C_L^2 + C_D^2) w^2 cos(d / 2)``
(``q = rho A_f r_c^2 / 2``), the largest over ``d`` up to ``d_max`` and ``w`` up to both
``w_max`` and the drive's limit. Under this model the force does not depend on the speed
through the water.
"""

from __future__ import annotations

import math

from numba.extending import register_jitable

from ucat_console.control.params import MpcConfig


@register_jitable
def mean_rate_limit(stroke: float, acceleration: float, max_rate: float) -> float:
    """The fastest mean rate (rad/s) of a stroke of ``|stroke|`` rad from rest to rest."""
    d = abs(stroke)
    if d == 0.0:
        return 0.0
    peak = math.sqrt(acceleration * d)
    if peak <= max_rate:
        return 0.5 * peak
    return d / (d / max_rate + max_rate / acceleration)


def profile_velocity(stroke: float, mean_rate: float, acceleration: float, max_rate: float) -> float:
    """The profile velocity (rad/s) that makes a stroke of ``|stroke|`` rad take
    ``|stroke| / mean_rate`` (module docstring); the drive's fastest when it cannot."""
    d = abs(stroke)
    if d == 0.0 or mean_rate <= 0.0:
        return mean_rate
    if mean_rate >= mean_rate_limit(d, acceleration, max_rate):
        return min(max_rate, math.sqrt(acceleration * d))
    at = acceleration * d / mean_rate
    return 0.5 * (at - math.sqrt(max(0.0, at * at - 4.0 * acceleration * d)))


def deliverable_force(cfg: MpcConfig, acceleration: float, max_rate: float, steps: int = 240) -> float:
    """The largest cycle-mean force (N) of one fin by the fin model, its strokes at most
    ``cfg.d_max`` and timed by a drive of ``acceleration`` and ``max_rate`` (module docstring)."""
    q = 0.5 * cfg.rho * cfg.fin_area * cfg.r_c ** 2 * math.hypot(cfg.c_l, cfg.c_d)
    best = 0.0
    for k in range(1, steps + 1):
        d = cfg.d_max * k / steps
        w = min(cfg.w_max, mean_rate_limit(d, acceleration, max_rate))
        best = max(best, q * w * w * math.cos(0.5 * d))
    return best
