"""The run report's plots (matplotlib's Agg, as ``sessions compare``'s), each a PNG data URI:
the timeline's strip plot, tracking against the references, power (electrical and shaft),
each fin's Strouhal number against its corridor; and the timeline's items they show."""

from __future__ import annotations

import base64
import io
import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from ucat_console.backend.review.metrics import RunData
from ucat_console.robot.fins import N_FINS

#: the most points a plotted line keeps (evenly strided beyond it)
MAX_POINTS = 4000
#: the timeline's kinds, in the strip plot's order (top first)
KINDS = ("mode", "tuning", "setpoints", "armed", "marker", "segment", "seek", "failsafe")


@dataclass(frozen=True)
class TimelineItem:
    t: float  # session s
    kind: str  # one of KINDS
    what: str  # source/code
    message: str
    t1: float | None = None  # a segment's end (session s)

def _stride(*cols: np.ndarray) -> tuple[np.ndarray, ...]:
    n = cols[0].size
    k = max(1, math.ceil(n / MAX_POINTS))
    return tuple(c[::k] for c in cols)


def _png(fig: Any) -> str:
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    try:
        fig.savefig(buf, format="png", dpi=90)
    finally:
        plt.close(fig)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _plt() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _shade(ax: Any, driven: tuple[float, float] | None, origin: float) -> None:
    if driven is not None:
        ax.axvspan(driven[0] - origin, driven[1] - origin, color="#eef3fb", zorder=0)


def timeline_png(items: Sequence[TimelineItem], duration: float) -> str:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(10, 2.8))
    for row, kind in enumerate(KINDS):
        y = len(KINDS) - 1 - row
        its = [i for i in items if i.kind == kind]
        for i in its:
            if i.t1 is not None:
                ax.plot([i.t, i.t1], [y, y], "-", color=f"C{row}", lw=6, alpha=0.5, solid_capstyle="butt")
        if its:
            ax.plot([i.t for i in its], [y] * len(its), "|", color=f"C{row}", ms=12, mew=1.5)
    ax.set_yticks(range(len(KINDS)), list(reversed(KINDS)), fontsize=8)
    pad = 0.01 * max(duration, 1e-3)
    ax.set_xlim(-pad, max(duration, 1e-3) + pad)
    ax.set_ylim(-0.7, len(KINDS) - 0.3)
    ax.set_xlabel("session time (s)")
    ax.grid(axis="x", alpha=0.3)
    fig.tight_layout()
    return _png(fig)


def tracking_png(tracking: Sequence[tuple[float, ...]], origin: float, driven: tuple[float, float] | None) -> str:
    """``tracking``: (t, driving, speed, depth and heading references, their errors) rows."""
    plt = _plt()
    a = np.asarray(tracking, dtype=float).reshape(-1, 8)
    t = a[:, 0] - origin
    fig, axes = plt.subplots(3, 1, figsize=(10, 7), sharex=True)
    heading = np.angle(np.exp(1j * (a[:, 4] + a[:, 7])))  # reference + error, wrapped
    for ax, ref, got, name in ((axes[0], a[:, 2], a[:, 2] + a[:, 5], "speed (m/s)"),
                               (axes[1], a[:, 3], a[:, 3] + a[:, 6], "depth (m)"),
                               (axes[2], a[:, 4], heading, "heading (rad)")):
        _shade(ax, driven, origin)
        tt, r, g = _stride(t, ref, got)
        ax.plot(tt, r, "--", color="C1", lw=1, label="reference")
        ax.plot(tt, g, "-", color="C0", lw=1, label="measured")
        ax.set_ylabel(name)
    axes[1].invert_yaxis()
    axes[0].legend(fontsize=8, loc="best")
    axes[2].set_xlabel("session time (s); shaded: the fins driven")
    fig.tight_layout()
    return _png(fig)


def power_png(d: RunData, origin: float, driven: tuple[float, float] | None) -> str:
    plt = _plt()
    fig, axes = plt.subplots(2, 1, figsize=(10, 5.5), sharex=True)
    for ax, series, name in ((axes[0], d.electrical, "electrical (battery) power (W)"),
                             (axes[1], d.power, "shaft (mechanical estimate) power (W)")):
        _shade(ax, driven, origin)
        a = series.array()
        if len(series) == 0:
            ax.text(0.5, 0.5, "no readings", transform=ax.transAxes, ha="center", va="center", color="grey")
        else:
            cols = _stride(a[:, 0] - origin, *(a[:, k] for k in range(1, 6)))
            ax.plot(cols[0], cols[1], "-", color="black", lw=1.2, label="total")
            for i in range(N_FINS):
                ax.plot(cols[0], cols[2 + i], "-", color=f"C{i}", lw=0.7, alpha=0.8, label=f"fin {i}")
        ax.set_ylabel(name, fontsize=8)
    for ax in axes:
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7, loc="upper right", ncol=5)
            break
    axes[1].set_xlabel("session time (s)")
    fig.tight_layout()
    return _png(fig)


def strouhal_png(d: RunData, origin: float) -> str:
    plt = _plt()
    fig, axes = plt.subplots(N_FINS, 1, figsize=(10, 8), sharex=True, sharey=True)
    for i, ax in enumerate(axes):
        a = d.strokes[i].array()
        if len(d.strokes[i]):
            t, st, lo, hi, opt = _stride(a[:, 0] - origin, a[:, 1], a[:, 2], a[:, 3], a[:, 4])
            ax.fill_between(t, lo, hi, step="post", color="#cfe8cf", zorder=0, label="corridor")
            ax.step(t, opt, where="post", color="C2", lw=0.8, label="optimum")
            inside = (st >= lo) & (st <= hi)
            ax.plot(t[inside], st[inside], ".", color="C0", ms=2.5, label="in corridor")
            ax.plot(t[~inside], st[~inside], ".", color="C3", ms=2.5, label="outside")
        else:
            ax.text(0.5, 0.5, "no strokes", transform=ax.transAxes, ha="center", va="center", color="grey")
        ax.set_ylabel(f"fin {i} St", fontsize=8)
    if axes[0].get_legend_handles_labels()[0]:
        axes[0].legend(fontsize=7, loc="upper right", ncol=4)
    axes[-1].set_xlabel("session time (s)")
    fig.tight_layout()
    return _png(fig)
