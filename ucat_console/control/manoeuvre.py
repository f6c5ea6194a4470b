"""The identification manoeuvre: fixed-frequency stroke pairs, step after step.

A step ``(offset, stroke, rate)`` of :class:`~ucat_console.control.params.ManoeuvreConfig`
beats a symmetric stroke pair of ``stroke`` rad at the mean rate ``rate`` (a fixed
frequency ``rate / (2 stroke)``) about the centre ``c + offset``, where ``c`` is the
centre at which the controller's model pushes straight forward (the baseline's centre for
a pure thrust demand). Plans are in the MPC's command format, so the same execution
module runs them; time is an argument (seconds since the manoeuvre began), as everywhere
in the core. After the last step the fin holds still.
"""

from __future__ import annotations

import math

from ucat_console.control.argcheck import finite
from ucat_console.control.baseline import BaselinePlanner, wrap_angle
from ucat_console.control.params import BaselineConfig, ManoeuvreConfig, MpcConfig

Vec4 = tuple[float, float, float, float]


class ManoeuvrePlanner:
    """Cycles of the identification manoeuvre for one fin (stateless)."""

    def __init__(self, cfg: ManoeuvreConfig, mpc: MpcConfig) -> None:
        self.cfg = cfg
        self.centre = BaselinePlanner(mpc, BaselineConfig()).centre(-1.0, 0.0, 0.0)
        self._w_hold = mpc.w_min  # a held fin's zero strokes still get an admissible rate

    def step_at(self, t: float) -> tuple[float, float, float] | None:
        """The step in force ``t`` s after the start (None before it and after the last)."""
        t = finite("t", t)
        if t < 0.0 or t >= self.cfg.duration:
            return None
        return self.cfg.steps[min(int(t // self.cfg.step_s), len(self.cfg.steps) - 1)]

    def plan(self, t: float, theta_now: float) -> tuple[Vec4, Vec4]:
        """``(u, commands)`` of the cycle starting at ``t`` from the fin angle ``theta_now``:
        the first stroke to the extreme of the pair farther from the fin, the second to
        the other (as the baseline joins its cycles); a zero cycle after the last step."""
        theta_now = finite("theta_now", theta_now)
        step = self.step_at(t)
        if step is None:
            w = self._w_hold
            return (0.0, 0.0, w, w), (theta_now, w, theta_now, w)
        offset, stroke, rate = step
        c = wrap_angle(self.centre + offset)
        # the centre nearest the fin (whole turns) so that the first stroke is short
        c += 2.0 * math.pi * round((theta_now - c) / (2.0 * math.pi))
        upper, lower = c + 0.5 * stroke, c - 0.5 * stroke
        first, second = (lower, upper) if abs(lower - theta_now) > abs(upper - theta_now) else (upper, lower)
        return (first - theta_now, second - first, rate, rate), (first, rate, second, rate)
