"""Seek efficiency on a running robot: :class:`SeekRun` (docs/seek.md).

With the robot holding its setpoints, the pilot's seek tries candidate values of the
configured parameters (``[[seek.params]]``: live tuning keys and their bounds), one at a
time: each is set through the console's tuning (the pilot's change, checked as any:
the parameter's own range, its block's check; journalled, its effect measured), then after
``settle_s`` it is measured over ``window_s`` by
:func:`~ucat_console.backend.review.metrics.table_row` (the figures' one definition): the
battery's (``power/electrical``) energy per metre with its bootstrap interval, and the
speed, depth and heading tracking errors. A candidate whose tracking error is larger than
its band is rejected (never rewarded; the best values are put back before the next), as is
one without electrical readings or without an interval (a window of fewer than two fin
cycles). A candidate under which the robot loses its track (an axis off its expected
response, the tracking failsafe's measure, for ``abort_s``) is rejected at once, before the
failsafe's timeout, and the best put back, so that a gait that cannot hold the speed ends
its candidate, not the seek; with the best back, the tracking failsafe's expected response
starts again from the robot's present state (it is judged on its way back, and a robot that
does not come back raises the failsafe after its timeout). The search (:class:`~ucat_console.backend.seek.search.Search`,
Optuna's TPE) is told each result and suggests the next; the first candidate is the values
in force at the start. Each candidate is an event (source ``"seek"``, code
``"candidate"``) and a journal entry with its figures and verdict.

After ``max_candidates`` the search's ``confirm`` best accepted candidates are measured once
more each, as any candidate (a re-measure's candidate names the one it ``confirms``); the
least energy per metre of these second measures is the best (the least of twenty noisy
first measures is, by being chosen, lower than what its values give again; a second measure
is not chosen on its own figure). When none of them is accepted the first measures' best
stands. The best is then put in force; with ``drift_check`` the run goes on
measuring it, window after window, and seeks again (from the best) when a window's energy
per metre falls outside the best's interval (the robot changed), up to ``max_seeks``
searches. The pilot can stop it at any time, keeping the best or reverting to the values it
found. It stops at once when the robot is disarmed, any failsafe is active (the tracking
failsafe among them) or its pilot is no longer the pilot, leaving what ``on_stop`` says.

``start`` / ``poll`` / ``finish`` drive it without blocking (the supervisor polls it after
every chunk, at a failsafe and at once on a disarm); :meth:`SeekRun.wait` blocks. It
reaches the console through a :class:`SeekHost`, not the supervisor.
"""

from __future__ import annotations

import math
import threading
import time
import logging
from dataclasses import dataclass, replace
from typing import Any, Callable, Iterable, Mapping

from ucat_console.backend.access import LOCAL, Actor, actor_name
from ucat_console.backend.loop.commands import CommandRefused
from ucat_console.backend.review.metrics import (
    ELECTRICAL,
    TABLE_CHANNELS,
    Estimate,
    MetricsConfig,
    RunData,
    TableRow,
    table_row,
)
from ucat_console.backend.seek.config import SeekConfig, SeekParam
from ucat_console.backend.seek.search import Dimension, Search
from ucat_console.backend.supervisor.scripted_run import segment_line
from ucat_console.telemetry.events import Event
from ucat_console.typedconf import describe_range

log = logging.getLogger(__name__)

#: the figures a candidate's event carries
CANDIDATE_FIGURES = ("energy_per_metre", "power", "speed", "speed_mae", "depth_mae", "heading_mae")


