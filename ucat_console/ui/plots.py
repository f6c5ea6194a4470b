"""Live plots: a stream subscriber fills fixed-size ring buffers; uPlot charts show a window.

:class:`PlotFeeder` subscribes to the telemetry stream and keeps only the latest value of
each plotted quantity (O(1) per message, whatever the rate). At each refresh the UI thread
calls :meth:`PlotFeeder.sample`, which appends one row (time, values) to a
:class:`RingBuffer` of fixed capacity (the longest history window times the refresh
rate). :class:`LivePlots` then sends the rows of the chosen history window, decimated to
at most ``max_plot_points`` per series: the size of a plot update is bounded by the
configuration, never by the length of the session. A value not known at a row (NaN, or
not finite) is drawn as the last known one before it (uPlot takes NaN for data, not for a
gap), and a value not known anywhere in the window is drawn as nothing, never as 0; the
series are computed in one compiled pass (:mod:`ucat_console.ui.plot_series`).

Charts (one shared time axis labelled in seconds: of stream time live, from the session's start
(:attr:`PlotFeeder.origin`) in review; synchronised cursors; no line until there are rows):

* Strouhal number of each fin's last plan on a fixed 0-1 axis with the optimal corridor
  filled; a value above 1 is drawn at 1 and marked with a point; no St is drawn while
  the robot is disarmed or slower than :data:`ST_MIN_SPEED` (St = f A / U means nothing
  there): those values are put below the axis;
* depth and its target; forward velocity and its target; yaw rate and its target; each
  axis spans at least :data:`MIN_SPAN` (an invisible pair of points keeps it from
  zooming 2 mm of depth noise up to the whole chart);
* power per fin and in total, with the running mean of the total, and the energy per
  metre travelled on the right-hand axis of the same chart (second, so that it is in view
  at 1280x800). The power is the battery's (``power/electrical``, the fin drives'
  electrical input), as in the efficiency figures (:mod:`ucat_console.backend.review.metrics`),
  with the total of the encoders' mechanical estimate (``power``) dotted beside it; a
  window without an electrical total (a recording made before the drives reported, a drive
  that does not answer: NaN) draws the estimate's instead, and nothing beside it. The
  chart's title names the power drawn (:func:`power_title`). The estimate's running mean
  and energy per metre are the control loop's (``Power``); the battery's are
  :class:`PlotFeeder`'s (:class:`BatteryMean`) over the readings it was given: live since
  the view started, in review since the session's start, or since the history window
  before a jump;
* on every chart, each change (mode, tuning and formulation, setpoints, marker: the events
  of :data:`MARK_CODES`) as a pink spike at its time (:func:`change_marks`);
* in review, the playhead: a black spike at the playback position (:func:`playhead_marks`).
"""

from __future__ import annotations

import collections
import contextlib
import math
import threading
from typing import Any, Callable, Iterator, Sequence

import numpy as np

from ucat_console.backend.review.metrics import ELECTRICAL, LABELS, MECHANICAL, default_label
from ucat_console.robot import look
from ucat_console.robot.look import hex_colour
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.messages import BodyState, ElectricalPower, FinPlan, Power, Setpoints, Status
from ucat_console.ui import plot_series as ps
from ucat_console.ui.plot_series import window_rows
from ucat_console.ui.viser_compat import set_plot_data

N_FINS = ch.N_FINS
#: below this forward speed (m/s) no Strouhal number is shown
ST_MIN_SPEED = 0.02
#: where a hidden St is put (below the fixed 0-1 axis: not drawn)
ST_HIDDEN = -1.0
#: the smallest span of each tracking chart's value axis
MIN_SPAN = {"depth": 0.2, "velocity": 0.1, "yaw_rate": 0.1}

