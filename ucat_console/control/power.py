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
three, so the first estimate comes with the third sample. ``I``, rho, C_D, A_f and r_c are
the fin's own (``PowerConfig``), not the controller's model: an MPC given other coefficients
(identified, or tuned) plans with them, and the power is still measured with the fin's.

The estimate runs on every encoder sample of every fin (100 Hz x 4), so it is a numba
kernel (``cache=True``) over a :class:`PowerBank` table with one row per fin;
:class:`PowerEstimator` is one fin's view of it.

Means over a run are time averages (trapezoidal rule over the sample times).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from ucat_console.control.argcheck import finite, finite_array, in_range
from ucat_console.control.params import MpcConfig, PowerConfig
from ucat_console.robot.layout import Layout


def drag_coefficient(cfg: MpcConfig | PowerConfig) -> float:
    """k in P_drag = k |w|^3: 0.5 rho C_D A_f r_c^3 (of the controller's model or of the fin)."""
    return 0.5 * cfg.rho * cfg.c_d * cfg.fin_area * cfg.r_c**3


def drag_power(w: ArrayLike, cfg: MpcConfig | PowerConfig) -> NDArray[np.float64]:
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


# the declared layout of a power table's row ("none yet" is NaN), and its columns
POWER_ROW = Layout("a power table's row", [
    ("t", 1, "time of the last angle sample"), ("theta", 1, "the last angle"), ("w", 1, "the last filtered rate"),
    ("lpw_t", 1, "the rate filter's last time"), ("lpa", 1, "the acceleration filter's value"),
    ("lpa_t", 1, "its last time"),
    ("last_t", 1, "the last estimate: time"), ("last_w", 1, "rate"), ("last_alpha", 1, "acceleration"),
    ("last_inert", 1, "inertial power"), ("last_drag", 1, "drag power"), ("last_fin", 1, "fin power"),
    ("energy", 1, "J over the accumulated spans"), ("duration", 1, "s covered by the energy"),
])
P_T, P_THETA, P_W, P_LPW_T, P_LPA, P_LPA_T, P_LAST_T, P_LAST_W, P_LAST_ALPHA, P_LAST_INERT, P_LAST_DRAG, \
    P_LAST_FIN, P_ENERGY, P_DURATION = (POWER_ROW.at(f) for f in POWER_ROW.fields)
NP = POWER_ROW.size

#: what an update gave
FIRST, SECOND, ESTIMATE, NOT_AFTER = 0, 1, 2, -1


@njit(cache=True)
def clear_power(p: np.ndarray, i: int) -> None:
    for j in range(NP):
        p[i, j] = math.nan
    p[i, P_ENERGY] = 0.0
    p[i, P_DURATION] = 0.0


@njit(cache=True)
def _low_pass(value: float, t_last: float, x: float, t: float, tau: float) -> float:
    if math.isnan(value) or math.isnan(t_last):
        return x
    if tau == 0.0:
        return x
    return value + (1.0 - math.exp(-(t - t_last) / tau)) * (x - value)


@njit(cache=True)
def power_update(p: np.ndarray, i: int, t: float, theta: float, accumulate: bool,
                 k_drag: float, inertia: float, tau: float) -> int:
    """One encoder angle of row ``i``: FIRST, SECOND (no estimate yet), ESTIMATE, or
    NOT_AFTER when ``t`` is not after the row's last sample (nothing changed)."""
    if math.isnan(p[i, P_T]):
        p[i, P_T] = t
        p[i, P_THETA] = theta
        return FIRST
    dt = t - p[i, P_T]
    if dt <= 0.0:
        return NOT_AFTER
    w = _low_pass(p[i, P_W], p[i, P_LPW_T], (theta - p[i, P_THETA]) / dt, t, tau)
    p[i, P_LPW_T] = t
    w_prev = p[i, P_W]
    p[i, P_T] = t
    p[i, P_THETA] = theta
    p[i, P_W] = w
    if math.isnan(w_prev):
        return SECOND
    alpha = _low_pass(p[i, P_LPA], p[i, P_LPA_T], (w - w_prev) / dt, t, tau)
    p[i, P_LPA] = alpha
    p[i, P_LPA_T] = t
    p_inert = inertia * alpha * w
    p_drag = k_drag * math.pow(abs(w), 3.0)
    p_fin = max(0.0, p_inert) + p_drag
    if not math.isnan(p[i, P_LAST_T]) and accumulate:
        span = t - p[i, P_LAST_T]
        p[i, P_ENERGY] += 0.5 * (p_fin + p[i, P_LAST_FIN]) * span
        p[i, P_DURATION] += span
    p[i, P_LAST_T] = t
    p[i, P_LAST_W] = w
    p[i, P_LAST_ALPHA] = alpha
    p[i, P_LAST_INERT] = p_inert
    p[i, P_LAST_DRAG] = p_drag
    p[i, P_LAST_FIN] = p_fin
    return ESTIMATE


@njit(cache=True)
def power_update_all(p: np.ndarray, t: float, theta: np.ndarray, accumulate: bool,
                     k_drag: float, inertia: float, tau: float) -> int:
    """Every row's angle ``theta[i]`` at ``t``; the first row whose ``t`` is not after its
    last sample (nothing changed from it on), or -1."""
    for i in range(theta.shape[0]):
        if power_update(p, i, t, theta[i], accumulate, k_drag, inertia, tau) == NOT_AFTER:
            return i
    return -1


