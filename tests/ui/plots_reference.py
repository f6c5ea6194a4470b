"""The live plots' series as numpy computed them before ``ui/plot_series.py``: the
reference the compiled pass is checked against (``test_plots.py``)."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ucat_console.ui.plots import COL, N_FINS, ST_HIDDEN, ST_MIN_SPEED, VALUES, RingBuffer

_VALUES_MAX = float(np.finfo(VALUES).max)
_ST_ROWS = [COL[f"st{i}"] for i in range(N_FINS)]
_TRACKED = ("depth", "velocity", "yaw_rate")
_TRACKED_ROWS = np.array([[COL[name], COL[f"{name}_sp"]] for name in _TRACKED])


def filled(a: np.ndarray) -> np.ndarray:
    """``a`` with NaN replaced by the last finite value before it (leading NaN by the first
    finite value; NaN when there is none); a 2-D ``a`` column by column."""
    ok = np.isfinite(a)
    if ok.all():
        return a
    if a.ndim == 2:
        out = a.copy()
        for j in np.flatnonzero(~ok.all(axis=0)):
            out[:, j] = filled(a[:, j])
        return out
    if not ok.any():
        return np.full_like(a, np.nan)
    idx = np.where(ok, np.arange(len(a)), 0)
    np.maximum.accumulate(idx, out=idx)
    out = a[idx]
    first = int(np.argmax(ok))
    out[:first] = a[first]
    return out


def st_shown(st: np.ndarray, armed: np.ndarray, speed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(St drawn on the 0-1 axis, markers at 1 where St is above 1)."""
    hide = ~(armed > 0.5) | ~(np.abs(speed) >= ST_MIN_SPEED) | ~np.isfinite(st)
    shown = np.where(hide, ST_HIDDEN, np.minimum(st, 1.0))
    above = np.where(~hide & (st > 1.0), 1.0, ST_HIDDEN)
    return shown, above


def span_pins(series: np.ndarray, span: Sequence[float]) -> np.ndarray:
    """For each chart, two constant series around the middle of its series at least
    ``span[c]`` apart: (charts, 2, n), of ``series``' type."""
    charts, n = series.shape[0], series.shape[-1]
    flat = series.reshape(charts, -1)
    finite = np.isfinite(flat)
    lo = np.where(finite, flat, np.inf).min(axis=1).astype(np.float64)
    hi = np.where(finite, flat, -np.inf).max(axis=1).astype(np.float64)
    has = finite.any(axis=1)
    mid = 0.5 * np.where(has, lo, 0.0) + 0.5 * np.where(has, hi, 0.0)
    half = 0.5 * np.asarray(span, dtype=np.float64)
    pins = np.empty((charts, 2, n), series.dtype)
    pins[:, 0] = (mid - half)[:, None]
    pins[:, 1] = (mid + half)[:, None]
    return pins


def chart_data(buffer: RingBuffer, n: int, max_points: int, corridor: tuple[float, float],
               spans: Sequence[float]) -> dict[str, tuple[np.ndarray, ...]] | None:
    """Each chart's data (st, depth, velocity, yaw_rate, power) for the last ``n`` rows, as
    the numpy refresh sent it; None where it sent nothing."""
    r = buffer.last(n, max_points)
    if r.shape[0] < 2 or not r[-1, 0] > r[0, 0]:
        return None
    r[:, 1:] = filled(r[:, 1:])
    col = np.ascontiguousarray(r.T)
    t = col[0]
    val = np.clip(col, -_VALUES_MAX, _VALUES_MAX).astype(VALUES)
    lo, hi = corridor
    shown, above = st_shown(col[_ST_ROWS], col[COL["armed"]], col[COL["velocity"]])
    m = len(t)
    with np.errstate(over="ignore"):  # a huge negative St becomes -inf, as it did
        out = {"st": (t, np.full(m, hi, VALUES), np.full(m, lo, VALUES), *shown.astype(VALUES),
                      above.max(axis=0).astype(VALUES))}
    tracked = val[_TRACKED_ROWS]
    pins = span_pins(tracked, spans)
    for k, name in enumerate(_TRACKED):
        out[name] = (t, tracked[k, 0], tracked[k, 1], pins[k, 0], pins[k, 1])
    # the battery's power where the window has its total, the estimate's total beside it; else
    # the estimate's, nothing beside it
    battery = bool(np.isfinite(col[COL["e_total"]]).any())
    p, mean, epm = ("e", "e_mean", "e_energy_per_metre") if battery else ("p", "p_mean", "energy_per_metre")
    shaft = val[COL["p_total"]] if battery else np.full(m, np.nan, VALUES)
    out["power"] = (t, *(val[COL[f"{p}{i}"]] for i in range(N_FINS)), val[COL[f"{p}_total"]], val[COL[mean]],
                    val[COL[epm]], shaft)
    return out
