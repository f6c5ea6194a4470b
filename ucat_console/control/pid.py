"""PID controller as a pure state object (time is an argument).

Form, with ``e = setpoint - measurement``::

    u = kp e + I - kd dy/dt        (derivative on measurement; dy/dt of -e when only e is given)
    I <- I + ki e dt               (integral kept in output units, so changing ki never bumps)
    u <- clip(u, -limit, limit)

Anti-windup by conditional integration: the integral is not advanced on a step where the
output is saturated and the error pushes it further into saturation, and the integral term
itself is kept within [-limit, limit]. After a long saturation the integral therefore holds
at most what it had when the output first saturated (plus one step), and the output leaves
saturation on the first step at which the error changes sign enough to pull it back.

``preset(output)`` sets the integral so that the next output, with unchanged error and
measurement, equals ``output`` (bumpless transfer when a loop is switched on).
"""

from __future__ import annotations

from math import isfinite

from ucat_console.control.argcheck import finite
from ucat_console.control.params import PidGains


class Pid:
    """One PID loop; ``update`` returns the limited output."""

    def __init__(self, gains: PidGains) -> None:
        self.gains = gains
        self.reset()

    def reset(self) -> None:
        """Forget the integral, the last sample and the last output."""
        self.integral = 0.0  # integral term, in output units
        self.output = 0.0
        self.saturated = False
        self._t: float | None = None
        self._y: float | None = None  # last measurement (or -error)
        self._p = 0.0
        self._d = 0.0

    def set_gains(self, gains: PidGains) -> None:
        """New gains, keeping the integral (clipped to the new limit)."""
        self.gains = gains
        self.integral = min(gains.limit, max(-gains.limit, self.integral))

    def preset(self, output: float) -> None:
        """Make the next output equal ``output`` for the same inputs (bumpless transfer)."""
        out = finite("output", output)
        lim = self.gains.limit
        out = min(lim, max(-lim, out))
        self.integral = min(lim, max(-lim, out - self._p - self._d))
        self.output = out

    def update(self, target: float | tuple[float, float], t: float) -> float:
        """Advance to time ``t`` (s) and return the output.

        ``target`` is either the error ``e`` or a pair ``(setpoint, measurement)``; with the
        pair the derivative acts on the measurement only, so a setpoint step gives no kick.
        ``t`` must not decrease; a repeated ``t`` neither integrates nor differentiates anew.
        """
        if isinstance(target, tuple):
            if len(target) != 2:
                raise ValueError(f"target: expected (setpoint, measurement), got {target!r}")
            sp, y = target
            if not (isfinite(sp) and isfinite(y) and isfinite(t)):  # inline: the control rate
                finite("setpoint", sp)
                finite("measurement", y)
                finite("t", t)
            e = sp - y
        else:
            e = target
            if not (isfinite(e) and isfinite(t)):
                finite("error", e)
                finite("t", t)
            y = -e
        g = self.gains
        p = g.kp * e
        d = self._d
        dt = 0.0
        if self._t is not None:
            if t < self._t:
                raise ValueError(f"t: {t!r} is earlier than the last update at {self._t!r}")
            dt = t - self._t
        if dt > 0.0 and self._y is not None:
            d = -g.kd * (y - self._y) / dt
        integral = self.integral
        if dt > 0.0:
            candidate = integral + g.ki * e * dt
            unsat = p + candidate + d
            pushes_out = (unsat > g.limit and e > 0.0) or (unsat < -g.limit and e < 0.0)
            if not pushes_out:
                integral = min(g.limit, max(-g.limit, candidate))
        u = p + integral + d
        out = min(g.limit, max(-g.limit, u))
        self.saturated = out != u
        self.integral = integral
        self.output = out
        self._p, self._d = p, d
        if dt > 0.0 or self._t is None:
            self._t, self._y = t, y
        return out