@dataclass(frozen=True)
class SeekHost:
    """What a seek uses of the console: the pilot's tuning (checked as the pilot's own),
    the telemetry to measure from and the state it follows."""

    require_pilot: Callable[[Actor, str], None]
    is_pilot: Callable[[Actor], bool]
    armed: Callable[[], bool]
    #: the active failsafes' names
    failsafes: Callable[[], tuple[str, ...]]
    #: a tunable parameter's field (its range, its kind), or CommandRefused naming the tunable ones
    param_field: Callable[[str], Any]
    param_value: Callable[[str], Any]
    #: the console's tuning: all of them or none, journalled (``Supervisor.set_params``)
    set_params: Callable[[Actor, Mapping[str, object]], None]
    #: a journal entry ``(who, key, old, new)``
    journal: Callable[[str, str, Any, Any], Any]
    publish_event: Callable[[Event], None]
    #: ``subscribe(fn, channels)`` on the telemetry stream; returns the unsubscribe
    subscribe: Callable[[Callable[[str, Any], None], Iterable[str]], Callable[[], None]]
    #: the loop's time (s)
    time: Callable[[], float]
    metrics: MetricsConfig
    #: ``off_track(now)``: how long the axis furthest off its expected response has been off (s,
    #: 0 when none is) and its error in words (``Safety.off_track``)
    off_track: Callable[[float], tuple[float, str]]
    #: the tracking failsafe's timeout (s): a candidate is rejected before it
    tracking_timeout: float
    #: the tracking failsafe's expected response starts again from the robot's present
    #: state (``Safety.restart_expected``): after the best is put back
    restart_expected: Callable[[], None]


@dataclass(frozen=True)
class Candidate:
    """One measured candidate: its values, figures and verdict."""

    index: int  # from 0 over the whole run
    search: int  # which search (0: the first; more after a drift)
    values: tuple[tuple[str, float], ...]
    energy: Estimate | None  # energy per metre (J/m) with its interval; None: no figures
    verdict: str  # "accepted", or why not
    line: str  # the figures in a line
    confirms: int | None = None  # a second measure: the index of the candidate it measures again

    @property
    def accepted(self) -> bool:
        return self.verdict == "accepted"


def _json(x: float) -> float | None:
    return x if math.isfinite(x) else None


def values_text(values: Iterable[tuple[str, float]]) -> str:
    return ", ".join(f"{k} {v:.4g}" for k, v in values)


def estimate_text(e: Estimate) -> str:
    interval = f" [{e.lo:.1f}, {e.hi:.1f}]" if math.isfinite(e.lo) and math.isfinite(e.hi) else " [no interval]"
    return f"{e.value:.1f} J/m{interval}"


def check_space(params: tuple[SeekParam, ...], field_of: Callable[[str], Any]) -> tuple[Dimension, ...]:
    """The search's dimensions of ``params``, each a tunable number whose bounds lie inside
    its field's own range; CommandRefused naming the parameter otherwise."""
    dims = []
    for p in params:
        f = field_of(p.name)
        if f.metadata.get("choices") is not None or f.type in ("bool", bool, "str", str):
            raise CommandRefused(f"seek: {p.name} is not a number (the seeker varies numbers only)")
        m = f.metadata
        lo, hi = m.get("lo"), m.get("hi")
        below = lo is not None and (p.lo <= lo if m.get("lo_open") else p.lo < lo)
        above = hi is not None and (p.hi >= hi if m.get("hi_open") else p.hi > hi)
        if below or above:
            raise CommandRefused(f"seek: {p.name}: the bounds [{p.lo:g}, {p.hi:g}] leave the parameter's "
                                 f"own range {describe_range(f)}")
        dims.append(Dimension(p.name, p.lo, p.hi, f.type in ("int", int)))
    return tuple(dims)


