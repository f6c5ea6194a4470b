"""Each change's measured effect: the figures over a window before a tuning, mode or
setpoint change and over a window after it (docs/review.md).

:class:`ChangeEffects` subscribes to the telemetry stream: it keeps the figures' messages
of the last few windows and notes each change event as it comes (cheap: the publisher's
thread). :meth:`ChangeEffects.check`, called by the supervisor between chunks of the loop
(stream time ``now``), computes the figures before a change at once and those after it when
``after`` seconds of stream time have passed, and publishes the completed entry as an
Event (source ``"review"``, code ``"effect"``) on the stream, so the session records it and
review shows it. Figures are those of :func:`~ucat_console.backend.review.metrics.window_figures`;
NaN is written as null (an event's data is JSON). The power figures of both windows are of
one source, the battery's when both have electrical readings, else the mechanical
estimate's (its label says so: ``power_source`` in the event's data); the estimate's are
beside them (``mech_*``).
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass, field, replace
from typing import Any, Callable

from ucat_console.backend.review.metrics import (
    ELECTRICAL,
    MECHANICAL,
    TABLE_CHANNELS,
    MetricsConfig,
    RunData,
    default_label,
    power_source,
    source_label,
    window_figures,
)
from ucat_console.telemetry.channels import EVENTS
from ucat_console.telemetry.events import Event

#: the changes whose effect is measured (event codes)
CHANGE_CODES = ("tuning", "mode", "setpoints")
#: the figures an entry carries
EFFECT_FIGURES = ("power", "energy_per_metre", "cost_of_transport", "mech_power", "mech_energy_per_metre",
                  "mech_cost_of_transport", "speed", "speed_mae", "depth_mae", "heading_mae", "st_mae", "st_in")
#: why an effect's figures are the estimate's when the battery's were in one window only
NOT_IN_BOTH = "electrical readings not in both windows"
_KEEP = 50


@dataclass(frozen=True)
class Effect:
    """One change and the figures before and after it (``after`` None until its window
    passed); the power figures of ``source``, labelled ``source_label``. A value: the
    figures filled in make a new one."""

    t: float
    code: str
    message: str
    data: dict[str, Any]
    due: float  # stream time when the after-window has passed
    before: dict[str, float | None] = field(default_factory=dict)
    after: dict[str, float | None] | None = None
    source: str = MECHANICAL
    source_label: str = ""


def _json(figures: dict[str, float]) -> dict[str, float | None]:
    return {k: (v if math.isfinite(v) else None) for k, v in figures.items() if k in EFFECT_FIGURES}


class ChangeEffects:
    """The effects of the changes on one stream (module docstring)."""

    def __init__(self, cfg: MetricsConfig, publish: Callable[[Event], None]) -> None:
        self.cfg = cfg
        self._publish = publish
        self._lock = threading.Lock()
        self._data = RunData()
        self._pending: list[Effect] = []
        self._done: list[Effect] = []
        self._t = -math.inf

    @property
    def channels(self) -> tuple[str, ...]:
        return (*TABLE_CHANNELS, EVENTS)

    def on_message(self, channel: str, msg: Any) -> None:
        with self._lock:
            if channel == EVENTS:
                if msg.code in CHANGE_CODES:
                    self._pending.append(Effect(msg.t, msg.code, msg.message, dict(msg.data), msg.t + self.cfg.after))
                return
            self._data.feed(channel, msg)
            self._t = max(self._t, msg.t)

    def check(self, now: float) -> list[Effect]:
        """Fill in what is due at stream time ``now``; the entries completed now."""
        cfg = self.cfg
        done = []
        with self._lock:
            pending = []
            for e in self._pending:
                if not e.before:
                    source = power_source(self._data, e.t - cfg.before, e.t)
                    e = replace(e, source=source, source_label=default_label(source))
                    e = replace(e, before=self._figures(e, e.t - cfg.before, e.t, closed=False))
                if now >= e.due:
                    if power_source(self._data, e.t, e.due) != e.source:  # like with like: the estimate's
                        e = replace(e, source_label=source_label(MECHANICAL, NOT_IN_BOTH))
                        if e.source == ELECTRICAL:
                            e = replace(e, source=MECHANICAL)
                            e = replace(e, before=self._figures(e, e.t - cfg.before, e.t, closed=False))
                    e = replace(e, after=self._figures(e, e.t, e.due))
                    done.append(e)
                else:
                    pending.append(e)
            self._pending = pending
            if done:
                self._done = (self._done + done)[-_KEEP:]
                oldest = min([e.t for e in self._pending], default=now)
                self._data.drop_before(min(oldest, now) - cfg.before - 1.0)
            elif not self._pending and self._t - self._data.start > 4 * (cfg.before + cfg.after):
                self._data.drop_before(self._t - cfg.before - 1.0)
        for e in done:
            self._publish(Event(now, "review", "effect", f"{e.message}: {summary(e)}", "info",
                                {"change_t": e.t, "code": e.code, "change": e.data, "before": e.before,
                                 "after": e.after, "power_source": e.source_label, "before_s": cfg.before,
                                 "after_s": cfg.after}))
        return done

    def _figures(self, e: Effect, t0: float, t1: float, closed: bool = True) -> dict[str, float | None]:
        """The figures of ``[t0, t1]``, the power of ``e``'s source."""
        return _json(window_figures(self._data, t0, t1, self.cfg.mass, closed=closed, source=e.source))

    def entries(self) -> list[Effect]:
        """The latest changes, newest first (pending ones without ``after``)."""
        with self._lock:
            return [*reversed(self._pending), *reversed(self._done)]


def _fmt(v: float | None, f: str) -> str:
    return "–" if v is None else format(v, f)


def summary(e: Effect) -> str:
    """``electrical (battery): 4.00 → 3.50 W, 20.0 → 17.5 J/m; ...`` (before → after; the
    power's source first)."""
    a = e.after or {}

    def parts(keys: tuple[tuple[str, str, str], ...]) -> str:
        return ", ".join(f"{_fmt(e.before.get(key), f)} → {_fmt(a.get(key), f) if e.after else '…'}{unit}"
                         for key, f, unit in keys)

    power = parts((("power", ".2f", " W"), ("energy_per_metre", ".1f", " J/m")))
    rest = parts((("speed_mae", ".3f", " m/s speed MAE"), ("st_in", ".0f", " % St in corridor")))
    return f"{e.source_label + ': ' if e.source_label else ''}{power}; {rest}"
