"""Evaluation metrics of the paper's Tables III and V (control.md section 10).

Pure functions over numpy arrays. Empty or non-finite input raises ValueError naming the
argument; nothing is silently averaged over zero samples.

* force error: mean of the per-plan ``c_force`` (N) of the executed plans;
* St deviation / St MAE: mean ``|St - St_opt|``;
* in-range rate: share of plans with ``st_low <= St <= st_high`` (a fraction in [0, 1]);
* command stability: mean over successive plans of ``|u_t - u_{t-1}|_1``;
* velocity MAE: mean ``|v - v_ref|``;
* mean power (time average when times are given) and the saving against a baseline run
  at the same reference, in percent: ``100 (P_baseline - P) / P_baseline``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ucat_console.control.argcheck import finite_array, in_range
from ucat_console.control.power import time_mean


def force_error(force_errors: ArrayLike) -> float:
    """Mean force tracking error (N) from per-plan ``c_force`` values (each >= 0)."""
    e = finite_array("force_errors", force_errors)
    if np.any(e < 0.0):
        raise ValueError("force_errors: c_force values are 1-norms; allowed: >= 0")
    return float(e.mean())


def st_deviation(st: ArrayLike, st_opt: float = 0.30) -> float:
    """Mean absolute deviation of the Strouhal numbers ``st`` from ``st_opt``."""
    s = finite_array("st", st)
    opt = in_range("st_opt", st_opt, 0.0, lo_open=True)
    return float(np.abs(s - opt).mean())


#: Table V's "St MAE against St_opt" is the same quantity as Table III's St deviation.
st_mae = st_deviation


def in_range_rate(st: ArrayLike, st_low: float = 0.25, st_high: float = 0.35) -> float:
    """Share (0..1) of Strouhal numbers inside the corridor [st_low, st_high]."""
    s = finite_array("st", st)
    lo = in_range("st_low", st_low, 0.0)
    hi = in_range("st_high", st_high, lo, lo_open=True)
    return float(np.count_nonzero((s >= lo) & (s <= hi)) / s.size)


def command_stability(u: ArrayLike) -> float:
    """Mean of ``|u_t - u_{t-1}|_1`` over successive plans; ``u`` has shape (plans, n)."""
    a = finite_array("u", u, ndim=2)
    if a.shape[0] < 2:
        raise ValueError(f"u: at least 2 successive plans are needed, got {a.shape[0]}")
    return float(np.abs(np.diff(a, axis=0)).sum(axis=1).mean())


def velocity_mae(v: ArrayLike, v_ref: ArrayLike) -> float:
    """Mean absolute velocity error (m/s); ``v_ref`` a scalar or an array like ``v``."""
    a = finite_array("v", v)
    r = finite_array("v_ref", v_ref)
    if r.size != 1 and r.shape != a.shape:
        raise ValueError(f"v_ref: shape {r.shape} does not match v {a.shape}")
    return float(np.abs(a - r).mean())


def mean_power(p: ArrayLike, t: ArrayLike | None = None) -> float:
    """Mean power (W): time average over sample times ``t`` if given, else sample mean."""
    a = finite_array("p", p, ndim=1)
    if t is None:
        return float(a.mean())
    return time_mean(t, a)


def power_saving(p: float, p_baseline: float) -> float:
    """Saving (%) of mean power ``p`` against ``p_baseline`` at the same reference."""
    base = in_range("p_baseline", p_baseline, 0.0, lo_open=True, unit="W")
    x = in_range("p", p, 0.0, unit="W")
    return 100.0 * (base - x) / base