class SeekRun:
    """One seek (module docstring)."""

    def __init__(self, host: SeekHost, who: Actor, cfg: SeekConfig, params: tuple[str, ...] = ()) -> None:
        self.host = host
        self.who = who
        self.cfg = cfg
        self.params = cfg.only(params)
        #: why it ended ("" while it runs)
        self.reason = ""
        #: settle, measure, recover (the best back after a rejection), watch (the best, for a drift), done
        self.phase = "settle"
        self.candidates: list[Candidate] = []
        #: the values in force at the start (what "revert" puts back)
        self.start_values: dict[str, float] = {}
        #: the best accepted candidate so far (None: none yet)
        self.best: Candidate | None = None
        self.searches = 0
        self._dims: tuple[Dimension, ...] = ()
        self._search: Search | None = None
        self._trial: Any = None
        self._values: dict[str, float] = {}
        self._home: dict[str, float] = {}  # the values the present search began from
        self._in_search = 0  # candidates measured in the present search
        self._to_confirm: list[Candidate] = []  # the search's best, waiting for their second measure
        self._confirming: Candidate | None = None  # the candidate measured again now
        self._window = (math.nan, math.nan)
        self._due = math.nan
        self._data = RunData()
        self._data_lock = threading.Lock()
        self._unsubscribe: Callable[[], None] | None = None
        self._finished = False
        self._lock = threading.RLock()

    # ------------------------------------------------------------------ state
    @property
    def finished(self) -> bool:
        return self._finished

    @property
    def searching(self) -> bool:
        """A search is under way (not watching the best, not finished)."""
        return not self._finished and self.phase != "watch"

    def time_left(self) -> float:
        """Seconds of loop time until the present search ends (0 watching or finished)."""
        if not self.searching:
            return 0.0
        per = self.cfg.settle_s + self.cfg.window_s
        if self._confirming is not None:
            rest = len(self._to_confirm)
        else:
            rest = max(0, self.cfg.max_candidates - self._in_search - 1) + self.cfg.confirm
        return max(0.0, self._window[1] - self.host.time()) + rest * per

    # ------------------------------------------------------------------ driving it
    def _why_stop(self) -> str:
        host = self.host
        if not host.armed():
            return "the robot is disarmed"
        active = host.failsafes()
        if active:
            return f"failsafe {', '.join(active)}"
        if not host.is_pilot(self.who):
            return "its pilot is no longer the pilot"
        return ""

    def start(self) -> None:
        """The first candidate (the values in force) settles from now (pilot only, armed, no
        failsafe active, every parameter tunable within its own range)."""
        host = self.host
        host.require_pilot(self.who, "seek")
        if not host.armed():
            raise CommandRefused("seek: arm the motors first (the robot holds its setpoints while it seeks)")
        active = host.failsafes()
        if active:
            raise CommandRefused(f"seek: refused while failsafe {', '.join(active)} is active")
        if self.cfg.abort_s >= host.tracking_timeout:
            raise CommandRefused(f"seek: seek.abort_s ({self.cfg.abort_s:g} s) must be shorter than the tracking "
                                 f"failsafe's timeout ({host.tracking_timeout:g} s)")
        with self._lock:
            self._dims = check_space(self.params, host.param_field)
            self.start_values = {p.name: float(host.param_value(p.name)) for p in self.params}
            # measuring from now on; the first window is timed once the search is made (its
            # first one imports Optuna: seconds, which the loop does not wait for)
            self._unsubscribe = host.subscribe(self._on_message, TABLE_CHANNELS)
            self._begin_search(self.start_values)
            host.journal(actor_name(self.who), "seek", "", f"started over {', '.join(d.name for d in self._dims)}")

    def _on_message(self, channel: str, msg: Any) -> None:
        with self._data_lock:
            self._data.feed(channel, msg)

    def poll(self) -> bool:
        """Stop when the robot is disarmed, a failsafe is active or the pilot is gone; else
        the step due now. True once finished."""
        with self._lock:
            if self._finished:
                return True
            why = self._why_stop()
            if why:
                self.finish(why, keep=self.cfg.on_stop == "best")
                return True
            now = self.host.time()
            if self.phase in ("settle", "measure"):
                off, what = self.host.off_track(now)
                if off >= self.cfg.abort_s:
                    self._reject(now, f"rejected: lost its track ({what} off its expected response for {off:.0f} s)")
                    return self._finished
            if now + 1e-9 < self._due:
                return False
            if self.phase == "settle":
                self.phase, self._due = "measure", self._window[1]
            elif self.phase == "measure":
                self._judge(now)
            elif self.phase == "recover":
                self._next(now)
            elif self.phase == "watch":
                self._watch(now)
            return self._finished

    def _begin_search(self, values: dict[str, float]) -> None:
        """A new search whose first candidate is ``values`` (in force now), settling from the
        loop's time once the search is made."""
        self.searches += 1
        self._search = Search(self._dims, self.cfg.seed + self.searches - 1, self.cfg.startup)
        self._trial = None
        self._values = dict(values)
        self._home = dict(values)
        self._in_search = 0
        self._settle(self.host.time())

    def _settle(self, now: float) -> None:
        m0 = now + self.cfg.settle_s
        self._window = (m0, m0 + self.cfg.window_s)
        self.phase, self._due = "settle", m0

    def _measure(self, label: str) -> tuple[TableRow | None, str]:
        t0, t1 = self._window
        with self._data_lock:
            try:
                row = table_row(self._data, t0, t1, self.host.metrics, label)
            except ValueError as e:  # no power messages: said, never a zero
                return None, f"no figures ({e})"
            finally:
                self._data.drop_before(t1 - 1.0)
        if row.source != ELECTRICAL:
            return row, f"no figures (the window has no electrical readings: {row.source_label})"
        e = row.figures["energy_per_metre"]
        if not (math.isfinite(e.value) and math.isfinite(e.lo) and math.isfinite(e.hi)):
            return row, (f"no figures (no energy per metre with an interval over {row.cycles} fin cycles: "
                         "lengthen seek.window_s)")
        return row, ""

    def _off_track(self, row: TableRow) -> str:
        f, cfg = row.figures, self.cfg
        off = []
        for key, band, unit, what in (("speed_mae", cfg.speed_band, "m/s", "speed"),
                                      ("depth_mae", cfg.depth_band, "m", "depth"),
                                      ("heading_mae", cfg.heading_band, "rad", "heading")):
            v = f[key].value
            if not math.isfinite(v):
                off.append(f"no {what} error measured")
            elif v > band:
                off.append(f"{what} error {v:.3g} {unit} > {band:g}")
        return "rejected: " + ", ".join(off) if off else ""

    def _judge(self, now: float) -> None:
        """The candidate's window has ended: its figures, verdict, event and journal entry;
        then the next step."""
        k = len(self.candidates)
        values = tuple((d.name, self._values[d.name]) for d in self._dims)
        row, why = self._measure(f"seek #{k}")
        verdict = why or (self._off_track(row) if row is not None else "") or "accepted"
        energy = row.figures["energy_per_metre"] if row is not None and not why else None
        line = segment_line(row) if row is not None else why
        cand = Candidate(k, self.searches - 1, values, energy, verdict, line)
        if self._confirming is not None:  # a second measure: the values of the one it measures again
            self._record_again(replace(cand, confirms=self._confirming.index), row, now)
        else:
            self._record(cand, row, now)

    def _reject(self, now: float, verdict: str) -> None:
        """The candidate under test rejected before its window ends (``verdict`` says why)."""
        k = len(self.candidates)
        with self._data_lock:
            self._data.drop_before(now - 1.0)
        values = tuple((d.name, self._values[d.name]) for d in self._dims)
        self._window = (self._window[0], min(self._window[1], now))
        cand = Candidate(k, self.searches - 1, values, None, verdict, verdict)
        if self._confirming is not None:
            self._record_again(replace(cand, confirms=self._confirming.index), None, now)
        else:
            self._record(cand, None, now)

    def _record(self, cand: Candidate, row: TableRow | None, now: float) -> None:
        """``cand`` measured: the search told, its event and journal entry; then the next step."""
        values, energy = cand.values, cand.energy
        self.candidates.append(cand)
        search = self._search
        assert search is not None
        if self._trial is not None:
            search.tell(self._trial, energy.value if cand.accepted and energy is not None else None)
        elif cand.accepted and energy is not None:
            search.add(dict(values), energy.value)
        self._trial = None
        self._in_search += 1
        best = self.best is None or (cand.accepted and energy is not None and self.best.energy is not None
                                     and energy.value < self.best.energy.value)
        if cand.accepted and best:
            self.best = cand
        self._publish_candidate(cand, row, now)
        if not cand.accepted:
            back = self._fallback()
            if back != self._values:
                self._set(back)
                self.host.restart_expected()  # judged again from here, on the values put back
                self._settle(now)
                self.phase, self._due = "recover", self._window[0]
                return
        self._next(now)

    def _publish_candidate(self, cand: Candidate, row: TableRow | None, now: float) -> None:
        """``cand``'s event and journal entry."""
        k, values, energy, verdict = cand.index, cand.values, cand.energy, cand.verdict
        info: dict[str, Any] = {
            "index": k, "search": cand.search, "values": dict(values), "verdict": verdict,
            "accepted": cand.accepted, "best": self.best is cand, "confirms": cand.confirms,
            "t0": self._window[0], "t1": self._window[1],
            "figures": None if row is None else {
                key: {"value": _json(row.figures[key].value), "lo": _json(row.figures[key].lo),
                      "hi": _json(row.figures[key].hi)} for key in CANDIDATE_FIGURES},
        }
        result = estimate_text(energy) if energy is not None else "no figures"
        again = f", #{cand.confirms} again" if cand.confirms is not None else ""
        message = f"seek #{k} ({values_text(values)}{again}): {result}; {verdict}"
        self.host.publish_event(Event(now, "seek", "candidate", message,
                                      "info" if cand.accepted else "warning", info))
        self.host.journal(actor_name(self.who), f"seek #{k}", values_text(values) + again, f"{result}; {verdict}")

    def _fallback(self) -> dict[str, float]:
        """The best so far, else the values the search began from."""
        return dict(self.best.values) if self.best is not None else dict(self._home)

    def _set(self, values: Mapping[str, float]) -> None:
        changes = {k: v for k, v in values.items() if self.host.param_value(k) != v}
        if changes:
            self.host.set_params(self.who, changes)
        self._values = {**self._values, **values}

    def _next(self, now: float) -> None:
        """The next candidate of the search, or its end."""
        search = self._search
        assert search is not None
        while self._in_search < self.cfg.max_candidates:
            trial, values = search.ask()
            try:
                self._set(values)
            except CommandRefused as e:  # a block's own check (e.g. the MPC's) refused it
                search.tell(trial, None)
                self._in_search += 1
                k = len(self.candidates)
                vals = tuple(values.items())
                self.candidates.append(Candidate(k, self.searches - 1, vals, None, f"refused: {e}", str(e)))
                self.host.publish_event(Event(now, "seek", "candidate", f"seek #{k} ({values_text(vals)}): "
                                              f"refused: {e}", "warning",
                                              {"index": k, "search": self.searches - 1, "values": values,
                                               "verdict": f"refused: {e}", "accepted": False, "best": False,
                                               "figures": None}))
                continue
            self._trial = trial
            self._settle(now)
            return
        self._end_search(now)

    def _end_search(self, now: float) -> None:
        """The search's candidates measured: its best measured again (module docstring)."""
        search = self.searches - 1
        ranked = sorted((c for c in self.candidates if c.search == search and c.confirms is None and c.accepted
                         and c.energy is not None), key=lambda c: c.energy.value if c.energy else math.inf)
        self._to_confirm = ranked[:self.cfg.confirm]
        self._confirm_next(now)

    def _confirm_next(self, now: float) -> None:
        if not self._to_confirm:
            self._confirming = None
            again = [c for c in self.candidates if c.search == self.searches - 1 and c.confirms is not None
                     and c.accepted and c.energy is not None]
            if again:  # else the first measures' best stands
                self.best = min(again, key=lambda c: c.energy.value if c.energy else math.inf)
            self._search_done(now)
            return
        self._confirming = self._to_confirm.pop(0)
        self._set(dict(self._confirming.values))
        self._settle(now)

    def _record_again(self, cand: Candidate, row: TableRow | None, now: float) -> None:
        """A second measure: its event and journal entry (the search is not told); the next."""
        self.candidates.append(cand)
        self._publish_candidate(cand, row, now)
        if not cand.accepted:
            self.host.restart_expected()  # the next values are judged from the robot's present state
        self._confirm_next(now)

    def _search_done(self, now: float) -> None:
        best = self.best
        self._set(self._fallback())
        self.host.publish_event(Event(now, "seek", "search", (
            f"seek: search {self.searches} done; best " + (
                f"{values_text(best.values)}: {estimate_text(best.energy)}" if best is not None and best.energy
                else "none (no candidate accepted)")), "info", {"search": self.searches, "best": self._best_data()}))
        if best is None or not self.cfg.drift_check:
            self.finish("completed", keep=True)
            return
        self._settle(now)
        self.phase, self._due = "watch", self._window[1]

    def _watch(self, now: float) -> None:
        """A window of the best in force has ended: a drift outside its interval seeks again."""
        best = self.best
        assert best is not None and best.energy is not None
        row, why = self._measure("seek drift check")
        e = best.energy
        if row is not None and not why and not self._off_track(row):
            v = row.figures["energy_per_metre"].value
            if math.isfinite(e.lo) and math.isfinite(e.hi) and not e.lo <= v <= e.hi:
                message = (f"seek: energy per metre {v:.1f} J/m drifted outside the best's interval "
                           f"[{e.lo:.1f}, {e.hi:.1f}]")
                if self.searches < self.cfg.max_seeks:
                    self.host.publish_event(Event(now, "seek", "drift", message + "; seeking again", "warning",
                                                  {"value": v, "lo": e.lo, "hi": e.hi}))
                    self.best = None  # the robot changed: what was measured before no longer holds
                    self._begin_search(dict(best.values))
                    return
                self.host.publish_event(Event(now, "seek", "drift", message + f"; {self.cfg.max_seeks} searches "
                                              "done, not seeking again", "warning", {"value": v}))
        self._settle(now)
        self.phase, self._due = "watch", self._window[1]

    def _best_data(self) -> dict[str, Any] | None:
        b = self.best
        if b is None or b.energy is None:
            return None
        return {"index": b.index, "values": dict(b.values), "energy_per_metre": {
            "value": _json(b.energy.value), "lo": _json(b.energy.lo), "hi": _json(b.energy.hi)}}

    def finish(self, reason: str = "stopped", keep: bool = True) -> None:
        """End it now, the best (``keep``) or the values it found in force (once, whichever
        thread comes first)."""
        with self._lock:
            if self._finished:
                return
            self._finished = True
            self.reason = reason
            self.phase = "done"
            host = self.host
            if self._unsubscribe is not None:
                self._unsubscribe()
            values = self._fallback() if keep else dict(self.start_values)
            try:
                changes = {k: v for k, v in values.items() if host.param_value(k) != v}
                if changes:
                    host.set_params(LOCAL, changes)
            except Exception:  # the loop has stopped: nothing to put back into
                log.exception("seek: putting back %s failed", values_text(values.items()))
            left = "the best" if keep and self.best is not None else "the values it found"
            host.journal(actor_name(self.who), "seek", "running", f"ended ({reason}); {left} in force")
            host.publish_event(Event(host.time(), "seek", "end",
                                     f"seek ended: {reason}; {len(self.candidates)} candidates measured; "
                                     f"{left} in force ({values_text(values.items())})",
                                     "info" if reason in ("completed",) or reason.startswith("stopped by")
                                     else "warning",
                                     {"reason": reason, "candidates": len(self.candidates), "kept": keep,
                                      "values": values, "best": self._best_data()}))

    def wait(self, poll_s: float = 0.2, until_watching: bool = True) -> None:
        """Block until it ends (or, ``until_watching``, until its search is done)."""
        while not self.poll() and not (until_watching and self.phase == "watch"):
            time.sleep(poll_s)
