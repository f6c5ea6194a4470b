"""Mechanical power of the fins from encoder positions (control.md section 9, paper V.B).

Per fin, from angle samples ``(t_i, theta_i)``::

    w_i     = LP( (theta_i - theta_{i-1}) / (t_i - t_{i-1}) )
    alpha_i = LP( (w_i - w_{i-1}) / (t_i - t_{i-1}) )
    P_inert = I alpha w
    P_drag  = 0.5 rho C_D A_f (r_c |w|)^3
    P_fin   = max(0, P_inert) + P_drag              (the motors do not regenerate)

LP is the first-order low-pass of :class:`ucat_console.control.filters.LowPass` with time
constant ``PowerConfig.filter_tau`` (``y += (1 - exp(-dt/tau)) (x - y)``, initialised with
its first input; ``tau = 0`` disables it). The rate needs two samples and the acceleration
three, so the first estimate comes with the third sample. ``I`` is
``PowerConfig.fin_inertia``; rho, C_D, A_f and r_c are the controller's (``MpcConfig``).

Means over a run are time averages (trapezoidal rule over the sample times).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ucat_console.control.argcheck import finite, finite_array, in_range
from ucat_console.control.filters import LowPass
from ucat_console.control.params import MpcConfig, PowerConfig


def drag_coefficient(cfg: MpcConfig) -> float:
    """k in P_drag = k |w|^3: 0.5 rho C_D A_f r_c^3."""
    return 0.5 * cfg.rho * cfg.c_d * cfg.fin_area * cfg.r_c**3


def drag_power(w: ArrayLike, cfg: MpcConfig) -> NDArray[np.float64]:
    """P_drag = 0.5 rho C_D A_f (r_c |w|)^3 (W) for fin rates ``w`` (rad/s)."""
    return drag_coefficient(cfg) * np.abs(np.asarray(w, dtype=float)) ** 3


def time_mean(t: ArrayLike, x: ArrayLike) -> float:
    """Time average of samples ``x`` at times ``t`` (trapezoidal rule), for 1-D arrays."""
    t = finite_array("t", t, ndim=1)
    x = finite_array("x", x, ndim=1)
    if t.shape != x.shape:
        raise ValueError(f"x: shape {x.shape} does not match t {t.shape}")
    if t.size < 2:
        raise ValueError("t: at least 2 samples are needed for a time average")
    if np.any(np.diff(t) <= 0.0):
        raise ValueError("t: sample times must be strictly increasing")
    return float(np.trapezoid(x, t) / (t[-1] - t[0]))


@dataclass(frozen=True)
class PowerSample:
    """One power estimate (rates rad/s, rad/s^2; powers W)."""

    t: float
    w: float
    alpha: float
    p_inert: float
    p_drag: float
    p_fin: float


class PowerEstimator:
    """Streaming power estimate for one fin; ``update(t, theta)`` per encoder sample."""

    def __init__(self, pcfg: PowerConfig, mcfg: MpcConfig) -> None:
        self.pcfg = pcfg
        self.mcfg = mcfg
        # scalar per-sample update (it runs at the PDO rate)
        self._k_drag = drag_coefficient(mcfg)
        self._w_lp = LowPass(pcfg.filter_tau)
        self._a_lp = LowPass(pcfg.filter_tau)
        self.reset()

    def reset(self) -> None:
        self._w_lp.reset()
        self._a_lp.reset()
        self._t: float | None = None
        self._theta = 0.0
        self._w: float | None = None
        self.energy = 0.0  # J, trapezoidal integral of P_fin over the accumulated spans
        self.duration = 0.0  # s covered by ``energy``
        self._last: PowerSample | None = None

    @property
    def last(self) -> PowerSample | None:
        return self._last

    @property
    def mean_power(self) -> float | None:
        """Mean P_fin (W) over the accumulated spans, None before one was accumulated."""
        return self.energy / self.duration if self.duration > 0.0 else None

    def update(self, t: float, theta: float, accumulate: bool = True) -> PowerSample | None:
        """Add an encoder angle sample; returns the estimate (None for the first two samples).

        With ``accumulate`` False the span since the last estimate is left out of ``energy``
        and ``duration`` (the fin is not driven: moved by the water or stopping after a
        disarm); the estimate itself is made as always."""
        t = finite("t", t)
        theta = finite("theta", theta)
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


@dataclass(frozen=True)
class PowerTrace:
    """Batch power estimate of one fin: arrays aligned with ``t`` (from the third sample on)."""

    t: NDArray[np.float64]
    w: NDArray[np.float64]
    alpha: NDArray[np.float64]
    p_inert: NDArray[np.float64]
    p_drag: NDArray[np.float64]
    p_fin: NDArray[np.float64]

    @property
    def mean_power(self) -> float:
        return time_mean(self.t, self.p_fin)


def power_trace(t: ArrayLike, theta: ArrayLike, pcfg: PowerConfig, mcfg: MpcConfig) -> PowerTrace:
    """The streaming estimate run over a whole recording of one fin (same numbers)."""
    t = finite_array("t", t, ndim=1)
    theta = finite_array("theta", theta, ndim=1)
    if t.shape != theta.shape:
        raise ValueError(f"theta: shape {theta.shape} does not match t {t.shape}")
    if t.size < 3:
        raise ValueError("t: at least 3 samples are needed (rate and acceleration)")
    est = PowerEstimator(pcfg, mcfg)
    n = t.size - 2
    out = np.empty((5, n))
    for i in range(t.size):
        s = est.update(float(t[i]), float(theta[i]))
        if s is not None:
            out[:, i - 2] = (s.w, s.alpha, s.p_inert, s.p_drag, s.p_fin)
    return PowerTrace(t[2:].copy(), *out)


def fleet_mean_power(
    t: ArrayLike, theta: ArrayLike, pcfg: PowerConfig, mcfg: MpcConfig
) -> tuple[NDArray[np.float64], float]:
    """Mean P_fin per fin and summed, for angles ``theta`` of shape (samples, fins)."""
    theta = finite_array("theta", theta, ndim=2)
    per_fin = np.array(
        [power_trace(t, theta[:, k], pcfg, mcfg).mean_power for k in range(theta.shape[1])]
    )
    return per_fin, float(per_fin.sum())


def energy_per_metre(mean_power: float, duration: float, distance: float) -> float:
    """Energy per distance travelled (J/m) of a run at ``mean_power`` W for ``duration`` s."""
    p = in_range("mean_power", mean_power, 0.0, unit="W")
    T = in_range("duration", duration, 0.0, unit="s")
    d = in_range("distance", distance, 0.0, lo_open=True, unit="m")
    return p * T / d
