"""A figure's trend over the run library's sessions: CSV, a summary per group, a PNG
(matplotlib, the Agg backend as ``sessions compare``'s; only where matplotlib is installed,
the ``experiments`` extra), and the arrays the Review tab's trend chart draws.

The points are :class:`~ucat_console.backend.sessions.library.TrendPoint`: one session's
value and its group (its day, or a configuration key's value), with the figure's interval
where the library keeps one.

The page offers a fixed choice: the figures of :data:`FIGURES` against the axes of
:data:`AXES` (the day, or one of the recorded MPC weights); :func:`check_choice` refuses
anything else a page sends with a message naming it and the choices, before the library is
asked. :func:`chart` turns the points into the chart's x and series (a run without a start,
or without a number for the configuration key, is left out and counted).
"""

from __future__ import annotations

import csv
import importlib.util
import io
import math
import statistics
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from ucat_console.backend.sessions.library import TrendPoint
from ucat_console.backend.sessions.replay import WEIGHT_NAMES

#: the figures the page's trend offers: library field -> what the page calls it
FIGURES: dict[str, str] = {
    "epm": "energy per metre (J/m)",
    "cot": "cost of transport (J/(kg m))",
    "speed_mae": "speed error, mean |e| (m/s)",
    "depth_mae": "depth error, mean |e| (m)",
    "heading_mae": "heading error, mean |e| (rad)",
    "st_mae": "St error, mean |St - St_opt|",
    "st_in": "strokes in the St corridor (%)",
}
#: the axes the page's trend offers: the day, or a recorded MPC weight (its configuration key)
DATE = "date"
AXES: tuple[str, ...] = (DATE, *(f"loop.mpc.{w}" for w in WEIGHT_NAMES))


def check_choice(figure: object, by: object) -> tuple[str, str]:
    """(library field, axis) of a page's choice: ``figure`` a field of :data:`FIGURES` or
    its label, ``by`` one of :data:`AXES`; ValueError naming the one refused."""
    labels = {v: k for k, v in FIGURES.items()}
    if not isinstance(figure, str) or (figure not in FIGURES and figure not in labels):
        raise ValueError(f"trend figure {str(figure)[:60]!r}: not one of " + "; ".join(FIGURES.values()))
    if not isinstance(by, str) or by not in AXES:
        raise ValueError(f"trend axis {str(by)[:60]!r}: not one of " + ", ".join(AXES))
    return labels.get(figure, figure), by


@dataclass(frozen=True)
class Chart:
    """A trend as the page's chart draws it: ``x`` (UNIX s by date, else the key's value)
    ascending, and per point its value, interval (NaN: none) and its group's mean."""

    x: np.ndarray  # float64
    value: np.ndarray  # float32, as each series below
    lo: np.ndarray
    hi: np.ndarray
    mean: np.ndarray
    left_out: int  # points without a place on the axis
    groups: int
    has_interval: bool


def chart(points: Sequence[TrendPoint], by: str) -> Chart:
    """The chart of ``points`` against ``by`` (module docstring)."""
    placed: list[tuple[float, TrendPoint]] = []
    for p in points:
        if by == DATE:
            x = p.start
        else:
            try:
                x = float(p.group)
            except ValueError:
                x = None
        if x is not None and math.isfinite(x) and math.isfinite(p.value):
            placed.append((x, p))
    placed.sort(key=lambda xp: xp[0])
    kept = [p for _, p in placed]
    means = {g.group: g.mean for g in groups(kept)}
    nan = math.nan
    return Chart(
        x=np.array([x for x, _ in placed], dtype=np.float64),
        value=np.array([p.value for p in kept], dtype=np.float32),
        lo=np.array([nan if p.lo is None else p.lo for p in kept], dtype=np.float32),
        hi=np.array([nan if p.hi is None else p.hi for p in kept], dtype=np.float32),
        mean=np.array([means[p.group] for p in kept], dtype=np.float32),
        left_out=len(points) - len(kept), groups=len(means),
        has_interval=any(p.lo is not None or p.hi is not None for p in kept),
    )


@dataclass(frozen=True)
class Group:
    group: str
    n: int
    mean: float
    low: float  # the smallest value
    high: float  # the largest


def groups(points: Sequence[TrendPoint]) -> list[Group]:
    """Each group's count, mean and range, in the order the groups first appear."""
    by: dict[str, list[float]] = {}
    for p in points:
        by.setdefault(p.group, []).append(p.value)
    return [Group(g, len(v), statistics.fmean(v), min(v), max(v)) for g, v in by.items()]


def _numeric(names: Sequence[str]) -> bool:
    try:
        return all(math.isfinite(float(n)) for n in names)
    except ValueError:
        return False


def csv_text(points: Sequence[TrendPoint], name: str, by: str) -> str:
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["session", "start_utc", by, name])
    for p in points:
        start = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(p.start)) if p.start is not None else ""
        w.writerow([p.session_id, start, p.group, repr(p.value)])
    return buf.getvalue()


def can_plot() -> bool:
    return importlib.util.find_spec("matplotlib") is not None


def write_png(points: Sequence[TrendPoint], name: str, unit: str, by: str, path: Path) -> None:
    """Each session a dot at its group, each group's mean a line; the groups in order (by
    value when every group is a number, else as they first appear: by start)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    gs = groups(points)
    order = [g.group for g in gs]
    if _numeric(order):
        order.sort(key=float)
    x_of = {g: k for k, g in enumerate(order)}
    fig, ax = plt.subplots(figsize=(max(6.0, 0.6 * len(order) + 3.0), 4.5))
    try:
        ax.plot([x_of[p.group] for p in points], [p.value for p in points], "o", color="C0", alpha=0.6,
                ms=4, label="a session")
        means = {g.group: g.mean for g in gs}
        ax.plot(range(len(order)), [means[g] for g in order], "-", color="C1", lw=1.5, label="mean")
        ax.set_xticks(range(len(order)), order, rotation=45 if len(order) > 6 else 0, ha="right"
                      if len(order) > 6 else "center", fontsize=8)
        ax.set_xlabel(by)
        ax.set_ylabel(f"{name} ({unit})" if unit else name)
        ax.set_title(f"{name} by {by}: {len(points)} sessions", fontsize=10)
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(path, dpi=100)
    finally:
        plt.close(fig)