class PowerBank:
    """The streaming power estimate of ``n`` fins (rows), one compiled call per sample time."""

    def __init__(self, pcfg: PowerConfig, n: int) -> None:
        self.pcfg = pcfg
        self.table = np.empty((n, NP))
        self._k_drag = drag_coefficient(pcfg)
        self._inertia = float(pcfg.fin_inertia)
        self._tau = float(pcfg.filter_tau)
        self.reset()

    def reset(self) -> None:
        for i in range(self.table.shape[0]):
            clear_power(self.table, i)

    def update(self, row: int, t: float, theta: float, accumulate: bool = True) -> int:
        """One fin's angle sample (FIRST, SECOND or ESTIMATE); ValueError when ``t`` is not
        after its last sample."""
        out = power_update(self.table, row, t, theta, accumulate, self._k_drag, self._inertia, self._tau)
        if out == NOT_AFTER:
            raise ValueError(f"t: {t!r} is not after the last sample at {self.table[row, P_T]!r}")
        return out

    def update_all(self, t: float, theta: np.ndarray, accumulate: bool = True) -> None:
        """Every fin's angle at one time ``t``; ValueError when ``t`` is not after a fin's
        last sample."""
        bad = power_update_all(self.table, t, theta, accumulate, self._k_drag, self._inertia, self._tau)
        if bad >= 0:
            raise ValueError(f"t: {t!r} is not after fin {bad}'s last sample at {self.table[bad, P_T]!r}")

    def last(self, row: int) -> PowerSample | None:
        r = self.table[row]
        if math.isnan(r[P_LAST_T]):
            return None
        return PowerSample(float(r[P_LAST_T]), float(r[P_LAST_W]), float(r[P_LAST_ALPHA]),
                           float(r[P_LAST_INERT]), float(r[P_LAST_DRAG]), float(r[P_LAST_FIN]))

    def p_fin(self, row: int) -> float:
        """The last power estimate of ``row`` (W), 0 before the first."""
        v = float(self.table[row, P_LAST_FIN])
        return 0.0 if math.isnan(v) else v

    def energy(self, row: int) -> float:
        return float(self.table[row, P_ENERGY])

    def mean_power(self, row: int) -> float | None:
        d = float(self.table[row, P_DURATION])
        return float(self.table[row, P_ENERGY]) / d if d > 0.0 else None


class PowerEstimator:
    """Streaming power estimate for one fin; ``update(t, theta)`` per encoder sample."""

    def __init__(self, pcfg: PowerConfig) -> None:
        self.pcfg = pcfg
        self._bank = PowerBank(pcfg, 1)

    def reset(self) -> None:
        self._bank.reset()

    @property
    def last(self) -> PowerSample | None:
        return self._bank.last(0)

    @property
    def energy(self) -> float:
        """J, trapezoidal integral of P_fin over the accumulated spans."""
        return self._bank.energy(0)

    @property
    def duration(self) -> float:
        """s covered by ``energy``."""
        return float(self._bank.table[0, P_DURATION])

    @property
    def mean_power(self) -> float | None:
        """Mean P_fin (W) over the accumulated spans, None before one was accumulated."""
        return self._bank.mean_power(0)

    def update(self, t: float, theta: float, accumulate: bool = True) -> PowerSample | None:
        """Add an encoder angle sample; returns the estimate (None for the first two samples).

        With ``accumulate`` False the span since the last estimate is left out of ``energy``
        and ``duration`` (the fin is not driven: moved by the water or stopping after a
        disarm); the estimate itself is made as always."""
        out = self._bank.update(0, finite("t", t), finite("theta", theta), accumulate)
        return self._bank.last(0) if out == ESTIMATE else None


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


def power_trace(t: ArrayLike, theta: ArrayLike, pcfg: PowerConfig) -> PowerTrace:
    """The streaming estimate run over a whole recording of one fin (same numbers)."""
    t = finite_array("t", t, ndim=1)
    theta = finite_array("theta", theta, ndim=1)
    if t.shape != theta.shape:
        raise ValueError(f"theta: shape {theta.shape} does not match t {t.shape}")
    if t.size < 3:
        raise ValueError("t: at least 3 samples are needed (rate and acceleration)")
    est = PowerEstimator(pcfg)
    n = t.size - 2
    out = np.empty((5, n))
    for i in range(t.size):
        s = est.update(float(t[i]), float(theta[i]))
        if s is not None:
            out[:, i - 2] = (s.w, s.alpha, s.p_inert, s.p_drag, s.p_fin)
    return PowerTrace(t[2:].copy(), *out)


def fleet_mean_power(
    t: ArrayLike, theta: ArrayLike, pcfg: PowerConfig
) -> tuple[NDArray[np.float64], float]:
    """Mean P_fin per fin and summed, for angles ``theta`` of shape (samples, fins)."""
    theta = finite_array("theta", theta, ndim=2)
    per_fin = np.array(
        [power_trace(t, theta[:, k], pcfg).mean_power for k in range(theta.shape[1])]
    )
    return per_fin, float(per_fin.sum())


def energy_per_metre(mean_power: float, duration: float, distance: float) -> float:
    """Energy per distance travelled (J/m) of a run at ``mean_power`` W for ``duration`` s."""
    p = in_range("mean_power", mean_power, 0.0, unit="W")
    T = in_range("duration", duration, 0.0, unit="s")
    d = in_range("distance", distance, 0.0, lo_open=True, unit="m")
    return p * T / d
