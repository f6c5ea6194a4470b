"""A figure's trend over the run library's sessions: CSV, a summary per group, and a PNG
(matplotlib, the Agg backend as ``sessions compare``'s; only where matplotlib is installed,
the ``experiments`` extra).

The points are :class:`~ucat_console.backend.sessions.library.TrendPoint`: one session's
value and its group (its day, or a configuration key's value).
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

from ucat_console.backend.sessions.library import TrendPoint


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