#: the columns of a row
COLUMNS: tuple[str, ...] = (
    "t",
    *(f"st{i}" for i in range(N_FINS)),
    "depth", "depth_sp",
    "velocity", "velocity_sp",
    "yaw_rate", "yaw_rate_sp",
    *(f"p{i}" for i in range(N_FINS)),
    "p_total", "p_mean",
    "energy_per_metre",
    *(f"e{i}" for i in range(N_FINS)),
    "e_total", "e_mean",
    "e_energy_per_metre",
    "armed",
)
COL = {name: i for i, name in enumerate(COLUMNS)}
#: the channels the feeder reads
CHANNELS = (ch.BODY_STATE, ch.SETPOINTS, ch.POWER, ch.POWER_ELECTRICAL, ch.STATUS, ch.EVENTS,
            *(ch.fin_plan(i) for i in range(N_FINS)))
#: the events marked on every chart's time axis: mode, tuning (the formulation too),
#: setpoint changes and markers
MARK_CODES = frozenset({"mode", "tuning", "setpoints", "marker"})
MARK_COLOUR = "#e377c2"
#: the review plots' playhead (the playback position)
PLAYHEAD_COLOUR = "#000000"
_MARKS_KEPT = 500

#: the type of the values sent to the pages (the time axis is float64)
VALUES = np.float32
_VALUES_MAX = float(np.finfo(VALUES).max)
FIN_COLOURS = tuple(hex_colour(c) for c in look.FIN_COLOURS)  # each fin its 3-D blade's colour
_PLANS = {ch.fin_plan(i): i for i in range(N_FINS)}


class RingBuffer:
    """A fixed number of rows of floats; the oldest row is overwritten when full."""

    def __init__(self, capacity: int, columns: int) -> None:
        if capacity < 1 or columns < 1:
            raise ValueError(f"capacity and columns must be >= 1, got {capacity}, {columns}")
        self._data = np.full((capacity, columns), np.nan)
        self._next = 0
        self._count = 0
        self._lock = threading.Lock()

    @property
    def capacity(self) -> int:
        return self._data.shape[0]

    def __len__(self) -> int:
        return self._count

    def append(self, row: Sequence[float]) -> None:
        with self._lock:
            self._data[self._next] = row
            self._next = (self._next + 1) % self._data.shape[0]
            self._count = min(self._count + 1, self._data.shape[0])

    @contextlib.contextmanager
    def locked(self) -> Iterator[tuple[np.ndarray, int, int]]:
        """(the rows' array, the index of the next row written, the rows held), held still."""
        with self._lock:
            yield self._data, self._next, self._count

    def last(self, n: int, max_points: int | None = None) -> np.ndarray:
        """The last ``n`` rows, oldest first (a copy), keeping at most ``max_points`` of
        them: every k-th row counted back from the newest, so the newest is always shown."""
        with self._lock:
            n = max(0, min(int(n), self._count))
            cap = self._data.shape[0]
            idx = (self._next - n + np.arange(n)) % cap
            if max_points is not None and n > max_points > 0:
                step = math.ceil(n / max_points)
                idx = idx[::-1][::step][::-1]
            return self._data[idx].copy()


class BatteryMean:
    """The battery's running mean and energy per metre from its readings, as the loop's
    :class:`~ucat_console.telemetry.messages.Power` gives the estimate's: its energy while
    armed (trapezoidal between consecutive finite totals of one armed stretch; a reading a
    drive did not answer, NaN, is skipped, never counted zero), over that time, and over the
    distance the loop counted meanwhile (a drop of the count is the loop's new start, as in
    the efficiency figures: the new count is what came since)."""

    def __init__(self) -> None:
        self.energy = self.time = 0.0  # J, s: while armed
        self.moved_energy = self.distance = 0.0  # J, m: over the stretches whose distance is known
        self._last: tuple[float, float, float] | None = None  # t, total, distance of the last finite reading
        self._armed = False  # armed since that reading

    def add(self, t: float, total: float, distance: float, armed: bool) -> None:
        """A reading of the total at ``t`` (W), the loop's distance count then (m; NaN:
        none yet), whether the fins are driven (armed)."""
        last = self._last
        if not math.isfinite(total) or not (last is None or t > last[0]):
            return
        self._last = (t, total, distance)
        counted, self._armed = last is not None and self._armed and armed, armed
        if not counted:
            return
        energy = 0.5 * (total + last[1]) * (t - last[0])
        self.energy += energy
        self.time += t - last[0]
        moved = distance - last[2]
        if moved < 0.0:  # the loop started its count again
            moved = distance
        if math.isfinite(moved):
            self.moved_energy += energy
            self.distance += moved

    def disarmed(self) -> None:
        """The fins stopped being driven: the time until the next reading after they are
        armed again is not counted (however many readings were NaN in between)."""
        self._armed = False

    @property
    def mean(self) -> float:
        """W; NaN before two finite readings while armed."""
        return self.energy / self.time if self.time > 0.0 else math.nan

    @property
    def energy_per_metre(self) -> float:
        """J/m; NaN until the robot has moved."""
        return self.moved_energy / self.distance if self.distance > 0.0 else math.nan


