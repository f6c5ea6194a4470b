"""Efficiency and tracking figures of a run, from the one telemetry stream (live or a file).

:class:`RunData` collects the messages a run's figures need (``feed(channel, message)``,
in time order, from the live stream or a session file); the functions below compute over
a time window ``[t0, t1]`` on the stream's clock. Nothing here reads a clock or a file.

Definitions (the paper's Table V):

* power: the battery's by default, the fin drives' electrical input (``power/electrical``,
  :data:`ELECTRICAL`); where a window has no electrical readings (a recording made before
  the drives reported, a drive that did not answer) the encoders' mechanical estimate
  (``power``, :data:`MECHANICAL`) with a label saying so (:func:`source_label`). The
  estimate's figures are always beside them (``mech_*``);
* energy: the integral of the total power (trapezoidal rule over its finite samples: a
  reading a drive did not answer is skipped, never counted zero; the cumulative integral is
  interpolated at the window's ends, so windows add up exactly); per fin the same with
  ``per_fin``;
* mean power: energy / the part of the window the power's samples cover (W), per fin and
  total;
* distance: the increase of ``power.distance`` (metres travelled while the fins are driven);
  a drop (the loop restarted its count) counts as a new start, never as negative distance;
* energy per metre: energy / the distance over the same stretch (J/m); cost of transport:
  energy / (mass distance) (J/(kg m)); mean speed: distance / window length;
* tracking errors: mean |error| of ``body/tracking``'s speed, depth and heading errors over
  the samples in the window while the fins are driven (NaN samples skipped);
* St: each stroke's ``fin/<i>/strouhal`` as it starts: St MAE = mean |St - St_opt| and the
  share of strokes inside their corridor ``[st_low, st_high]``, per fin and over all fins;
* opening: mean |d_1 + d_2| of the fin's plans (rad); winding: the fin's net turn over the
  window (rad/min, signed).

Confidence intervals: a bootstrap over cycles. The window is cut at the ends of one fin's
executed cycles (``fin/<i>/cycle``; the fin with the most cycles in the window); each
figure is a ratio of sums over these cycles (energy over distance, |error| sums over
sample counts ...), so a resample of the cycles, with replacement, gives the figure again;
the interval is the resamples' percentile interval. Fewer than two cycles: no interval (NaN).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ucat_console.robot.fins import N_FINS
from ucat_console.robot.hull import MASS
from ucat_console.telemetry import channels as ch
from ucat_console.typedconf import Config, param


@dataclass(frozen=True)
class MetricsConfig(Config):
    """The efficiency figures and their comparison (docs/review.md)."""

    window: float = param(10.0, lo=0.5, hi=3600.0, unit="s",
                          doc="the live robot figures (power, energy per metre, cost of transport, "
                              "tracking) are over this last stretch of time")
    mass: float = param(MASS, lo=0.1, hi=1000.0, unit="kg", doc="mass in the cost of transport")
    resamples: int = param(1000, lo=50, hi=100_000, doc="bootstrap resamples of the cycles")
    confidence: float = param(0.95, lo=0.5, hi=0.999, doc="confidence of the bootstrap intervals")
    seed: int = param(0, lo=0, hi=2**31 - 1, doc="seed of the bootstrap (the same data give the same intervals)")
    speed_bound: float = param(0.02, lo=0.0, hi=1.0, unit="m/s",
                               doc="runs whose mean speed differs more than this are not comparable")
    speed_mae_bound: float = param(0.02, lo=0.0, hi=1.0, unit="m/s",
                                   doc="runs whose speed MAE differs more than this are not comparable")
    depth_mae_bound: float = param(0.05, lo=0.0, hi=10.0, unit="m",
                                   doc="runs whose depth MAE differs more than this are not comparable")
    before: float = param(10.0, lo=1.0, hi=600.0, unit="s",
                          doc="a change's effect: the figures over this long before it")
    after: float = param(10.0, lo=1.0, hi=600.0, unit="s",
                         doc="a change's effect: the figures over this long after it (filled in when it has passed)")


class _Series:
    """Growing columns of floats: ``t`` and named values."""

    def __init__(self, *names: str) -> None:
        self.names = names
        self._rows: list[tuple[float, ...]] = []
        self._cache: NDArray[np.float64] | None = None

    def add(self, *row: float) -> None:
        self._rows.append(row)
        self._cache = None

    def array(self) -> NDArray[np.float64]:
        if self._cache is None:
            self._cache = np.asarray(self._rows, dtype=float).reshape(-1, len(self.names))
        return self._cache

    def col(self, name: str) -> NDArray[np.float64]:
        return self.array()[:, self.names.index(name)]

    def __len__(self) -> int:
        return len(self._rows)

    def drop_before(self, t: float) -> None:
        k = 0
        while k < len(self._rows) and self._rows[k][0] < t:
            k += 1
        if k:
            del self._rows[:k]
            self._cache = None


#: the power the figures are of: the battery's (the fin drives' electrical input) by
#: default, or the encoders' mechanical estimate
ELECTRICAL = "electrical"
MECHANICAL = "mechanical"
LABELS = {ELECTRICAL: "electrical (battery)", MECHANICAL: "mechanical (shaft estimate)"}
#: why a window's figures are the estimate when nothing else is said
NO_ELECTRICAL = "no electrical readings"


def source_label(source: str, why: str = "") -> str:
    """``electrical (battery)``, or ``mechanical (shaft estimate): <why>``."""
    return LABELS[source] + (f": {why}" if why else "")


def default_label(source: str) -> str:
    """The label of a window's own source: the estimate's is the fallback (no electrical readings)."""
    return source_label(source, NO_ELECTRICAL if source == MECHANICAL else "")


#: the channels the table's figures read (no fin states: the winding, a live figure only,
#: is not in the table, and they are the most numerous messages)
TABLE_CHANNELS: tuple[str, ...] = (
    ch.POWER, ch.POWER_ELECTRICAL, ch.BODY_TRACKING, ch.BODY_STATE,
    *(f(i) for f in (ch.fin_strouhal, ch.fin_cycle, ch.fin_plan) for i in range(N_FINS)),
)
#: the channels every figure reads
CHANNELS: tuple[str, ...] = (*TABLE_CHANNELS, *(ch.fin_state(i) for i in range(N_FINS)))


@dataclass
class RunData:
    """The messages of one run that its figures need, as columns (see the module docstring)."""

    power: _Series = field(default_factory=lambda: _Series("t", "total", "p0", "p1", "p2", "p3", "distance"))
    electrical: _Series = field(default_factory=lambda: _Series("t", "total", "p0", "p1", "p2", "p3"))
    tracking: _Series = field(default_factory=lambda: _Series("t", "driving", "speed", "depth", "heading"))
    speed: _Series = field(default_factory=lambda: _Series("t", "u", "depth"))
    strokes: list[_Series] = field(default_factory=lambda: [
        _Series("t", "st", "low", "high", "opt", "stroke") for _ in range(N_FINS)])
    cycles: list[_Series] = field(default_factory=lambda: [_Series("t", "duration") for _ in range(N_FINS)])
    plans: list[_Series] = field(default_factory=lambda: [_Series("t", "opening") for _ in range(N_FINS)])
    angles: list[_Series] = field(default_factory=lambda: [_Series("t", "angle") for _ in range(N_FINS)])

    def feed(self, channel: str, m: Any) -> None:
        """Take one message (any channel; those not needed are ignored)."""
        if channel == ch.POWER:
            self.power.add(m.t, m.total, *m.per_fin, m.distance)
        elif channel == ch.POWER_ELECTRICAL:
            self.electrical.add(m.t, m.total, *m.per_fin)
        elif channel == ch.BODY_TRACKING:
            self.tracking.add(m.t, float(m.driving), m.speed_error, m.depth_error, m.heading_error)
        elif channel == ch.BODY_STATE:
            self.speed.add(m.t, m.velocity[0], m.depth)
        elif channel.startswith("fin/"):
            fin = getattr(m, "fin", -1)
            if not 0 <= fin < N_FINS:
                return
            kind = channel.rsplit("/", 1)[-1]
            if kind == "strouhal":
                self.strokes[fin].add(m.t, m.st, m.st_low, m.st_high, m.st_opt, m.stroke)
            elif kind == "cycle":
                self.cycles[fin].add(m.t, m.duration)
            elif kind == "plan":
                self.plans[fin].add(m.t, abs(m.u[0] + m.u[1]))
            elif kind == "state":
                self.angles[fin].add(m.t, m.angle)

    def series(self) -> list[_Series]:
        return [self.power, self.electrical, self.tracking, self.speed,
                *self.strokes, *self.cycles, *self.plans, *self.angles]

    def drop_before(self, t: float) -> None:
        """Forget what is older than ``t`` (a live view keeps only its window)."""
        for s in self.series():
            s.drop_before(t)

    @property
    def end(self) -> float:
        ts = [s.array()[-1, 0] for s in self.series() if len(s)]
        return max(ts) if ts else math.nan

    @property
    def start(self) -> float:
        ts = [s.array()[0, 0] for s in self.series() if len(s)]
        return min(ts) if ts else math.nan


# ---- live figures --------------------------------------------------------------------------------


@dataclass(frozen=True)
class Stroke:
    st: float
    low: float
    high: float

    @property
    def in_corridor(self) -> bool:
        return self.low <= self.st <= self.high


@dataclass(frozen=True)
class FinNow:
    """One fin's figures now: its latest two strokes (a cycle's both strokes, latest last),
    its mean power over the window (of the robot's ``source``), the opening of its latest
    plan and its winding."""

    fin: int
    strokes: tuple[Stroke, ...]
    power: float
    opening: float
    winding: float


@dataclass(frozen=True)
class RobotNow:
    """The robot's figures over the window: power, energy per metre and cost of transport of
    ``source`` (its label ``source_label``), the mechanical estimate's beside them."""

    window: float
    power: float
    energy_per_metre: float
    cost_of_transport: float
    speed_mae: float
    depth_mae: float
    heading_mae: float
    source: str = MECHANICAL
    source_label: str = ""
    mech_power: float = math.nan
    mech_energy_per_metre: float = math.nan
    mech_cost_of_transport: float = math.nan


def _cumulative(t: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.float64]:
    """The trapezoidal integral of y over t from the first sample (NaN values count as 0)."""
    y = np.nan_to_num(y, nan=0.0, posinf=0.0, neginf=0.0)
    out = np.zeros(t.size)
    if t.size > 1:
        out[1:] = np.cumsum(0.5 * (y[1:] + y[:-1]) * np.diff(t))
    return out


def _restarting(c: NDArray[np.float64]) -> NDArray[np.float64]:
    """A cumulative count made monotone: after a drop (a restart) it counts on from there."""
    c = np.nan_to_num(c, nan=0.0)
    if c.size == 0:
        return c
    d = np.diff(c, prepend=c[0])
    d = np.where(d < 0.0, c, d)  # a drop: the new count is what came since the restart
    d[0] = 0.0
    return np.cumsum(d)


def _at(t: NDArray[np.float64], c: NDArray[np.float64], x: NDArray[np.float64] | float) -> Any:
    return np.interp(x, t, c) if t.size else np.zeros_like(np.asarray(x, dtype=float))


def _finite_span(s: _Series) -> tuple[float, float] | None:
    """The first and last time of a power series' finite totals (None: fewer than two)."""
    a = s.array()
    t = a[np.isfinite(a[:, 1]), 0] if len(s) else np.empty(0)
    return (float(t[0]), float(t[-1])) if t.size > 1 else None


def power_source(data: RunData, t0: float, t1: float) -> str:
    """:data:`ELECTRICAL` when the electrical readings cover some of ``[t0, t1]``, else
    :data:`MECHANICAL`."""
    span = _finite_span(data.electrical)
    return ELECTRICAL if span is not None and min(t1, span[1]) > max(t0, span[0]) else MECHANICAL


def _energy(t: NDArray[np.float64], y: NDArray[np.float64],
            edges: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Per interval of ``edges``: the energy of power ``y`` over its finite samples, the time
    they cover, and the edges clipped to their span (no samples: NaN energy, no time)."""
    ok = np.isfinite(y)
    t, y = t[ok], y[ok]
    if t.size < 2:
        return np.full(edges.size - 1, math.nan), np.zeros(edges.size - 1), edges
    span = np.clip(edges, t[0], t[-1])
    return np.diff(_at(t, _cumulative(t, y), edges)), np.diff(span), span


class _Sums:
    """Each figure's numerator and denominator per interval (cycle) of a window; the power
    figures of ``source`` (:data:`ELECTRICAL` or :data:`MECHANICAL`), the mechanical
    estimate's as ``mech_*``."""

    def __init__(self, data: RunData, edges: NDArray[np.float64], mass: float, closed: bool = True,
                 source: str = ELECTRICAL) -> None:
        if source not in LABELS:
            raise ValueError(f"power source {source!r} is not one of {', '.join(LABELS)}")
        self.edges = edges
        self.closed = closed
        n = edges.size - 1
        p = data.power.array()
        t = p[:, 0]
        distance = _restarting(p[:, 6])
        # within the power samples' span only: no extrapolated zero power outside it
        covered = np.diff(np.clip(edges, t[0], t[-1])) if t.size else np.zeros(n)
        self.num: dict[str, NDArray[np.float64]] = {}
        self.den: dict[str, NDArray[np.float64]] = {}
        self._set("speed", np.diff(_at(t, distance, edges)), covered)
        self.duration = np.diff(edges)
        for prefix, src in (("", source), ("mech_", MECHANICAL)):
            a = (data.electrical if src == ELECTRICAL else data.power).array()
            e, cover, span = _energy(a[:, 0], a[:, 1], edges)
            d = np.diff(_at(t, distance, span))  # the distance over the stretch the power covers
            self._set(f"{prefix}power", e, cover)
            self._set(f"{prefix}energy_per_metre", e, d)
            self._set(f"{prefix}cost_of_transport", e / mass, d)
            for i in range(N_FINS):
                self._set(f"{prefix}power_{i}", *_energy(a[:, 0], a[:, 2 + i], edges)[:2])
        tr = data.tracking.array()
        for k, name in ((2, "speed_mae"), (3, "depth_mae"), (4, "heading_mae")):
            ok = (tr[:, 1] != 0.0) & np.isfinite(tr[:, k])
            self._binned(name, tr[ok, 0], np.abs(tr[ok, k]))
        all_st: list[tuple[NDArray[np.float64], ...]] = []
        for i in range(N_FINS):
            s = data.strokes[i].array()
            ok = np.isfinite(s[:, 1])
            s = s[ok]
            err = np.abs(s[:, 1] - s[:, 4])
            inside = ((s[:, 1] >= s[:, 2]) & (s[:, 1] <= s[:, 3])).astype(float)
            self._binned(f"st_mae_{i}", s[:, 0], err)
            self._binned(f"st_in_{i}", s[:, 0], inside)
            all_st.append((s[:, 0], err, inside))
        ts = np.concatenate([a[0] for a in all_st])
        self._binned("st_mae", ts, np.concatenate([a[1] for a in all_st]))
        self._binned("st_in", ts, np.concatenate([a[2] for a in all_st]))

    def _set(self, name: str, num: NDArray[np.float64], den: NDArray[np.float64]) -> None:
        self.num[name], self.den[name] = np.asarray(num, float), np.asarray(den, float)

    def _binned(self, name: str, t: NDArray[np.float64], v: NDArray[np.float64]) -> None:
        n = self.edges.size - 1
        k = np.searchsorted(self.edges, t, side="right") - 1
        if self.closed:  # the window's end belongs to its last interval
            k[t == self.edges[-1]] = n - 1
        ok = (k >= 0) & (k < n)
        self._set(name, np.bincount(k[ok], weights=v[ok], minlength=n),
                  np.bincount(k[ok], minlength=n).astype(float))

    def value(self, name: str) -> float:
        den = self.den[name].sum()
        return float(self.num[name].sum() / den) if den > 0.0 else math.nan


def _window_edges(data: RunData, t0: float, t1: float) -> tuple[NDArray[np.float64], int]:
    """The window cut at one fin's cycle ends (the fin with most of them), and how many
    whole cycles it holds (the first and last pieces are the window's remainders)."""
    best = np.empty(0)
    for c in data.cycles:
        ends = c.col("t") if len(c) else np.empty(0)
        ends = ends[(ends > t0) & (ends < t1)]
        if ends.size > best.size:
            best = ends
    return np.concatenate(([t0], best, [t1])), max(best.size - 1, 0)


def window_figures(data: RunData, t0: float, t1: float, mass: float, closed: bool = True,
                   source: str | None = None) -> dict[str, float]:
    """Every figure of :data:`FIGURES` over ``[t0, t1]`` (no intervals), the power figures of
    ``source`` (None: :func:`power_source`); NaN where none."""
    if len(data.power) == 0:
        return {k: math.nan for k in FIGURES}
    s = _Sums(data, np.array([t0, t1]), mass, closed, source or power_source(data, t0, t1))
    return {k: s.value(k) * (100.0 if k in _PERCENT else 1.0) for k in FIGURES}


def fin_energies(data: RunData, t0: float, t1: float, source: str | None = None) -> tuple[float, ...]:
    """Each fin's energy over ``[t0, t1]`` (J; the energy of the module docstring, of
    ``source``'s power, None: :func:`power_source`); NaN for a fin without samples there."""
    source = source or power_source(data, t0, t1)
    if source not in LABELS:
        raise ValueError(f"power source {source!r} is not one of {', '.join(LABELS)}")
    a = (data.electrical if source == ELECTRICAL else data.power).array()
    edges = np.array([t0, t1])
    return tuple(float(_energy(a[:, 0], a[:, 2 + i], edges)[0][0]) for i in range(N_FINS))


def robot_now(data: RunData, t1: float, cfg: MetricsConfig) -> RobotNow:
    """The robot's figures over ``[t1 - cfg.window, t1]``, of the battery's power where
    there are electrical readings, else of the estimate, labelled so."""
    t0 = t1 - cfg.window
    if len(data.power) == 0:
        nan = math.nan
        return RobotNow(cfg.window, nan, nan, nan, nan, nan, nan)
    source = power_source(data, t0, t1)
    s = _Sums(data, np.array([t0, t1]), cfg.mass, source=source)
    return RobotNow(cfg.window, s.value("power"), s.value("energy_per_metre"), s.value("cost_of_transport"),
                    s.value("speed_mae"), s.value("depth_mae"), s.value("heading_mae"), source,
                    default_label(source), s.value("mech_power"), s.value("mech_energy_per_metre"),
                    s.value("mech_cost_of_transport"))


def fins_now(data: RunData, t1: float, cfg: MetricsConfig) -> list[FinNow]:
    """Each fin's figures now (see :class:`FinNow`); its power over ``cfg.window``, of the
    same source as :func:`robot_now`'s."""
    t0 = t1 - cfg.window
    s = _Sums(data, np.array([t0, t1]), cfg.mass, source=power_source(data, t0, t1)) if len(data.power) else None
    out = []
    for i in range(N_FINS):
        st = data.strokes[i].array()
        st = st[st[:, 0] <= t1][-2:]
        strokes = tuple(Stroke(float(r[1]), float(r[2]), float(r[3])) for r in st)
        pl = data.plans[i].array()
        pl = pl[pl[:, 0] <= t1]
        ang = data.angles[i].array()
        ang = ang[(ang[:, 0] >= t0) & (ang[:, 0] <= t1)]
        span = ang[-1, 0] - ang[0, 0] if len(ang) > 1 else 0.0
        winding = float((ang[-1, 1] - ang[0, 1]) * 60.0 / span) if span > 0.0 else math.nan
        out.append(FinNow(i, strokes, s.value(f"power_{i}") if s else math.nan,
                          float(pl[-1, 1]) if len(pl) else math.nan, winding))
    return out


# ---- Table V -------------------------------------------------------------------------------------

#: Table V's figures: key -> (heading, unit); per fin: ``power_<i>``, ``st_mae_<i>``, ``st_in_<i>``;
#: the power figures are of the row's source, the ``mech_*`` ones the mechanical estimate's
FIGURES: dict[str, tuple[str, str]] = {
    "power": ("mean power", "W"),
    "energy_per_metre": ("energy per metre", "J/m"),
    "cost_of_transport": ("cost of transport", "J/(kg m)"),
    "mech_power": ("mechanical power (shaft estimate)", "W"),
    "mech_energy_per_metre": ("mechanical energy per metre (shaft estimate)", "J/m"),
    "mech_cost_of_transport": ("mechanical cost of transport (shaft estimate)", "J/(kg m)"),
    "speed": ("mean speed", "m/s"),
    "speed_mae": ("speed MAE", "m/s"),
    "depth_mae": ("depth MAE", "m"),
    "heading_mae": ("heading MAE", "rad"),
    "st_mae": ("St MAE", "1"),
    "st_in": ("St in corridor", "%"),
    **{f"power_{i}": (f"fin {i} power", "W") for i in range(N_FINS)},
    **{f"mech_power_{i}": (f"fin {i} mechanical power (shaft estimate)", "W") for i in range(N_FINS)},
    **{f"st_mae_{i}": (f"fin {i} St MAE", "1") for i in range(N_FINS)},
    **{f"st_in_{i}": (f"fin {i} St in corridor", "%") for i in range(N_FINS)},
}
_PERCENT = {k for k, (_, unit) in FIGURES.items() if unit == "%"}
#: the figures of the row's power source (the rest do not depend on it)
POWER_FIGURES = ("power", "energy_per_metre", "cost_of_transport", *(f"power_{i}" for i in range(N_FINS)))


@dataclass(frozen=True)
class Estimate:
    """A figure and its bootstrap interval (NaN: none)."""

    value: float
    lo: float
    hi: float


@dataclass(frozen=True)
class TableRow:
    """One run's or segment's Table V figures over ``[t0, t1]``; the power figures
    (:data:`POWER_FIGURES`) are of ``source``, labelled ``source_label``."""

    label: str
    t0: float
    t1: float
    cycles: int
    figures: dict[str, Estimate]
    not_comparable: str = ""  # why it is not comparable with the reference row ("" when it is)
    source: str = MECHANICAL
    source_label: str = ""


def table_row(data: RunData, t0: float, t1: float, cfg: MetricsConfig, label: str = "",
              closed: bool = True, source: str | None = None, source_why: str = "") -> TableRow:
    """Table V's figures of ``[t0, t1]`` (``closed`` False: ``[t0, t1)``, so that a stroke
    or sample at a segment's end counts in the next segment only) with bootstrap intervals
    over cycles; the power figures of ``source``, ``source_why`` saying why it is the
    estimate (None: :func:`power_source`, labelled by :func:`default_label`)."""
    if not t1 > t0:
        raise ValueError(f"{label or 'window'}: empty time window [{t0:g}, {t1:g}]")
    if len(data.power) == 0:
        raise ValueError(f"{label or 'window'}: no power messages: its efficiency cannot be computed")
    if source is None:
        source = power_source(data, t0, t1)
        source_why = NO_ELECTRICAL if source == MECHANICAL else ""
    edges, cycles = _window_edges(data, t0, t1)
    s = _Sums(data, edges, cfg.mass, closed, source)
    # the bootstrap resamples the whole cycles (the remainders at the window's ends stay in)
    inner = np.arange(1, edges.size - 2)
    outer = np.setdiff1d(np.arange(edges.size - 1), inner)
    rng = np.random.default_rng(cfg.seed)
    pick = rng.integers(0, inner.size, size=(cfg.resamples, inner.size)) if inner.size >= 2 else None
    alpha = 0.5 * (1.0 - cfg.confidence)
    figures = {}
    for name in FIGURES:
        scale = 100.0 if name in _PERCENT else 1.0
        v = s.value(name) * scale
        lo = hi = math.nan
        if pick is not None:
            num, den = s.num[name], s.den[name]
            fixed_n, fixed_d = num[outer].sum(), den[outer].sum()
            rn = num[inner][pick].sum(axis=1) + fixed_n
            rd = den[inner][pick].sum(axis=1) + fixed_d
            with np.errstate(invalid="ignore", divide="ignore"):
                r = rn / rd * scale
            r = r[np.isfinite(r)]
            if r.size:
                lo, hi = (float(x) for x in np.quantile(r, [alpha, 1.0 - alpha]))
        figures[name] = Estimate(v, lo, hi)
    return TableRow(label, t0, t1, cycles, figures, source=source, source_label=source_label(source, source_why))


def comparable(row: TableRow, reference: TableRow, cfg: MetricsConfig) -> str:
    """Why ``row`` is not comparable with ``reference`` (its tracking differs by more than
    the configured bounds), or "" when it is."""
    why = []
    for key, bound, unit in (("speed", cfg.speed_bound, "m/s"), ("speed_mae", cfg.speed_mae_bound, "m/s"),
                             ("depth_mae", cfg.depth_mae_bound, "m")):
        a, b = row.figures[key].value, reference.figures[key].value
        if math.isfinite(a) and math.isfinite(b) and abs(a - b) > bound:
            why.append(f"{FIGURES[key][0]} differs by {abs(a - b):.3g} {unit} (> {bound:g})")
    return "; ".join(why)


def flag_rows(rows: list[TableRow], cfg: MetricsConfig) -> list[TableRow]:
    """The rows with ``not_comparable`` set against the first (the reference)."""
    if not rows:
        return rows
    return [rows[0]] + [replace(r, not_comparable=comparable(r, rows[0], cfg)) for r in rows[1:]]
