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
``schedule(scale)`` runs the gains times ``scale`` from now on (a gain schedule).
"""

from __future__ import annotations

import math
from math import isfinite

import numpy as np
from numba.extending import register_jitable

from ucat_console.control.argcheck import finite
from ucat_console.control.params import PidGains
from ucat_console.robot.layout import Layout

# the declared layout of one PID's numbers (a row of a float array): its state, then its gains
PID_ROW = Layout("one PID's numbers", [
    ("integral", 1, "integral term, in output units"), ("output", 1, "the last output"),
    ("saturated", 1, "1.0: the last output was limited"), ("t", 1, "time of the last sample (NaN: none yet)"),
    ("y", 1, "the last measurement, or -error (NaN: none yet)"), ("p", 1, "the last proportional term"),
    ("d", 1, "the last derivative term"), ("kp", 1, "proportional gain"), ("ki", 1, "integral gain"),
    ("kd", 1, "derivative gain"), ("limit", 1, "output limit"),
    ("i_prev", 1, "the integral before the last step's increment (pid_unwind)"),
])
PID_INTEGRAL, PID_OUTPUT, PID_SATURATED, PID_T, PID_Y, PID_P, PID_D, PID_KP, PID_KI, PID_KD, PID_LIMIT, \
    PID_I_PREV = (PID_ROW.at(f) for f in PID_ROW.fields)
NPID = PID_ROW.size

#: what :func:`pid_step` returns for a time earlier than the last update (nothing changed)
EARLIER = math.inf


@register_jitable
def pid_reset(s: np.ndarray) -> None:
    """Forget the integral, the last sample and the last output (the gains stay)."""
    s[PID_INTEGRAL] = 0.0
    s[PID_OUTPUT] = 0.0
    s[PID_SATURATED] = 0.0
    s[PID_T] = math.nan
    s[PID_Y] = math.nan
    s[PID_P] = 0.0
    s[PID_D] = 0.0
    s[PID_I_PREV] = 0.0


@register_jitable
def pid_step(s: np.ndarray, e: float, y: float, t: float) -> float:
    """One update of the PID ``s`` at time ``t`` with error ``e`` and measurement ``y``
    (``-e`` without one); the limited output, or :data:`EARLIER` when ``t`` is before the
    last update. The one definition of the step (module docstring): :class:`Pid` runs it
    as Python, the closed loop's compiled core compiled."""
    t_last = s[PID_T]
    if not math.isnan(t_last) and t < t_last:
        return EARLIER
    dt = 0.0 if math.isnan(t_last) else t - t_last
    d = s[PID_D]
    if dt > 0.0 and not math.isnan(s[PID_Y]):
        d = -s[PID_KD] * (y - s[PID_Y]) / dt
    return _pid_finish(s, e, d, y, t, dt)


@register_jitable
def pid_step_rate(s: np.ndarray, e: float, de: float, t: float) -> float:
    """:func:`pid_step` with the error's rate ``de`` measured (a gyro's, for a heading):
    the derivative term is ``kd de``."""
    t_last = s[PID_T]
    if not math.isnan(t_last) and t < t_last:
        return EARLIER
    dt = 0.0 if math.isnan(t_last) else t - t_last
    return _pid_finish(s, e, s[PID_KD] * de, -e, t, dt)


@register_jitable
def pid_unwind(s: np.ndarray, direction: float) -> None:
    """Something after the PID cut its output in ``direction`` (> 0: it gave less than the
    PID asked, < 0: more negative than asked): undo the last step's integration if it pushed
    that way, so the integral does not wind up against a limit the PID does not see."""
    if (s[PID_INTEGRAL] - s[PID_I_PREV]) * direction > 0.0:
        s[PID_INTEGRAL] = s[PID_I_PREV]
    if direction != 0.0:
        s[PID_SATURATED] = 1.0