class PlotFeeder:
    """Stream subscriber holding the latest plotted values; rows into a ring buffer."""

    def __init__(self, capacity: int) -> None:
        self.buffer = RingBuffer(capacity, len(COLUMNS))
        #: the stream time shown as 0 (a review: the session's start; rows and changes are
        #: times from it)
        self.origin = 0.0
        self._latest = [math.nan] * len(COLUMNS)
        self._t_last_row = -math.inf
        self.battery = BatteryMean()
        self._distance = math.nan  # the loop's distance count (Power)
        #: the times of the changes marked on the charts (MARK_CODES), oldest first
        self.changes: collections.deque[float] = collections.deque(maxlen=_MARKS_KEPT)

    @property
    def latest(self) -> list[float]:
        return list(self._latest)

    def on_message(self, channel: str, msg: Any) -> None:
        if channel == ch.EVENTS:
            if msg.code in MARK_CODES and math.isfinite(msg.t):
                self.changes.append(float(msg.t) - self.origin)
            return
        row = self._latest
        fin = _PLANS.get(channel)
        if fin is not None:
            plan: FinPlan = msg
            row[1 + fin] = plan.st
            return
        if channel == ch.BODY_STATE:
            b: BodyState = msg
            row[0] = b.t - self.origin
            row[COL["depth"]] = b.depth
            row[COL["velocity"]] = b.velocity[0]
            row[COL["yaw_rate"]] = b.rates[2]
        elif channel == ch.SETPOINTS:
            s: Setpoints = msg
            row[COL["depth_sp"]] = s.depth
            row[COL["velocity_sp"]] = s.velocity
            row[COL["yaw_rate_sp"]] = s.yaw_rate
        elif channel == ch.POWER:
            p: Power = msg
            base = COL["p0"]
            for i in range(N_FINS):
                row[base + i] = p.per_fin[i]
            row[COL["p_total"]] = p.total
            row[COL["p_mean"]] = p.mean_total
            row[COL["energy_per_metre"]] = p.energy_per_metre
            self._distance = p.distance
        elif channel == ch.POWER_ELECTRICAL:
            e: ElectricalPower = msg
            base = COL["e0"]
            for i in range(N_FINS):
                row[base + i] = e.per_fin[i]  # NaN: a drive that did not answer
            row[COL["e_total"]] = e.total
            b = self.battery
            b.add(e.t, e.total, self._distance, row[COL["armed"]] == 1.0)
            row[COL["e_mean"]] = b.mean
            row[COL["e_energy_per_metre"]] = b.energy_per_metre
        elif channel == ch.STATUS:
            st: Status = msg
            row[COL["armed"]] = 1.0 if st.armed else 0.0
            if not st.armed:
                self.battery.disarmed()
        t = msg.t - self.origin
        if t > row[0] or row[0] != row[0]:
            row[0] = t

    def sample(self) -> bool:
        """Append the latest values as one row; False when no time has passed since the last."""
        row = list(self._latest)
        t = row[0]
        if not t > self._t_last_row:  # NaN or not advanced
            return False
        self._t_last_row = t
        self.buffer.append(row)
        return True

    def reset(self) -> None:
        """Forget everything (e.g. a new source starts from t = 0)."""
        self.buffer = RingBuffer(self.buffer.capacity, len(COLUMNS))
        self._latest = [math.nan] * len(COLUMNS)
        self._t_last_row = -math.inf
        self.battery = BatteryMean()
        self._distance = math.nan
        self.changes.clear()


