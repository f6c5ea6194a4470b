"""Watching strokes end: the executor's per-sample work, compiled, over all fins at once.

The executor (:mod:`ucat_console.control.executor`, paper Algorithm 2) decides from encoder
feedback when a fin's stroke is over. That decision runs on every feedback sample of every
fin (100 Hz x 4), so it is a numba kernel (``cache=True``) over a :class:`StrokeWatches`
table with one row per fin; the executor's plan and stroke sequencing, which acts a few
times a second, stays Python. Per fin (row)::

    feed:   a = (w_fb - w_prev) / (t_fb - t_prev)      (rate change between samples)
            armed once a sample taken after the send shows the fin moving in the stroke
            direction faster than w_th
    check:  w_pred = w_fb + a (t_now - t_fb)
            stopped  when armed, the sample is after the send, min_stroke_time has passed
                     and s * w_pred < w_th (|w_pred| when the direction is unknown)
            timeout  when t_now >= t_start + max(timeout_min, timeout_factor * planned)

A row holds numbers only; "none yet" is NaN (no feedback, no target, no angle). Rows are
owned by one executor at a time: :meth:`StrokeWatches.clear` gives an executor fresh rows
when it takes its fins over.

:func:`feedback_kernel` is the loop's per-sample call: the feedback of several fins taken at
one time, fed in the order given, each followed by the check of every fin of its executor
(``members``), exactly as the executor did fin by fin; it returns at the first fin whose
executor saw a stroke end, so that the executor acts (the next stroke goes out at once)
before the remaining fins are fed.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ucat_console.control.params import ExecutorConfig
from ucat_console.robot.layout import Layout

# the declared layout of a watch's row, and its columns
WATCH_ROW = Layout("a stroke-end watch's row", [
    ("t_fb", 1, "time of the last feedback sample (NaN: none yet)"), ("w_fb", 1, "its rate"),
    ("a", 1, "rate change between the last two samples"), ("theta_fb", 1, "last feedback angle (NaN: none yet)"),
    ("target", 1, "target of the current / last stroke (NaN: none yet)"),
    ("done", 1, "1: the stroke is over (or none was sent)"), ("t_start", 1, "when the stroke was sent"),
    ("direction", 1, "+1 / -1, 0 when unknown"), ("armed", 1, "1: the fin has been seen moving (or need not be)"),
    ("planned", 1, "planned duration (s)"), ("timeout_at", 1, "the stroke is over by then in any case"),
])
W_T_FB, W_W_FB, W_A, W_THETA_FB, W_TARGET, W_DONE, W_T_START, W_DIRECTION, W_ARMED, W_PLANNED, \
    W_TIMEOUT_AT = (WATCH_ROW.at(f) for f in WATCH_ROW.fields)
NW = WATCH_ROW.size

# what a check found
NOTHING = 0
STOPPED = 1
TIMEOUT = 2
#: feedback_kernel's status when a sample is older than the fin's last one
BACKWARDS = -1


@njit(cache=True)
def clear_rows(w: np.ndarray, rows: np.ndarray) -> None:
    """Fresh rows: no feedback, no stroke."""
    for k in range(rows.shape[0]):
        i = rows[k]
        for j in range(NW):
            w[i, j] = 0.0
        w[i, W_T_FB] = math.nan
        w[i, W_THETA_FB] = math.nan
        w[i, W_TARGET] = math.nan
        w[i, W_DONE] = 1.0
        w[i, W_ARMED] = 1.0
        w[i, W_TIMEOUT_AT] = math.inf


@njit(cache=True)
def start_stroke(w: np.ndarray, i: int, t: float, theta_from: float, theta_ref: float, w_ref: float,
                 w_th: float, min_time: float, timeout_min: float, timeout_factor: float) -> None:
    """Row ``i`` starts a stroke to ``theta_ref`` at ``w_ref`` (rad/s) at time ``t``, from
    ``theta_from`` (NaN: from the last target, else the last feedback angle, else unknown)."""
    if math.isnan(theta_from):
        theta_from = w[i, W_TARGET] if not math.isnan(w[i, W_TARGET]) else w[i, W_THETA_FB]
    if math.isnan(theta_from):
        known = False
        length = 0.0
        w[i, W_DIRECTION] = 0.0
        w[i, W_PLANNED] = math.pi / w_ref
    else:
        known = True
        delta = theta_ref - theta_from
        length = abs(delta)
        w[i, W_DIRECTION] = math.copysign(1.0, delta) if delta != 0.0 else 0.0
        w[i, W_PLANNED] = length / w_ref
    short = known and length < w_th * min_time
    w[i, W_ARMED] = 1.0 if (short or w_ref <= w_th) else 0.0
    w[i, W_T_START] = t
    w[i, W_TIMEOUT_AT] = t + max(timeout_min, timeout_factor * w[i, W_PLANNED])
    w[i, W_TARGET] = theta_ref
    w[i, W_DONE] = 0.0


@njit(cache=True)
def feed(w: np.ndarray, i: int, t_fb: float, w_fb: float, theta_fb: float, w_th: float) -> bool:
    """One feedback sample of row ``i`` (``theta_fb`` NaN: no angle); False when it is older
    than the row's last sample (nothing changed)."""
    t_last = w[i, W_T_FB]
    if not math.isnan(t_last):
        if t_fb < t_last:
            return False
        if t_fb == t_last:
            return True  # the same sample again
        w[i, W_A] = (w_fb - w[i, W_W_FB]) / (t_fb - t_last)
    w[i, W_T_FB] = t_fb
    w[i, W_W_FB] = w_fb
    if not math.isnan(theta_fb):
        w[i, W_THETA_FB] = theta_fb
    if w[i, W_DONE] == 0.0 and w[i, W_ARMED] == 0.0 and t_fb >= w[i, W_T_START]:
        d = w[i, W_DIRECTION]
        moving = d * w_fb if d != 0.0 else abs(w_fb)
        if moving > w_th:
            w[i, W_ARMED] = 1.0
    return True