@register_jitable
def _pid_finish(s: np.ndarray, e: float, d: float, y: float, t: float, dt: float) -> float:
    """The step's integral, output and state, with the derivative term ``d`` worked out."""
    p = s[PID_KP] * e
    limit = s[PID_LIMIT]
    t_last = s[PID_T]
    integral = s[PID_INTEGRAL]
    s[PID_I_PREV] = integral
    if dt > 0.0:
        candidate = integral + s[PID_KI] * e * dt
        unsat = p + candidate + d
        pushes_out = (unsat > limit and e > 0.0) or (unsat < -limit and e < 0.0)
        if not pushes_out:
            integral = min(limit, max(-limit, candidate))
    u = p + integral + d
    out = min(limit, max(-limit, u))
    s[PID_SATURATED] = 1.0 if out != u else 0.0
    s[PID_INTEGRAL] = integral
    s[PID_OUTPUT] = out
    s[PID_P] = p
    s[PID_D] = d
    if dt > 0.0 or math.isnan(t_last):
        s[PID_T] = t
        s[PID_Y] = y
    return out


def set_pid_gains(s: np.ndarray, gains: PidGains, cap: float = math.inf,
                  scale: tuple[float, float, float] = (1.0, 1.0, 1.0)) -> None:
    """New gains in the PID ``s`` (``gains`` times ``scale``: kp, ki, kd), keeping the
    integral (clipped to the new limit); the limit is the gains' or ``cap``, whichever is
    smaller."""
    limit = min(gains.limit, cap)
    s[PID_KP], s[PID_KI], s[PID_KD] = gains.kp * scale[0], gains.ki * scale[1], gains.kd * scale[2]
    s[PID_LIMIT] = limit
    s[PID_INTEGRAL] = min(limit, max(-limit, float(s[PID_INTEGRAL])))


class Pid:
    """One PID loop; ``update`` returns the limited output. Its numbers are a row of
    ``state`` (layout ``PID_*``): its own, or a row of a table another owner shares (the
    closed loop's compiled core runs the same rows)."""

    def __init__(self, gains: PidGains, state: np.ndarray | None = None, cap: float = math.inf) -> None:
        self.state = np.zeros(NPID) if state is None else state
        self.gains = gains
        self.cap = cap  # the output never exceeds this either (what the actuators can do)
        self.scale = (1.0, 1.0, 1.0)  # the gains run are ``gains`` times this (kp, ki, kd)
        set_pid_gains(self.state, gains, cap)
        self.reset()

    @property
    def limit(self) -> float:
        """The output limit in force: the gains' or the cap, whichever is smaller."""
        return float(self.state[PID_LIMIT])

    def reset(self) -> None:
        """Forget the integral, the last sample and the last output."""
        pid_reset(self.state)

    @property
    def integral(self) -> float:
        return float(self.state[PID_INTEGRAL])

    @property
    def output(self) -> float:
        return float(self.state[PID_OUTPUT])

    @property
    def saturated(self) -> bool:
        return bool(self.state[PID_SATURATED] != 0.0)

    def set_gains(self, gains: PidGains) -> None:
        """New gains, keeping the integral (clipped to the new limit)."""
        self.gains = gains
        set_pid_gains(self.state, gains, self.cap, self.scale)

    def schedule(self, scale: tuple[float, float, float]) -> None:
        """Run the gains times ``scale`` (kp, ki, kd; each >= 0) from now on, the integral
        kept (it is in output units: a new ki does not move the output)."""
        for name, x in zip(("kp", "ki", "kd"), scale):
            if not (math.isfinite(x) and x >= 0.0):
                raise ValueError(f"scale.{name}: {x!r} is out of range; allowed: a finite number >= 0")
        self.scale = (float(scale[0]), float(scale[1]), float(scale[2]))
        set_pid_gains(self.state, self.gains, self.cap, self.scale)

    def preset(self, output: float) -> None:
        """Make the next output equal ``output`` for the same inputs (bumpless transfer)."""
        out = finite("output", output)
        lim = self.limit
        out = min(lim, max(-lim, out))
        s = self.state
        s[PID_INTEGRAL] = min(lim, max(-lim, out - float(s[PID_P]) - float(s[PID_D])))
        s[PID_OUTPUT] = out

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
            if not (isfinite(sp) and isfinite(y) and isfinite(t)):
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
        out = pid_step(self.state, float(e), float(y), float(t))
        if out == EARLIER:
            raise ValueError(f"t: {t!r} is earlier than the last update at {float(self.state[PID_T])!r}")
        return out
