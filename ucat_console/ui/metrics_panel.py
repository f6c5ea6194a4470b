"""Efficiency as numbers: each fin's St of its latest two strokes (coloured in or out of its
corridor), power, cycle opening and winding; the robot's power, energy per metre, cost of
transport and tracking errors over a window (docs/review.md). The power is the battery's
(electrical) where the drives report it, the mechanical estimate's below it; without
electrical readings the battery's row says so and the estimate's is used (marked ▸, as are
the fins' powers).

:class:`MetricsPanel` subscribes to a telemetry stream (the live one, or a review's) and
keeps the messages of the last window in a :class:`~ucat_console.backend.review.metrics.RunData`
(the figures' one definition); :meth:`MetricsPanel.refresh`, from a UI thread, renders them
as an HTML table. Each fin's row starts with a swatch of its plot colour (the 3-D fins have
the same colours).

A stroke's St is a measurement only while the robot is armed and swims at least
:data:`~ucat_console.ui.plots.ST_MIN_SPEED` (the plots' rule: St = f A / U means nothing
slower, where the planner's speed floor sets it). Otherwise, and for every fin while the
robot is disarmed (the stream's ``status``), its tile shows a greyed "–", never a value.
"""

from __future__ import annotations

import html
import math
import threading
from dataclasses import replace
from typing import Any, Callable

from ucat_console.backend.review.effects import Effect, summary
from ucat_console.backend.review.metrics import (
    CHANNELS,
    ELECTRICAL,
    LABELS,
    MECHANICAL,
    MetricsConfig,
    RobotNow,
    RunData,
    fins_now,
    robot_now,
)
from ucat_console.robot.fins import N_FINS
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.stream import TelemetryStream
from ucat_console.ui.markdown import esc
from ucat_console.ui.plots import FIN_COLOURS, ST_MIN_SPEED

#: the colours of a stroke's St inside and outside its corridor (text on them: white)
IN_COLOUR = "#1e7b34"
OUT_COLOUR = "#c0392b"
#: the window's largest length (s), and the least the panel keeps in memory
MAX_WINDOW = 600.0
KEEP = 60.0
#: a message this much older than the latest (s) starts the figures afresh (a seek back)
BACK = 1.0
#: the channels the panel reads: the figures', and the armed state
PANEL_CHANNELS = (*CHANNELS, ch.STATUS)
_STROUHAL = frozenset(ch.fin_strouhal(i) for i in range(N_FINS))


def _num(x: float, fmt: str) -> str:
    return format(x, fmt) if math.isfinite(x) else "–"


_CELL = "padding:1px 4px;text-align:right;white-space:nowrap"


def _power_rows(r: RobotNow) -> str:
    """The robot's power, energy per metre and cost of transport: a row for the battery's, one
    for the estimate's; the one the figures use first, marked ▸ and bold (its cells classed
    ``ucat-power``, ``ucat-epm``, ``ucat-cot``)."""
    left = f"{_CELL};text-align:left"
    used_values = (r.power, r.energy_per_metre, r.cost_of_transport)
    mech_values = (r.mech_power, r.mech_energy_per_metre, r.mech_cost_of_transport)
    rows = []
    for source in (r.source, MECHANICAL if r.source == ELECTRICAL else ELECTRICAL):
        used = source == r.source
        if used or source == MECHANICAL:
            values = used_values if used else mech_values
            classes = ("ucat-power", "ucat-epm", "ucat-cot") if used else ("", "", "")
            cells = "".join(f'<td style="{_CELL}" class="{c}">{_num(v, f)}</td>'
                            for c, v, f in zip(classes, values, (".2f", ".1f", ".2f")))
        else:  # the battery's, not used: the window holds no electrical readings
            cells = f'<td style="{left}" colspan="3" class="ucat-none">no readings</td>'
        title = r.source_label if used else LABELS[source]
        rows.append(f'<tr class="ucat-source{" ucat-used" if used else ""}" data-source="{source}" '
                    f'style="{"font-weight:bold" if used else "opacity:.7"}" title="{html.escape(title)}">'
                    f'<td style="{left}">{"▸ " if used else ""}{LABELS[source]}</td>{cells}</tr>')
    head = "".join(f'<th style="{_CELL}">{h}</th>' for h in ("P (W)", "J/m", "CoT (J/(kg m))"))
    return (f'<table class="ucat-robot-power" style="border-collapse:collapse;margin-top:2px">'
            f'<tr><th style="{left};font-weight:normal;opacity:.7">over {r.window:g} s</th>{head}</tr>'
            f'{"".join(rows)}</table>')


