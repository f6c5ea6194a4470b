"""The Python implementations that the compiled per-sample kernels replaced, kept as the
reference the kernels are tested against (``test_power.py``, ``test_stroke_watch.py``).

They are the code the closed loop ran before its per-sample path was compiled, unchanged
but for the names of what they import.
"""

from __future__ import annotations

import math

from ucat_console.control.filters import LowPass
from ucat_console.control.params import ExecutorConfig, PowerConfig
from ucat_console.control.power import PowerSample, drag_coefficient


class ReferencePowerEstimator:
    """Streaming power estimate for one fin; ``update(t, theta)`` per encoder sample."""

    def __init__(self, pcfg: PowerConfig) -> None:
        self.pcfg = pcfg
        self._k_drag = drag_coefficient(pcfg)
        self._w_lp = LowPass(pcfg.filter_tau)
        self._a_lp = LowPass(pcfg.filter_tau)
        self._t: float | None = None
        self._theta = 0.0
        self._w: float | None = None
        self.energy = 0.0
        self.duration = 0.0
        self._last: PowerSample | None = None

    def update(self, t: float, theta: float, accumulate: bool = True) -> PowerSample | None:
        if self._t is None:
            self._t, self._theta = t, theta
            return None
        dt = t - self._t
        if dt <= 0.0:
            raise ValueError(f"t: {t!r} is not after the last sample at {self._t!r}")
        w = self._w_lp.update((theta - self._theta) / dt, t)
        w_prev = self._w
        self._t, self._theta, self._w = t, theta, w
        if w_prev is None:
            return None
        alpha = self._a_lp.update((w - w_prev) / dt, t)
        p_inert = self.pcfg.fin_inertia * alpha * w
        p_drag = self._k_drag * abs(w) ** 3
        sample = PowerSample(t, w, alpha, p_inert, p_drag, max(0.0, p_inert) + p_drag)
        if self._last is not None and accumulate:
            span = t - self._last.t
            self.energy += 0.5 * (sample.p_fin + self._last.p_fin) * span
            self.duration += span
        self._last = sample
        return sample


class ReferenceFinWatch:
    """Feedback predictor and end-of-stroke detection for one physical fin."""

    def __init__(self, fin: int, cfg: ExecutorConfig) -> None:
        self.fin = fin
        self.cfg = cfg
        self.t_fb: float | None = None
        self.w_fb = 0.0
        self.a = 0.0
        self.theta_fb: float | None = None
        self.target: float | None = None  # target of the current / last stroke
        self.active = False
        self.done = True
        self.t_start = 0.0
        self.direction = 0.0
        self.armed = True
        self.planned = 0.0
        self.timeout_at = math.inf

    def start(self, t: float, theta_from: float | None, theta_ref: float, w_ref: float) -> None:
        cfg = self.cfg
        if theta_from is None:
            theta_from = self.target if self.target is not None else self.theta_fb
        if theta_from is None:
            length = None
            self.direction = 0.0
            self.planned = math.pi / w_ref
        else:
            delta = theta_ref - theta_from
            length = abs(delta)
            self.direction = math.copysign(1.0, delta) if delta != 0.0 else 0.0
            self.planned = length / w_ref
        short = length is not None and length < cfg.w_threshold * cfg.min_stroke_time
        self.armed = short or w_ref <= cfg.w_threshold
        self.t_start = t
        self.timeout_at = t + max(cfg.stroke_timeout_min, cfg.stroke_timeout_factor * self.planned)
        self.target = theta_ref
        self.active = True
        self.done = False

    def feed(self, t_fb: float, w_fb: float, theta_fb: float | None) -> None:
        if self.t_fb is not None:
            if t_fb < self.t_fb:
                raise ValueError(
                    f"t_fb: {t_fb!r} is earlier than the last feedback at {self.t_fb!r}"
                )
            if t_fb == self.t_fb:
                return  # the same sample again
            self.a = (w_fb - self.w_fb) / (t_fb - self.t_fb)
        self.t_fb, self.w_fb = t_fb, w_fb
        if theta_fb is not None:
            self.theta_fb = theta_fb
        if self.active and not self.armed and t_fb >= self.t_start:
            moving = self.direction * w_fb if self.direction else abs(w_fb)
            if moving > self.cfg.w_threshold:
                self.armed = True

    def check(self, t_now: float, predict: bool) -> str | None:
        """Mark the stroke done and return why ("stopped" / "timeout"), or None."""
        if self.done:
            return None
        cfg = self.cfg
        if (
            predict
            and self.armed
            and self.t_fb is not None
            and self.t_fb >= self.t_start
            and t_now - self.t_start >= cfg.min_stroke_time
        ):
            w_pred = self.w_fb + self.a * (t_now - self.t_fb)
            moving = self.direction * w_pred if self.direction else abs(w_pred)
            if moving < cfg.w_threshold:
                self.done = True
                return "stopped"
        if t_now >= self.timeout_at:
            self.done = True
            return "timeout"
        return None


