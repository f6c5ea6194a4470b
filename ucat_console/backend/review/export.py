"""A comparison written out: Markdown (Table V form), CSV (one row per figure) and a PNG of
the runs overlaid (matplotlib, Agg: no display needed); each says which power its power
figures are of (the rows' source: the battery's, or the mechanical estimate's)."""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ucat_console.backend.review.compare import Window, power_source
from ucat_console.backend.review.metrics import (
    ELECTRICAL,
    FIGURES,
    LABELS,
    MECHANICAL,
    POWER_FIGURES,
    MetricsConfig,
    TableRow,
    source_label,
)
from ucat_console.robot.fins import N_FINS

#: the robot table's columns, then each fin's
ROBOT_COLUMNS = ("power", "energy_per_metre", "cost_of_transport", "mech_power", "mech_energy_per_metre",
                 "mech_cost_of_transport", "speed", "speed_mae", "depth_mae", "heading_mae", "st_mae", "st_in")
FIN_COLUMNS = ("power", "st_mae", "st_in")


def cell(row: TableRow, key: str) -> str:
    """``value [lo, hi]``, 3 significant digits; "–" for none."""
    e = row.figures[key]
    if not math.isfinite(e.value):
        return "–"
    text = f"{e.value:.3g}"
    if math.isfinite(e.lo) and math.isfinite(e.hi):
        text += f" [{e.lo:.3g}, {e.hi:.3g}]"
    return text


def _md_text(s: str) -> str:
    return s.replace("\\", "\\\\").replace("|", "\\|").replace("\n", " ").replace("`", "\\`")


def markdown(rows: Sequence[TableRow], wins: Sequence[Window], cfg: MetricsConfig) -> str:
    def head(keys: Sequence[str], names: Sequence[str]) -> list[str]:
        cols = ["run / segment", *names]
        return ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]

    conf = f"{cfg.confidence * 100:g}%"
    out = [
        "# Runs compared", "",
        f"Figures with their {conf} bootstrap interval over cycles in brackets ({cfg.resamples} resamples); "
        f"cost of transport with mass {cfg.mass:g} kg. Times are session time (s from each session's start). "
        f"A row is *not comparable* with the first when its mean speed differs by more than "
        f"{cfg.speed_bound:g} m/s, its speed MAE by more than {cfg.speed_mae_bound:g} m/s or its depth MAE "
        f"by more than {cfg.depth_mae_bound:g} m.", "",
        f"Power: {_md_text(rows[0].source_label) if rows else '–'} (mean power, energy per metre, cost of "
        f"transport and each fin's power); the {LABELS[MECHANICAL]} beside it.", "",
        *head(["window", "cycles", *ROBOT_COLUMNS, "comparable"],
              ["window (s)", "cycles", *(f"{FIGURES[k][0]} ({FIGURES[k][1]})" for k in ROBOT_COLUMNS),
               "comparable"]),
    ]
    for r, w in zip(rows, wins):
        span = f"{r.t0 - w.run.origin:.1f}–{r.t1 - w.run.origin:.1f}"
        flag = f"**not comparable**: {_md_text(r.not_comparable)}" if r.not_comparable else "yes"
        out.append("| " + " | ".join([_md_text(r.label), span, str(r.cycles),
                                      *(cell(r, k) for k in ROBOT_COLUMNS), flag]) + " |")
    out += ["", "## Per fin", "",
            *head([], [f"fin {i} {FIGURES[k][0]} ({FIGURES[k][1]})" for i in range(N_FINS) for k in FIN_COLUMNS])]
    for r in rows:
        out.append("| " + " | ".join([_md_text(r.label), *(cell(r, f"{k}_{i}") for i in range(N_FINS)
                                                           for k in FIN_COLUMNS)]) + " |")
    return "\n".join(out) + "\n"


