"""Runs side by side: sessions (or their segments) read into :class:`Run`, cut at events,
aligned at an event, and their Table V rows (docs/review.md).

A segment runs from one cutting event (a marker, a mode, tuning or setpoint change: the
codes asked for) to the next, or to the run's start or end. Times shown are session time:
seconds from the session's first message, the one time base of review.

Every row's power figures are of one source (:func:`power_source`): the battery's when every
run or segment has electrical readings, else the mechanical estimate's, labelled with the
ones that have none, so a run is never weighed by its battery against another's estimate.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Sequence

from ucat_console.backend.review.metrics import (
    ELECTRICAL,
    MECHANICAL,
    NO_ELECTRICAL,
    TABLE_CHANNELS,
    MetricsConfig,
    RunData,
    TableRow,
    flag_rows,
    table_row,
)
from ucat_console.backend.review.metrics import power_source as window_source
from ucat_console.backend.sessions.limits import MemoryBudget
from ucat_console.backend.sessions.reader import SessionParts
from ucat_console.telemetry.channels import EVENTS
from ucat_console.telemetry.events import Event

#: the event codes that may cut a run into segments
SEGMENT_CODES = ("marker", "mode", "tuning", "setpoints", "armed", "disarmed")


@dataclass
class Run:
    """One session's figures' data and events; ``origin`` (stream s, its first message) is
    its session time 0; ``[start, end]`` the stretch compared (the whole session unless cut)."""

    name: str
    data: RunData
    events: list[Event]
    origin: float
    start: float
    end: float

    def cut(self, lo: float, hi: float) -> None:
        """Compare only session time ``[lo, hi]``."""
        self.start, self.end = max(self.start, self.origin + lo), min(self.end, self.origin + hi)
        if not self.end > self.start:
            raise ValueError(f"{self.name}: the window {lo:g}..{hi:g} s holds none of the session")


@dataclass(frozen=True)
class Window:
    """A stretch of one run: ``[t0, t1]`` in stream seconds, and the stream time that is 0
    on an overlaid plot (the alignment event, else the window's start)."""

    run: Run
    label: str
    t0: float
    t1: float
    zero: float


def read_run(session: SessionParts, name: str | None = None, max_messages: int | None = None) -> Run:
    """The figures' channels and the events of an open session; ``max_messages``: refuse a
    session holding more (ValueError naming it) before reading it."""
    if max_messages is not None and session.message_count > max_messages:
        raise ValueError(f"{session.session_id}: {session.message_count} messages; at most {max_messages} "
                         "are compared here (use `ucat-console sessions compare` from the shell)")
    data = RunData()
    events: list[Event] = []
    for r in session.records((*TABLE_CHANNELS, EVENTS)):
        if r.channel == EVENTS:
            events.append(r.message)
        else:
            data.feed(r.channel, r.message)
    return Run(name or session.session_id, data, events, session.start, session.start, session.end)


def load_run(session: str | Path, directory: str | Path | None = None, max_messages: int | None = None,
             *, confined: bool = True, budget: MemoryBudget | None = None) -> Run:
    """Open a session (id or any part file; a file that is not a session is refused with a
    ValueError naming it; ``confined`` and ``budget``: as :class:`SessionParts`) and read it."""
    with SessionParts(session, directory, confined=confined, budget=budget) as s:
        return read_run(s, max_messages=max_messages)


def check_codes(codes: Iterable[str], what: str) -> tuple[str, ...]:
    out = tuple(codes)
    bad = [c for c in out if c not in SEGMENT_CODES]
    if bad:
        raise ValueError(f"{what}: {', '.join(map(repr, bad))} not one of {', '.join(SEGMENT_CODES)}")
    return out


def _cuts(run: Run, codes: Sequence[str]) -> list[Event]:
    return [e for e in run.events if e.code in codes and run.start < e.t < run.end]


def windows(run: Run, segment_codes: Sequence[str] = (), align: str | None = None) -> list[Window]:
    """The run whole (no codes), or cut at its events of ``segment_codes``; each window's
    plot zero is its first ``align`` event (a code of SEGMENT_CODES; None: its start)."""
    check_codes(segment_codes, "segments")
    if align is not None:
        check_codes([align], "align")
    cuts = _cuts(run, segment_codes)
    edges = [run.start, *(e.t for e in cuts), run.end]
    names = ["start", *(f"{e.code}: {e.message}" for e in cuts)]
    out = []
    for k, (t0, t1) in enumerate(zip(edges[:-1], edges[1:])):
        if not t1 > t0:
            continue
        label = run.name if not cuts else f"{run.name} #{k + 1} ({names[k]})"
        zero = t0
        if align is not None:
            at = [e.t for e in run.events if e.code == align and t0 <= e.t <= t1]
            if not at:
                raise ValueError(f"{label}: no {align!r} event to align at")
            zero = at[0]
        out.append(Window(run, label, t0, t1, zero))
    return out


def power_source(wins: Sequence[Window]) -> tuple[str, str]:
    """The power every window's figures are of (module docstring), and why it is the
    estimate ("" for the battery's)."""
    missing = [w.label for w in wins if window_source(w.run.data, w.t0, w.t1) != ELECTRICAL]
    if not missing:
        return ELECTRICAL, ""
    return MECHANICAL, NO_ELECTRICAL if len(missing) == len(wins) else f"{NO_ELECTRICAL} in {', '.join(missing)}"


def table(wins: Sequence[Window], cfg: MetricsConfig) -> list[TableRow]:
    """Table V rows of the windows, each flagged against the first, their power of one source."""
    for w in wins:
        if len(w.run.data.power) == 0:
            raise ValueError(f"{w.run.name}: the session has no power messages: its efficiency cannot be computed")
    source, why = power_source(wins)
    rows = [table_row(w.run.data, w.t0, w.t1, cfg, w.label, closed=w.t1 >= w.run.end, source=source, source_why=why)
            for w in wins]
    return flag_rows(rows, cfg)