def change_marks(t: np.ndarray, changes: Sequence[float]) -> np.ndarray:
    """The change marks' series on the time axis ``t`` (ascending), on the charts' "mark"
    scale (0 to 1): 1 at the first row at or after each change, -1 (below the chart,
    clipped) elsewhere, so that each change draws as a narrow spike across the chart and
    nothing else shows (uPlot draws NaN neither as a point nor as a gap)."""
    out = np.full(t.shape[0], -1.0, dtype=VALUES)
    if t.shape[0] == 0 or not changes:
        return out
    c = np.asarray(changes, dtype=np.float64)
    c = c[(c >= t[0]) & (c <= t[-1])]
    out[np.searchsorted(t, c)] = 1.0
    return out


def playhead_marks(t: np.ndarray, at: float | None) -> np.ndarray:
    """The playhead's series on the time axis ``t`` (ascending), on the "mark" scale as
    :func:`change_marks`: 1 at the last row at or before ``at`` (a spike there), -1
    elsewhere; nothing when ``at`` is None or before the first row."""
    out = np.full(t.shape[0], -1.0, dtype=VALUES)
    if at is not None and t.shape[0] and t[0] <= at:
        out[int(np.searchsorted(t, at, side="right")) - 1] = 1.0
    return out


def _empty(n: int) -> tuple[np.ndarray, ...]:
    """A chart's data before it has any: the x range 0-1 and no value (NaN draws nothing).
    Never an empty x array: viser's page derives the x range from the data, and an empty
    one gives it a NaN range that it then keeps for good (no lines, no ticks)."""
    return (_EMPTY_X, *(np.full(2, np.nan, dtype=VALUES),) * (n - 1))


def _series(label: str, stroke: str, width: float = 1.5, dash: tuple[float, ...] | None = None) -> dict:
    s: dict[str, Any] = {"label": label, "stroke": stroke, "width": width, "points": {"show": False}}
    if dash:
        s["dash"] = dash
    return s


_X = {"label": "t (s)"}
_X_AXIS = {"label": "t (s)", "size": 30, "labelSize": 14, "labelGap": 0}
_NO_LEGEND = {"show": False}
_SCALES = {"x": {"time": False}, "mark": {"range": [0.0, 1.0], "auto": False}}
_MARK = {"label": "changes", "stroke": MARK_COLOUR, "width": 1.5, "scale": "mark", "points": {"show": False}}
_CURSOR = {"sync": {"key": "ucat"}}
_PLAYHEAD = {"label": "playhead", "stroke": PLAYHEAD_COLOUR, "width": 2.0, "scale": "mark", "points": {"show": False}}
_EMPTY_X = np.array([0.0, 1.0])
_PIN = {"label": "axis span", "stroke": "rgba(0,0,0,0)", "width": 0.5, "points": {"show": False}}


_ST_COLS = np.array([COL[f"st{i}"] for i in range(N_FINS)], dtype=np.int64)
_TRACKED = ("depth", "velocity", "yaw_rate")  # the tracking charts: value and target each
_TRACKED_COLS = np.array([[COL[name], COL[f"{name}_sp"]] for name in _TRACKED], dtype=np.int64)
_TRACKED_SPANS = np.array([MIN_SPAN[name] for name in _TRACKED])
_POWER_COLS = np.zeros((2, N_FINS + 3), dtype=np.int64)  # each power's columns, as plot_series' POWER rows
_POWER_COLS[ps.MECHANICAL] = [*(COL[f"p{i}"] for i in range(N_FINS)), COL["p_total"], COL["p_mean"],
                              COL["energy_per_metre"]]
_POWER_COLS[ps.ELECTRICAL] = [*(COL[f"e{i}"] for i in range(N_FINS)), COL["e_total"], COL["e_mean"],
                              COL["e_energy_per_metre"]]