def csv_text(rows: Sequence[TableRow], wins: Sequence[Window]) -> str:
    """One line per row and figure: label, session, window (session s), figure, unit, value,
    interval, why the row is not comparable ("" when it is), and which power a power figure
    is of ("" for the others)."""
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["label", "session", "t0", "t1", "cycles", "figure", "unit", "value", "lo", "hi",
                "not_comparable", "power_source"])
    for r, win in zip(rows, wins):
        for key, est in r.figures.items():
            source = r.source_label if key in POWER_FIGURES else LABELS[MECHANICAL] if key.startswith("mech_") else ""
            w.writerow([r.label, win.run.name, f"{r.t0 - win.run.origin:.3f}", f"{r.t1 - win.run.origin:.3f}",
                        r.cycles, key, FIGURES[key][1], repr(est.value), repr(est.lo), repr(est.hi),
                        r.not_comparable, source])
    return buf.getvalue()


def overlay_figure(wins: Sequence[Window]) -> Any:
    """A matplotlib figure of speed, depth, total power (of the windows' source, as the
    table's) and each stroke's St over time from each window's zero (its alignment event),
    one colour per window (close it when done)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    source, why = power_source(wins)
    fig, axes = plt.subplots(4, 1, figsize=(10, 9), sharex=True)
    band = False
    for k, w in enumerate(wins):
        colour = f"C{k}"
        d = w.run.data
        sp = d.speed.array()
        sel = (sp[:, 0] >= w.t0) & (sp[:, 0] <= w.t1)
        axes[0].plot(sp[sel, 0] - w.zero, sp[sel, 1], color=colour, lw=1, label=w.label)
        axes[1].plot(sp[sel, 0] - w.zero, sp[sel, 2], color=colour, lw=1)
        p = (d.electrical if source == ELECTRICAL else d.power).array()
        sel = (p[:, 0] >= w.t0) & (p[:, 0] <= w.t1) & np.isfinite(p[:, 1])
        axes[2].plot(p[sel, 0] - w.zero, p[sel, 1], color=colour, lw=1)
        for s in d.strokes:
            a = s.array()
            sel = (a[:, 0] >= w.t0) & (a[:, 0] <= w.t1)
            axes[3].plot(a[sel, 0] - w.zero, a[sel, 1], ".", color=colour, ms=2)
            if not band and sel.any():
                axes[3].axhspan(float(np.median(a[sel, 2])), float(np.median(a[sel, 3])), color="#cfe8cf",
                                zorder=0)
                band = True
    axes[0].set_ylabel("speed (m/s)")
    axes[1].set_ylabel("depth (m)")
    axes[1].invert_yaxis()
    axes[2].set_ylabel("power (W)")
    axes[2].set_title(f"power: {source_label(source, why)}", fontsize=9)
    axes[3].set_ylabel("St per stroke")
    axes[3].set_xlabel("time from each window's alignment (s)")
    axes[0].legend(fontsize=7, loc="best")
    fig.tight_layout()
    return fig


def png_bytes(wins: Sequence[Window], dpi: int = 100) -> bytes:
    """The overlay as PNG bytes."""
    import matplotlib.pyplot as plt

    fig = overlay_figure(wins)
    buf = io.BytesIO()
    try:
        fig.savefig(buf, format="png", dpi=dpi)
    finally:
        plt.close(fig)
    return buf.getvalue()


def write_png(wins: Sequence[Window], path: Path) -> None:
    path.write_bytes(png_bytes(wins))


def write_all(rows: Sequence[TableRow], wins: Sequence[Window], cfg: MetricsConfig, out: Path) -> dict[str, Path]:
    """compare.md, compare.csv and compare.png in ``out`` (created)."""
    out.mkdir(parents=True, exist_ok=True)
    paths = {"markdown": out / "compare.md", "csv": out / "compare.csv", "png": out / "compare.png"}
    paths["markdown"].write_text(markdown(rows, wins, cfg))
    with open(paths["csv"], "w", newline="") as fh:
        fh.write(csv_text(rows, wins))
    write_png(wins, paths["png"])
    return paths