def _no_st(fin: int, why: str) -> str:
    """A fin's St tile without a measurement: a greyed dash, the reason on hover."""
    return (f'<span class="ucat-st none" data-fin="{fin}" title="{html.escape(why)}" '
            f'style="opacity:.45;padding:0 3px">–</span>')


def render(data: RunData, t: float, cfg: MetricsConfig, armed: bool | None = None) -> str:
    """The panel's HTML for time ``t`` (the latest message); ``armed``: the robot's state as
    last told (False: no St tile shows a value; None: not told)."""
    cell = _CELL
    rows = []
    for f in fins_now(data, t, cfg):
        sts = []
        for k, s in enumerate(f.strokes):
            if not math.isfinite(s.st):  # not a measurement: nor is an older stroke one now
                sts = []
                continue
            inside = s.in_corridor
            sts.append(
                f'<span class="ucat-st {"in" if inside else "out"}" data-fin="{f.fin}" data-stroke="{k}" '
                f'title="corridor {s.low:.2f}-{s.high:.2f}" style="background:{IN_COLOUR if inside else OUT_COLOUR};'
                f'color:#fff;border-radius:3px;padding:0 3px;margin-right:2px">{_num(s.st, ".2f")}</span>')
        if armed is False:
            sts = [_no_st(f.fin, "no measurement: the robot is disarmed")]
        elif not sts:
            sts = [_no_st(f.fin, f"no measurement: no stroke at {ST_MIN_SPEED:g} m/s or faster" if f.strokes
                          else "no stroke yet")]
        swatch = (f'<span style="display:inline-block;width:10px;height:10px;background:{FIN_COLOURS[f.fin]};'
                  f'margin-right:3px"></span>')
        rows.append(
            f'<tr data-fin="{f.fin}"><td style="{cell};text-align:left">{swatch}{f.fin}</td>'
            f'<td style="{cell}">{"".join(sts)}</td>'
            f'<td style="{cell}" class="ucat-fin-power">{_num(f.power, ".2f")}</td>'
            f'<td style="{cell}">{_num(f.opening, ".2f")}</td>'
            f'<td style="{cell}">{_num(f.winding, ".1f")}</td></tr>')
    r = robot_now(data, t, cfg)
    head = "".join(f'<th style="{cell}"{attr}>{h}</th>' for h, attr in
                   (("fin", ""), ("St (strokes)", ""), ("P (W)", f' title="{html.escape(r.source_label)}"'),
                    ("open (rad)", ""), ("wind (rad/min)", "")))
    robot = (
        f'<div class="ucat-robot">{_power_rows(r)}'
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
        self._armed: bool | None = None  # as the stream last told
        self._dirty = False
        self.html = gui.add_html(self._empty(), order=order)

    @staticmethod
    def _empty() -> str:
        return '<div class="ucat-metrics" style="font-size:12px;opacity:.7">efficiency: no telemetry yet</div>'

    def subscribe(self, stream: TelemetryStream) -> Callable[[], None]:
        return stream.subscribe(self.on_message, PANEL_CHANNELS)

    def on_message(self, channel: str, msg: Any) -> None:
        with self._lock:
            if msg.t < self._t - BACK:  # time went back (a review's seek, another session): afresh
                self._data = RunData()
                self._t = -math.inf
                self._armed = None
            if channel == ch.STATUS:
                self._armed = bool(msg.armed)
            elif channel in _STROUHAL and (self._armed is False or not msg.v_body >= ST_MIN_SPEED):
                msg = replace(msg, st=math.nan)  # not a measurement: its tile shows none
            self._data.feed(channel, msg)
            self._t = max(self._t, msg.t)
            self._dirty = True

    def reset(self) -> None:
        """Forget everything (another session opened)."""
        with self._lock:
            self._data = RunData()
            self._t = -math.inf
            self._armed = None
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
            content = render(self._data, self._t, cfg, self._armed)
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