_SOURCES = {ps.MECHANICAL: MECHANICAL, ps.ELECTRICAL: ELECTRICAL}


def power_title(source: str) -> str:
    """The power chart's title, naming the power it draws by the efficiency figures' labels:
    the battery's, with the estimate's total dotted beside it, or the estimate's, saying why."""
    title = f"Power (W) and energy per metre (J/m): {default_label(source)}"
    return title + (f"; total of the {LABELS[MECHANICAL]} dotted" if source == ELECTRICAL else "")


class LivePlots:
    """The uPlot charts of the live view (server-wide: every page sees the same plots)."""

    def __init__(self, gui: Any, feeder: PlotFeeder, *, rate: float, max_points: int,
                 corridor: Callable[[], tuple[float, float]], height: int = 170,
                 playhead: Callable[[], float | None] | None = None) -> None:
        """``playhead()``: where to draw the playhead (a time on the rows' axis; None: none
        now); without it the charts have no playhead series."""
        self.feeder = feeder
        self.playhead = playhead
        self.rate = float(rate)
        self.max_points = int(max_points)
        self.corridor = corridor
        self.updates = 0
        fins = range(N_FINS)
        head = (_PLAYHEAD,) if playhead is not None else ()
        common = dict(scales=_SCALES, cursor=_CURSOR, height=height)
        st_scales = {**_SCALES, "y": {"range": [0.0, 1.0], "auto": False}}
        above = {"label": "St > 1 (at 1)", "stroke": "rgba(0,0,0,0)", "width": 0.5,
                 "points": {"show": True, "size": 7, "stroke": "#d62728", "fill": "#d62728"}}
        self.st = gui.add_uplot(
            _empty(2 + N_FINS + 3 + len(head)),
            (_X, _series("St high", "#2ca02c", 1.0), _series("St low", "#2ca02c", 1.0),
             *(_series(f"St fin {i}", FIN_COLOURS[i]) for i in fins), above, _MARK, *head),
            bands=({"series": (1, 2), "fill": "rgba(44, 160, 44, 0.28)"},),
            title="St per fin 0-3 (red, blue, green, orange); corridor green; none while disarmed or still; "
                  "changes pink",
            axes=(_X_AXIS, {"label": "St", "size": 40}), cursor=_CURSOR, height=height, scales=st_scales,
            legend=_NO_LEGEND,
        )
        self.depth = gui.add_uplot(
            _empty(6 + len(head)),
            (_X, _series("depth", "#1f77b4"), _series("target", "#555", 1.0, (6, 3)), _PIN, _PIN, _MARK, *head),
            title="Depth (m): measured, target dashed", axes=(_X_AXIS, {"label": "m", "size": 40}),
            legend=_NO_LEGEND, **common,
        )
        self.velocity = gui.add_uplot(
            _empty(6 + len(head)),
            (_X, _series("u", "#d62728"), _series("target", "#555", 1.0, (6, 3)), _PIN, _PIN, _MARK, *head),
            title="Forward velocity (m/s): measured, target dashed", axes=(_X_AXIS, {"label": "m/s", "size": 40}),
            legend=_NO_LEGEND, **common,
        )
        self.yaw_rate = gui.add_uplot(
            _empty(6 + len(head)),
            (_X, _series("r", "#9467bd"), _series("target", "#555", 1.0, (6, 3)), _PIN, _PIN, _MARK, *head),
            title="Yaw rate (rad/s): measured, target dashed", axes=(_X_AXIS, {"label": "rad/s", "size": 40}),
            legend=_NO_LEGEND, **common,
        )
        epm = _series("energy per metre (J/m, right)", "#17becf", 2.0)
        epm["scale"] = "epm"
        #: the power the power chart draws (metrics' ELECTRICAL or MECHANICAL)
        self.source = ELECTRICAL
        self.power = gui.add_uplot(
            _empty(1 + N_FINS + 5 + len(head)),
            (_X, *(_series(f"fin {i}", FIN_COLOURS[i], 1.0) for i in fins),
             _series("total", "#888", 2.0), _series("running mean", "#8c564b", 1.5, (6, 3)), epm,
             _series(f"total, {LABELS[MECHANICAL]}", "#333", 1.5, (1.5, 3)), _MARK, *head),
            title=power_title(self.source),
            axes=(_X_AXIS, {"label": "W", "size": 40},
                  {"scale": "epm", "side": 1, "label": "J/m", "grid": {"show": False}, "size": 40}),
            scales={**_SCALES, "epm": {"auto": True}}, cursor=_CURSOR, height=height,
            legend={"show": True, "live": False},
            order=self.st.order + 1e-3,  # second, in view at 1280x800 with the efficiency figures above
        )
        self.energy = self.power  # one chart: power and energy per metre

    def refresh(self, window: float) -> None:
        """Send the last ``window`` seconds to every page (nothing until there are two rows:
        a chart needs an x range)."""
        got = series_of(self.feeder.buffer, int(math.ceil(window * self.rate)) + 1, self.max_points, self.corridor())
        if got is None:
            return
        # new arrays each time, sent as they are (float32 values: ui.viser_compat.set_plot_data)
        t, v, source = got
        self._show_source(source)
        marks: tuple[np.ndarray, ...] = (change_marks(t, list(self.feeder.changes)),)
        if self.playhead is not None:
            marks += (playhead_marks(t, self.playhead()),)
        set_plot_data(self.st, (t, *v[ps.ST_HIGH:ps.ST_ABOVE + 1], *marks))
        for k, chart in enumerate((self.depth, self.velocity, self.yaw_rate)):
            set_plot_data(chart, (t, *v[ps.TRACKED + 4 * k:ps.TRACKED + 4 * k + 4], *marks))
        set_plot_data(self.power, (t, *v[ps.POWER:ps.ROWS], *marks))
        self.updates += 1

    @property
    def charts(self) -> tuple[Any, ...]:
        return self.st, self.depth, self.velocity, self.yaw_rate, self.power

    def _show_source(self, source: str) -> None:
        """Title the power chart with the power it draws (sent only when that changes)."""
        if source != self.source:
            self.source = source
            self.power.title = power_title(source)

    def clear(self) -> None:
        """Empty charts (a new source, before its first rows)."""
        for chart in self.charts:
            set_plot_data(chart, _empty(len(chart.data)))
        self._show_source(ELECTRICAL)


