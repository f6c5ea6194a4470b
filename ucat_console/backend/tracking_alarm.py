"""What the robot is expected to do, for the ``tracking`` failsafe: an envelope per axis.

The body layer's references (``body/tracking``) close on the setpoints at limited rates,
and the designed loops follow them with the hull's model as feed-forward: a robot that
swims well is near its reference. It cannot be ahead of it, but it can be behind it by as
much as the loops, the fins' delay and a late start allow: the fins start their first
strokes seconds after arming on a busy computer (the first plans take long), while the
reference already ramps. So each axis is judged against an envelope between two edges:

* the fast edge: the body layer's reference itself;
* the slow edge: the reference through the slowest response the body layer is designed to
  give, a first-order lag of the fins' delay ``tau`` (``control.params.DESIGN_DELAY``)
  and a critically damped pair of poles at the loop's bandwidth ``w_b`` (two first-order
  lags of ``1 / w_b``; ``control.body_design``: speed and depth at ``1 / (k tau)``, heading
  at ``1 / (HEADING_FACTOR tau)``), its rate at most the robot's limit on that axis (the
  acceleration, the dive rate, the yaw rate). It starts from the measured value when the
  fins start (the first stroke after the fins are driven; :meth:`Envelope.start`) and runs
  on from its own state through every later setpoint change.

An axis is off when the measured value (reference plus the published error) is further
than its band from the envelope (:func:`outside`); the failsafe counts how long. A heading
is an angle: every difference is wrapped to (-pi, pi].

Pure: time is an argument, no clock, no thread.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


def wrap(a: float) -> float:
    """``a`` wrapped to (-pi, pi]."""
    w = math.remainder(a, 2.0 * math.pi)
    return math.pi if w == -math.pi else w


@dataclass(frozen=True)
class AxisModel:
    """The slowest response the body layer is designed to give on one axis."""

    delay: float  # s: the fins' delay (first-order lag)
    bandwidth: float  # rad/s: the closed loop's double pole
    max_rate: float  # the axis's unit per s: the robot's fastest change
    angle: bool = False  # the axis is an angle (wrapped)

    def __post_init__(self) -> None:
        for name in ("delay", "bandwidth", "max_rate"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0.0):
                raise ValueError(f"{name}: expected a finite value > 0, got {v!r}")

    def lags(self) -> tuple[float, float, float]:
        """The three first-order lags' time constants (s)."""
        return (self.delay, 1.0 / self.bandwidth, 1.0 / self.bandwidth)


def slow_step(stages: tuple[float, float, float], dt: float, ref: float,
              model: AxisModel) -> tuple[float, float, float]:
    """The slow edge's three lag stages (the last is the edge) moved on by ``dt`` s towards
    ``ref``: each stage exact for a reference held over ``dt``, the edge's change at most
    ``model.max_rate * dt``."""
    diff = wrap if model.angle else (lambda x: x)
    out = []
    u = ref
    for k, (y, tc) in enumerate(zip(stages, model.lags())):
        step = diff(u - y) * -math.expm1(-dt / tc)
        if k == 2:
            limit = model.max_rate * dt
            step = min(limit, max(-limit, step))
        y = y + step
        y = wrap(y) if model.angle else y
        out.append(y)
        u = y
    return out[0], out[1], out[2]


def outside(measured: float, ref: float, slow: float, angle: bool = False) -> float:
    """How far ``measured`` is outside the envelope between ``ref`` (the fast edge) and
    ``slow`` (the slow edge): 0 within it, > 0 beyond the higher edge, < 0 below the lower."""
    diff = wrap if angle else (lambda x: x)
    x, s = diff(measured - ref), diff(slow - ref)
    lo, hi = min(0.0, s), max(0.0, s)
    if x > hi:
        return x - hi
    if x < lo:
        return x - lo
    return 0.0


class Envelope:
    """One axis's slow edge over time (module docstring)."""

    __slots__ = ("model", "stages", "t")

    def __init__(self, model: AxisModel) -> None:
        self.model = model
        self.stages: tuple[float, float, float] | None = None
        self.t = math.nan

    def start(self, t: float, value: float) -> None:
        """The edge starts at ``value`` (measured) at ``t``: every stage at rest there."""
        self.stages = (value, value, value) if math.isfinite(value) else None
        self.t = t

    def stop(self) -> None:
        self.stages = None

    def off(self, t: float, ref: float, measured: float) -> float:
        """The edge moved on to ``t`` (towards ``ref``), and :func:`outside` for ``measured``;
        NaN where the reference or the measurement is missing (the edge starts again from the
        next measured value)."""
        if not (math.isfinite(ref) and math.isfinite(measured)):
            self.stages = None
            return math.nan
        if self.stages is None:
            self.start(t, measured)
        assert self.stages is not None
        dt = t - self.t
        if dt > 0.0:
            self.stages = slow_step(self.stages, dt, ref, self.model)
            self.t = t
        return outside(measured, ref, self.stages[2], self.model.angle)