@njit(cache=True)
def check(w: np.ndarray, i: int, t_now: float, predict: bool, w_th: float, min_time: float) -> int:
    """Whether row ``i``'s stroke is over at ``t_now``: NOTHING, STOPPED or TIMEOUT (then the
    row is done)."""
    if w[i, W_DONE] != 0.0:
        return NOTHING
    t_fb = w[i, W_T_FB]
    t_start = w[i, W_T_START]
    if (predict and w[i, W_ARMED] != 0.0 and not math.isnan(t_fb) and t_fb >= t_start
            and t_now - t_start >= min_time):
        w_pred = w[i, W_W_FB] + w[i, W_A] * (t_now - t_fb)
        d = w[i, W_DIRECTION]
        moving = d * w_pred if d != 0.0 else abs(w_pred)
        if moving < w_th:
            w[i, W_DONE] = 1.0
            return STOPPED
    if t_now >= w[i, W_TIMEOUT_AT]:
        w[i, W_DONE] = 1.0
        return TIMEOUT
    return NOTHING


@njit(cache=True)
def check_rows(w: np.ndarray, rows: np.ndarray, t_now: float, predict: bool, w_th: float,
               min_time: float, found: np.ndarray) -> bool:
    """Check every row of ``rows`` (-1 ends the list) into ``found``; True when one ended."""
    any_end = False
    for k in range(rows.shape[0]):
        r = rows[k]
        if r < 0:
            break
        found[k] = check(w, r, t_now, predict, w_th, min_time)
        if found[k] != NOTHING:
            any_end = True
    return any_end


@njit(cache=True)
def feedback_kernel(w: np.ndarray, members: np.ndarray, fins: np.ndarray, t_fb: float,
                    rates: np.ndarray, angles: np.ndarray, t_now: float, start: int,
                    w_th: float, min_time: float, found: np.ndarray) -> int:
    """Feed fins ``fins[start:]`` (rows; their samples ``rates[k]``, ``angles[k]``, taken at
    ``t_fb``), each followed by the check at ``t_now`` of the rows of its executor
    (``members[fin]``, -1 padded). Returns the position in ``fins`` of the first fin whose
    executor saw a stroke end (``found`` then holds the check of each member: NOTHING,
    STOPPED or TIMEOUT), ``fins.shape[0]`` when none did, or ``BACKWARDS - k`` when fin
    ``fins[k]``'s sample is older than its last one."""
    n = fins.shape[0]
    for k in range(start, n):
        f = fins[k]
        if not feed(w, f, t_fb, rates[k], angles[k], w_th):
            return BACKWARDS - k
        if check_rows(w, members[f], t_now, True, w_th, min_time, found):
            return k
    return n


class StrokeWatches:
    """The stroke-end table of some fins (rows ``0..n-1``) with the executor's thresholds."""

    def __init__(self, cfg: ExecutorConfig, n: int) -> None:
        self.cfg = cfg
        self.table = np.empty((n, NW))
        self.w_th = float(cfg.w_threshold)
        self.min_time = float(cfg.min_stroke_time)
        self.timeout_min = float(cfg.stroke_timeout_min)
        self.timeout_factor = float(cfg.stroke_timeout_factor)
        clear_rows(self.table, np.arange(n, dtype=np.int64))

    def clear(self, rows: tuple[int, ...]) -> None:
        clear_rows(self.table, np.asarray(rows, dtype=np.int64))

    def start(self, row: int, t: float, theta_from: float | None, theta_ref: float, w_ref: float) -> None:
        start_stroke(self.table, row, t, math.nan if theta_from is None else theta_from, theta_ref, w_ref,
                     self.w_th, self.min_time, self.timeout_min, self.timeout_factor)

    def feed(self, row: int, t_fb: float, w_fb: float, theta_fb: float | None) -> None:
        """One sample; ValueError when it is older than the row's last one."""
        if not feed(self.table, row, t_fb, w_fb, math.nan if theta_fb is None else theta_fb, self.w_th):
            raise ValueError(f"t_fb: {t_fb!r} is earlier than the last feedback at {self.table[row, W_T_FB]!r}")

    def check(self, row: int, t_now: float, predict: bool) -> int:
        return check(self.table, row, t_now, predict, self.w_th, self.min_time)

    def angle(self, row: int) -> float | None:
        a = float(self.table[row, W_THETA_FB])
        return None if math.isnan(a) else a

    def started(self, row: int) -> float:
        return float(self.table[row, W_T_START])

    def planned(self, row: int) -> float:
        return float(self.table[row, W_PLANNED])

    def done(self, row: int) -> bool:
        return bool(self.table[row, W_DONE] != 0.0)