def series_of(buffer: RingBuffer, n: int, max_points: int,
              corridor: tuple[float, float]) -> tuple[np.ndarray, np.ndarray, str] | None:
    """(the time axis, float64; the value series, float32, by the rows of
    :mod:`~ucat_console.ui.plot_series`; the power the power chart draws, ELECTRICAL or
    MECHANICAL) of the last ``n`` rows of ``buffer``, decimated to ``max_points``; None when
    there are fewer than two rows or no time passed between the first and the last. The
    time axis keeps its resolution over a long run; float32 is ample for the values, and
    half the bytes sent to every page 12 times a second."""
    lo, hi = corridor
    with buffer.locked() as (data, next_row, count):
        n, m, step = window_rows(count, n, max_points)
        if m < 2:
            return None
        t = np.empty(m)
        v = np.empty((ps.ROWS, m), VALUES)
        source = ps.series(data, next_row, n, step, _ST_COLS, COL["armed"], COL["velocity"], _TRACKED_COLS,
                           _TRACKED_SPANS, _POWER_COLS, float(lo), float(hi), ST_MIN_SPEED, ST_HIDDEN, _VALUES_MAX,
                           t, v)
    return (t, v, _SOURCES[source]) if t[-1] > t[0] else None


def warm_up() -> None:
    """Compile (or load) the plots' series (``ucat-console prepare``)."""
    buffer = RingBuffer(4, len(COLUMNS))
    for k in range(4):
        buffer.append([0.1 * k] + [0.0] * (len(COLUMNS) - 1))
    series_of(buffer, 4, 3, (0.2, 0.4))
