"""Bursts of one kind of warning folded into one event.

A slow machine can make dozens of plans late in a second; one event per plan floods the
events channel (159 of 192 events of one session were plan overruns) and buries what an
operator needs to see. :class:`BurstFolder` holds the events of the codes it folds, and
publishes one event per burst: the count, the first and last time, the worst lateness,
when no event of that code has come for ``gap`` s, or every ``span`` s while it goes on.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import Callable, Iterable

from ucat_console.telemetry.events import Event


#: what one event of a folded code says, in a burst's message
_WHAT = {"plan_overrun": "plan ready after its hand-over deadline",
         "stall": "loop stall skipped (the loop fell behind the wall clock)"}


@dataclass
class _Burst:
    first: Event
    last_t: float
    count: int = 0
    worst: float = 0.0
    fins: set = field(default_factory=set)


class BurstFolder:
    """Folds events of ``codes`` from ``source``; ``publish(event)`` receives the summaries."""

    def __init__(self, publish: Callable[[Event], None], codes: Iterable[str] = ("plan_overrun",),
                 source: str = "loop", gap: float = 1.0, span: float = 10.0) -> None:
        self.publish = publish
        self.codes = frozenset(codes)
        self.source = source
        self.gap = float(gap)
        self.span = float(span)
        self._lock = threading.Lock()
        self._open: dict[str, _Burst] = {}

    def take(self, ev: Event) -> bool:
        """True when ``ev`` is folded (the caller does not publish it)."""
        if ev.source != self.source or ev.code not in self.codes:
            return False
        with self._lock:
            b = self._open.get(ev.code)
            if b is None:
                b = self._open[ev.code] = _Burst(ev, ev.t)
            b.count += 1
            b.last_t = ev.t
            late = ev.data.get("late") if isinstance(ev.data, dict) else None
            if isinstance(late, (int, float)):
                b.worst = max(b.worst, float(late))
            fins = ev.data.get("fins") if isinstance(ev.data, dict) else None
            if isinstance(fins, list):
                b.fins.update(f for f in fins if isinstance(f, int))
        return True

    def check(self, now: float, flush: bool = False) -> None:
        """Publish the bursts that have ended (or, with ``flush``, all of them)."""
        done = []
        with self._lock:
            for code, b in list(self._open.items()):
                if flush or now - b.last_t >= self.gap or now - b.first.t >= self.span:
                    done.append(b)
                    del self._open[code]
        for b in done:
            self.publish(self._summary(b))

    def _summary(self, b: _Burst) -> Event:
        ev = b.first
        what = _WHAT.get(ev.code, ev.code)
        if b.count == 1:
            message = ev.message
        else:
            message = (f"{b.count} x {what} between {ev.t:.1f} and {b.last_t:.1f} s"
                       + (f" (worst {b.worst * 1e3:.1f} ms late)" if b.worst > 0 else "")
                       + (f", fins {sorted(b.fins)}" if b.fins else ""))
        data = dict(ev.data) if isinstance(ev.data, dict) else {}
        data.update({"count": b.count, "first": ev.t, "last": b.last_t, "worst_late": b.worst,
                     "fins": sorted(b.fins)})
        return Event(t=b.last_t, source=ev.source, code=ev.code, message=message, level=ev.level, data=data)
