"""The plots' series from the ring buffer's rows, in one compiled pass (:func:`series`).

Each refresh of the live plots (12 a second) turns the last rows of the plot ring buffer
into the 28 series the five charts draw: the window's rows (decimated to a bound), every
value column with its gaps filled, the Strouhal numbers hidden or capped, the tracking
charts' axis pins, the power chart's power chosen (the battery's, else the estimate's),
all but the time axis as float32. Done with numpy it took some forty array operations,
0.7 ms a refresh in the console with two pages (each operation's call costs more than its
arithmetic on a few hundred rows), about a tenth of the live view's thread; here it is
one call. ``ui/plots.py`` says what each series means; the tests keep the numpy version
as the reference and check that both give the same arrays.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: the value series of :func:`series`' output, by row
ST_HIGH, ST_LOW = 0, 1
ST_FIN = 2  # four rows: the fins' St as drawn
ST_ABOVE = 6  # markers at 1 where a fin's St is above 1
TRACKED = 7  # three charts of four rows: value, target, lower pin, upper pin
POWER = 19  # seven rows of the power drawn: per fin (four), total, running mean, energy per metre
TOTAL = 4  # the total's place among a power's seven
SHAFT = 26  # the mechanical estimate's total beside the battery's
ROWS = 27
#: the power the power chart draws (:func:`series`' result): the encoders' mechanical
#: estimate, or the battery's (the fin drives' electrical input)
MECHANICAL, ELECTRICAL = 0, 1


def window_rows(count: int, n: int, max_points: int) -> tuple[int, int, int]:
    """(the last rows taken, the rows shown, the decimation step) for the last ``n`` of
    ``count`` rows, at most ``max_points`` of them shown: every step-th row counted back
    from the newest (the newest is always shown)."""
    n = max(0, min(int(n), count))
    step = math.ceil(n / max_points) if 0 < max_points < n else 1
    return n, (n - 1) // step + 1 if n else 0, step


@njit(cache=True, nogil=True)
def _value(x, values_max):
    """``x`` as float32: beyond its range the largest finite value of the sign; NaN stays NaN."""
    return np.float32(x if x != x else min(max(x, -values_max), values_max))


@njit(cache=True, nogil=True)
def series(data, next_row, n, step, st_cols, armed_col, speed_col, tracked_cols, spans, power_cols,
           corridor_lo, corridor_hi, st_min_speed, st_hidden, values_max, t_out, v_out):
    """Fill ``t_out`` (m,) float64 and ``v_out`` (ROWS, m) float32 from the ring ``data``
    (capacity, columns; column 0 the time), whose next row to write is ``next_row``, for
    the window of the last ``n`` rows decimated by ``step`` (:func:`window_rows`).
    ``power_cols`` (2, 7): the columns of the power of :data:`MECHANICAL` and of
    :data:`ELECTRICAL`, each as the :data:`POWER` rows. Returns the power drawn: ELECTRICAL
    when the window has a finite electrical total, else MECHANICAL."""
    cap = data.shape[0]
    ncol = data.shape[1]
    m = t_out.shape[0]
    rows = np.empty((m, ncol))
    for j in range(m):
        rows[j, :] = data[(next_row - n + (n - 1 - (m - 1 - j) * step)) % cap]
    # every value column: a non-finite value is the last finite one before it (the first
    # finite one before that; NaN, drawn as nothing, when there is none)
    for c in range(1, ncol):
        first = math.nan
        for j in range(m):
            if math.isfinite(rows[j, c]):
                first = rows[j, c]
                break
        last = first
        for j in range(m):
            x = rows[j, c]
            if math.isfinite(x):
                last = x
            else:
                rows[j, c] = last
    for j in range(m):
        t_out[j] = rows[j, 0]
    # the St chart: the corridor, each fin's St (hidden below the axis while disarmed, still
    # or unknown; capped at 1), markers at 1 where one is above 1
    hi32 = np.float32(corridor_hi)
    lo32 = np.float32(corridor_lo)
    for j in range(m):
        v_out[ST_HIGH, j] = hi32
        v_out[ST_LOW, j] = lo32
        hide_all = not (rows[j, armed_col] > 0.5) or not (abs(rows[j, speed_col]) >= st_min_speed)
        above = st_hidden
        for f in range(st_cols.shape[0]):
            st = rows[j, st_cols[f]]
            if hide_all or not math.isfinite(st):
                v_out[ST_FIN + f, j] = st_hidden
            else:
                v_out[ST_FIN + f, j] = min(st, 1.0)
                if st > 1.0:
                    above = 1.0
        v_out[ST_ABOVE, j] = above
    # the tracking charts: value and target, and two constant pins at least the chart's
    # span apart around the middle of both (a value beyond float32's range is its largest)
    for k in range(tracked_cols.shape[0]):
        lo = np.inf
        hi = -np.inf
        for i in range(2):
            r = TRACKED + 4 * k + i
            c = tracked_cols[k, i]
            for j in range(m):
                x = _value(rows[j, c], values_max)
                v_out[r, j] = x
                if math.isfinite(x):
                    lo = min(lo, np.float64(x))
                    hi = max(hi, np.float64(x))
        mid = 0.0
        if lo <= hi:
            mid = 0.5 * lo + 0.5 * hi  # halves first: no overflow
        half = 0.5 * spans[k]
        pin_lo = np.float32(mid - half)
        pin_hi = np.float32(mid + half)
        for j in range(m):
            v_out[TRACKED + 4 * k + 2, j] = pin_lo
            v_out[TRACKED + 4 * k + 3, j] = pin_hi
    # the power chart: the battery's where the window has its total (every row's, filled,
    # or none), the estimate's total beside it; else the estimate's, with nothing beside it
    source = ELECTRICAL if m > 0 and math.isfinite(rows[0, power_cols[ELECTRICAL, TOTAL]]) else MECHANICAL
    for i in range(power_cols.shape[1]):
        c = power_cols[source, i]
        for j in range(m):
            v_out[POWER + i, j] = _value(rows[j, c], values_max)
    c = power_cols[MECHANICAL, TOTAL]
    for j in range(m):
        v_out[SHAFT, j] = _value(rows[j, c] if source == ELECTRICAL else math.nan, values_max)
    return source

