"""The Python implementations that the compiled per-sample kernels replaced, kept as the
reference the kernels are tested against (``test_power.py``, ``test_stroke_watch.py``,
``test_pid.py``, ``test_filters.py``, ``test_allocation.py``, ``test_loop_core.py``,
``backend/sim/test_sim_sensors.py``).

They are the code the closed loop ran before its per-sample path was compiled, unchanged
but for the names of what they import and, for the body-frame layer, for taking a reading's
numbers instead of the reading.
"""

from __future__ import annotations

import math
from collections import deque

from ucat_console.control.argcheck import finite
from ucat_console.control.filters import LowPass
from ucat_console.control.params import BodyConfig, ExecutorConfig, PidGains, PowerConfig
from ucat_console.control.power import PowerSample, drag_coefficient
from ucat_console.robot.units import current_to_pressure, depth_to_pressure, pressure_to_current, pressure_to_depth
from ucat_console.robot.units import LOOP_MAX_MA, LOOP_MIN_MA


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




class ReferencePid:
    """One PID loop; ``update`` returns the limited output."""

    def __init__(self, gains: PidGains) -> None:
        self.gains = gains
        self.integral = 0.0
        self.output = 0.0
        self.saturated = False
        self._t: float | None = None
        self._y: float | None = None
        self._p = 0.0
        self._d = 0.0

    def update(self, target: tuple[float, float], t: float) -> float:
        sp, y = target
        e = sp - y
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


class ReferenceMedian:
    """Median of the last ``window`` samples (all samples while fewer have arrived)."""

    def __init__(self, window: int) -> None:
        self._buf: deque[float] = deque(maxlen=window)

    @property
    def value(self) -> float | None:
        n = len(self._buf)
        if n == 0:
            return None
        s = sorted(self._buf)
        mid = n // 2
        return s[mid] if n % 2 else 0.5 * (s[mid - 1] + s[mid])

    def push(self, x: float) -> None:
        self._buf.append(finite("x", x))


class ReferenceBody:
    """The body-frame PIDs with their input filters (their outputs before allocation)."""

    def __init__(self, cfg: BodyConfig) -> None:
        self.cfg = cfg
        self.velocity_pid = ReferencePid(cfg.velocity)
        self.depth_pid = ReferencePid(cfg.depth)
        self.yaw_pid = ReferencePid(cfg.yaw_rate)
        self.velocity_filter = ReferenceMedian(cfg.median_window)
        self.depth_filter = ReferenceMedian(cfg.median_window)
        self.dvl_missing = 0
        self._yaw_rate: float | None = None
        self._new_v = self._new_z = self._new_r = False
        self.fx = self.fy = self.yaw = 0.0

    def on_dvl(self, valid: bool, v: float) -> None:
        if not valid:
            self.dvl_missing += 1
            return
        self.velocity_filter.push(v)
        self._new_v = True

    def on_depth(self, z: float) -> None:
        self.depth_filter.push(z)
        self._new_z = True

    def on_imu(self, r: float) -> None:
        self._yaw_rate = r
        self._new_r = True

    def update(self, t: float, sp: tuple[float, float, float]) -> tuple[float | None, float | None]:
        v = self.velocity_filter.value
        z = self.depth_filter.value
        r = self._yaw_rate
        if self._new_v and v is not None:
            self.fx = -self.velocity_pid.update((sp[0], v), t)
        if self._new_z and z is not None:
            self.fy = self.cfg.depth_sign * self.depth_pid.update((sp[1], z), t)
        if self._new_r and r is not None:
            self.yaw = self.yaw_pid.update((sp[2], r), t)
        self._new_v = self._new_z = self._new_r = False
        return v, z


def reference_depth(depth: float, noise_pa: float, rho: float, span_pa: float, adc_bits: int,
                    full_scale_ma: float) -> tuple[float, float]:
    """The simulated pressure sensor's (depth, pressure) at a true depth with its noise."""
    gauge = depth_to_pressure(depth, 0.0, rho) + noise_pa
    current = min(max(pressure_to_current(gauge, 0.0, span_pa), LOOP_MIN_MA), LOOP_MAX_MA)
    full = (1 << adc_bits) - 1
    code = min(max(round(current / full_scale_ma * full), 0), full)
    measured = current_to_pressure(code * full_scale_ma / full, 0.0, span_pa)
    return pressure_to_depth(measured, 0.0, rho), measured


def reference_dvl(velocity: tuple[float, float, float], depth: float, n: tuple[float, float, float, float],
                  dropout: float, bottom: float, alt_min: float, alt_max: float
                  ) -> tuple[float, float, float, bool, float]:
    """The simulated DVL's (vx, vy, vz, valid, altitude) with its noise row ``n``."""
    drop = 0.5 * math.erfc(-n[3] / math.sqrt(2.0)) < dropout
    altitude = bottom - depth
    in_range = alt_min <= altitude <= alt_max
    if not in_range or drop:
        return math.nan, math.nan, math.nan, False, altitude if in_range else math.nan
    return velocity[0] + n[0], velocity[1] + n[1], velocity[2] + n[2], True, altitude
