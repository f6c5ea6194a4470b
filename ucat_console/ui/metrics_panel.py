"""Efficiency as numbers: each fin's St of its latest two strokes (coloured in or out of its
corridor), power, cycle opening and winding; the robot's power, energy per metre, cost of
transport and tracking errors over a window (docs/review.md).

:class:`MetricsPanel` subscribes to a telemetry stream (the live one, or a review's) and
keeps the messages of the last window in a :class:`~ucat_console.backend.review.metrics.RunData`
(the figures' one definition); :meth:`MetricsPanel.refresh`, from a UI thread, renders them
as an HTML table. Each fin's row starts with a swatch of its plot colour (the 3-D fins have
the same colours).
"""

from __future__ import annotations

import math
import threading
from dataclasses import replace
from typing import Any, Callable

from ucat_console.backend.review.effects import Effect, summary
from ucat_console.backend.review.metrics import CHANNELS, MetricsConfig, RunData, fins_now, robot_now
from ucat_console.telemetry.stream import TelemetryStream
from ucat_console.ui.markdown import esc
from ucat_console.ui.plots import FIN_COLOURS

#: the colours of a stroke's St inside and outside its corridor (text on them: white)
IN_COLOUR = "#1e7b34"
OUT_COLOUR = "#c0392b"
#: the window's largest length (s), and the least the panel keeps in memory
MAX_WINDOW = 600.0
KEEP = 60.0
#: a message this much older than the latest (s) starts the figures afresh (a seek back)
BACK = 1.0


def _num(x: float, fmt: str) -> str:
    return format(x, fmt) if math.isfinite(x) else "–"


def render(data: RunData, t: float, cfg: MetricsConfig) -> str:
    """The panel's HTML for time ``t`` (the latest message)."""
    cell = "padding:1px 4px;text-align:right;white-space:nowrap"
    rows = []
    for f in fins_now(data, t, cfg):
        sts = []
        for k, s in enumerate(f.strokes):
            inside = s.in_corridor
            sts.append(
                f'<span class="ucat-st {"in" if inside else "out"}" data-fin="{f.fin}" data-stroke="{k}" '
                f'title="corridor {s.low:.2f}-{s.high:.2f}" style="background:{IN_COLOUR if inside else OUT_COLOUR};'
                f'color:#fff;border-radius:3px;padding:0 3px;margin-right:2px">{_num(s.st, ".2f")}</span>')
        swatch = (f'<span style="display:inline-block;width:10px;height:10px;background:{FIN_COLOURS[f.fin]};'
                  f'margin-right:3px"></span>')
        rows.append(
            f'<tr data-fin="{f.fin}"><td style="{cell};text-align:left">{swatch}{f.fin}</td>'
            f'<td style="{cell}">{"".join(sts) or "–"}</td>'
            f'<td style="{cell}" class="ucat-fin-power">{_num(f.power, ".2f")}</td>'
            f'<td style="{cell}">{_num(f.opening, ".2f")}</td>'
            f'<td style="{cell}">{_num(f.winding, ".1f")}</td></tr>')
    r = robot_now(data, t, cfg)
    head = "".join(f'<th style="{cell}">{h}</th>' for h in
                   ("fin", "St (strokes)", "P (W)", "open (rad)", "wind (rad/min)"))
    robot = (
        f'<div class="ucat-robot" style="margin-top:2px">'
        f'<b class="ucat-power">P {_num(r.power, ".2f")} W</b> · '
        f'<span class="ucat-epm">{_num(r.energy_per_metre, ".1f")} J/m</span> · '
        f'<span class="ucat-cot">CoT {_num(r.cost_of_transport, ".2f")} J/(kg m)</span> '
        f'<span style="opacity:.7">over {cfg.window:g} s</span><br>'
        f'errors: speed {_num(r.speed_mae, ".3f")} m/s · depth {_num(r.depth_mae, ".3f")} m · '
        f'heading {_num(math.degrees(r.heading_mae) if math.isfinite(r.heading_mae) else math.nan, ".1f")}°'
        f'</div>')
    return (f'<div class="ucat-metrics" style="font-size:12px;line-height:1.3">'
            f'<table style="border-collapse:collapse"><tr>{head}</tr>{"".join(rows)}</table>{robot}</div>')


class MetricsPanel:
    """The figures of one stream in an HTML element of ``gui`` (module docstring)."""

    def __init__(self, gui: Any, cfg: MetricsConfig, *, order: float | None = None,
                 window: Callable[[], float] | None = None) -> None:
        self.cfg = cfg
        self._window = window or (lambda: cfg.window)
        self._lock = threading.Lock()
        self._data = RunData()
        self._t = -math.inf
        self._dirty = False
        self.html = gui.add_html(self._empty(), order=order)

    @staticmethod
    def _empty() -> str:
        return '<div class="ucat-metrics" style="font-size:12px;opacity:.7">efficiency: no telemetry yet</div>'

    def subscribe(self, stream: TelemetryStream) -> Callable[[], None]:
        return stream.subscribe(self.on_message, CHANNELS)

    def on_message(self, channel: str, msg: Any) -> None:
        with self._lock:
            if msg.t < self._t - BACK:  # time went back (a review's seek, another session): afresh
                self._data = RunData()
                self._t = -math.inf
            self._data.feed(channel, msg)
            self._t = max(self._t, msg.t)
            self._dirty = True

    def reset(self) -> None:
        """Forget everything (another session opened)."""
        with self._lock:
            self._data = RunData()
            self._t = -math.inf
            self._dirty = False
        self._set(self._empty())

    def refresh(self) -> None:
        """Render the latest figures (a UI thread; does nothing when nothing came)."""
        with self._lock:
            if not self._dirty:
                return
            self._dirty = False
            window = min(float(self._window()), MAX_WINDOW)
            cfg = self.cfg if window == self.cfg.window else _with_window(self.cfg, window)
            self._data.drop_before(self._t - max(window, KEEP))
            content = render(self._data, self._t, cfg)
        self._set(content)

    def _set(self, content: str) -> None:
        if self.html.content != content:
            self.html.content = content


def _with_window(cfg: MetricsConfig, window: float) -> MetricsConfig:
    return replace(cfg, window=window)



def effects_markdown(entries: list[Effect], now: float) -> str:
    """The latest changes with their figures before -> after (a pending one: how long until
    its after-window completes)."""
    if not entries:
        return "Measured effects: no tuning, mode or setpoint change yet."
    out = ["Measured effects (newest first; before → after):", ""]
    for e in entries[:8]:
        due = "" if e.after is not None else f" (after-window fills in {max(0.0, e.due - now):.0f} s)"
        out.append(f"- {e.t:.1f} s {esc(e.message)}: {esc(summary(e))}{due}")
    return "\n".join(out)
