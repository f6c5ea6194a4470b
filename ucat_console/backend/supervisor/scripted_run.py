"""A scripted manoeuvre on a running robot: :class:`ScriptRun`.

The pilot's command (docs/manoeuvres.md): segment after segment of a
:class:`~ucat_console.control.scripted.Script`, it gives the segment's setpoints and mode
through the operator's commands (checked as any operator's: the envelope, the failsafes'
holds), drops a marker where each segment's settle and measure windows start, and at the
end of each measure window publishes the segment's figures as an event (source
``"manoeuvre"``, code ``"segment"``): energy per metre with its bootstrap interval, power,
speed and the speed, depth and heading tracking errors, computed by
:func:`~ucat_console.backend.review.metrics.table_row` (the figures' one definition) from the
telemetry it collects over the window. The recorder records them; Review and
``ucat-console sessions compare --segments marker`` cut the session at the markers.

It records (a session already being recorded is kept, else it starts one and stops it at
the end). It stops at once when the robot is disarmed, a failsafe is active or its pilot is
no longer the pilot: everything it does happens in :meth:`ScriptRun.poll`, which checks
these first; stopping puts back the mode and setpoints it found, drops an end marker and
publishes an event (code ``"manoeuvre"``) saying why it ended. ``start`` / ``poll`` /
``finish`` drive it without blocking (the supervisor polls it after every chunk of the
loop, and at once on a disarm); :meth:`ScriptRun.wait` blocks (the command line).

The run reaches the console through a :class:`ScriptHost`, not the supervisor.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable

from ucat_console.backend.access import LOCAL, Actor
from ucat_console.backend.loop.commands import CommandRefused
from ucat_console.backend.review.metrics import TABLE_CHANNELS, MetricsConfig, RunData, TableRow, table_row
from ucat_console.control.allocation import BodySetpoints
from ucat_console.control.scripted import Script, at
from ucat_console.telemetry.events import Event

log = logging.getLogger(__name__)

#: the figures a segment's event carries (keys of ``backend.review.metrics.FIGURES``)
SEGMENT_FIGURES = ("energy_per_metre", "power", "cost_of_transport", "mech_energy_per_metre", "speed",
                   "speed_mae", "depth_mae", "heading_mae", "st_mae", "st_in")


@dataclass(frozen=True)
class ScriptHost:
    """What a scripted manoeuvre uses of the console: the operator's commands (each checked
    as the operator's own), and the state it follows."""

    require_pilot: Callable[[Actor, str], None]
    is_pilot: Callable[[Actor], bool]
    armed: Callable[[], bool]
    #: the active failsafes' names
    failsafes: Callable[[], tuple[str, ...]]
    mode: Callable[[], str]
    set_mode: Callable[[Actor, str], None]
    setpoints: Callable[[], BodySetpoints]
    set_setpoints: Callable[..., None]  # (who, velocity=, depth=, yaw_rate=)
    #: the session being recorded, "" when none
    recording: Callable[[], str]
    start_recording: Callable[[Actor, str], str]
    stop_recording: Callable[[Actor], list[Path]]
    add_marker: Callable[[Actor, str], Any]
    publish_event: Callable[[Event], None]
    #: ``subscribe(fn, channels)`` on the telemetry stream; returns the unsubscribe
    subscribe: Callable[[Callable[[str, Any], None], Iterable[str]], Callable[[], None]]
    #: the loop's time (s)
    time: Callable[[], float]
    metrics: MetricsConfig


def _json(x: float) -> float | None:
    return x if math.isfinite(x) else None


def _fmt(x: float, f: str) -> str:
    return format(x, f) if math.isfinite(x) else "–"


def segment_line(row: TableRow) -> str:
    """``12.3 J/m [11.0, 13.4] (electrical (battery)); speed 0.198 m/s; errors: speed ...``"""
    f = row.figures
    e = f["energy_per_metre"]
    heading = math.degrees(f["heading_mae"].value) if math.isfinite(f["heading_mae"].value) else math.nan
    return (f"{_fmt(e.value, '.1f')} J/m [{_fmt(e.lo, '.1f')}, {_fmt(e.hi, '.1f')}] ({row.source_label}); "
            f"speed {_fmt(f['speed'].value, '.3f')} m/s; errors: speed {_fmt(f['speed_mae'].value, '.3f')} m/s, "
            f"depth {_fmt(f['depth_mae'].value, '.3f')} m, heading {_fmt(heading, '.1f')}°")


class ScriptRun:
    """One scripted manoeuvre, once (module docstring)."""

    def __init__(self, host: ScriptHost, who: Actor, script: Script) -> None:
        self.host = host
        self.who = who
        self.script = script
        self.session = ""
        self.paths: list[Path] = []
        #: why it ended ("" while it runs)
        self.reason = ""
        #: the figures of each segment measured so far (its event's data)
        self.results: list[dict[str, Any]] = []
        #: each measured segment in a line: its label and figures (what the page lists)
        self.lines: list[str] = []
        self._own_session = False
        self._mode = ""
        self._setpoints: BodySetpoints | None = None
        self._t0 = math.nan
        self._at = -1  # the phase reached: 2 k (settle of segment k), 2 k + 1 (its measure), 2 n (done)
        self._data = RunData()
        self._data_lock = threading.Lock()
        self._unsubscribe: Callable[[], None] | None = None
        self._finished = False
        self._lock = threading.RLock()  # the supervisor's thread polls, a disarming one and a waiting caller too

    # ------------------------------------------------------------------ state
    @property
    def name(self) -> str:
        return self.script.name

    @property
    def duration(self) -> float:
        return self.script.duration

    @property
    def elapsed(self) -> float:
        return 0.0 if math.isnan(self._t0) else max(0.0, self.host.time() - self._t0)

    @property
    def progress(self) -> float:
        """Share of the manoeuvre done (0-1)."""
        return 1.0 if self._finished else min(1.0, self.elapsed / self.duration)

    @property
    def segment(self) -> int:
        """The segment running (from 0; ``len(segments)`` once done)."""
        return max(self._at, 0) // 2

    @property
    def finished(self) -> bool:
        return self._finished

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

    def start(self) -> str:
        """Start recording (unless recording) and the first segment (pilot only, armed, no
        failsafe active); returns the session id."""
        host = self.host
        what = f"manoeuvre {self.name}"
        host.require_pilot(self.who, what)
        if not host.armed():
            raise CommandRefused(f"{what}: arm the motors first")
        active = host.failsafes()
        if active:
            raise CommandRefused(f"{what}: refused while failsafe {', '.join(active)} is active")
        with self._lock:
            self._mode, self._setpoints = host.mode(), host.setpoints()
            self.session = host.recording()
            if not self.session:
                self.session = host.start_recording(self.who, what)
                self._own_session = True
            self._unsubscribe = host.subscribe(self._on_message, TABLE_CHANNELS)
            self._t0 = host.time()
            try:
                self._advance(self._t0)
            except BaseException:
                self.finish("it could not start")
                raise
        return self.session

    def _on_message(self, channel: str, msg: Any) -> None:
        with self._data_lock:
            self._data.feed(channel, msg)

    def poll(self) -> bool:
        """Stop when the robot is disarmed, a failsafe is active or the pilot is gone; else
        give what the script asks now. True once finished."""
        with self._lock:
            if self._finished:
                return True
            why = self._why_stop()
            if why:
                self.finish(why)
                return True
            self._advance(self.host.time())
            return self._finished

    def _advance(self, now: float) -> None:
        """Every phase from the last one reached up to the one of loop time ``now``."""
        script = self.script
        step = at(script, max(0.0, now - self._t0))
        target = 2 * step.index + (1 if step.phase == "measure" else 0)
        n = len(script.segments)
        while self._at < target:
            self._at += 1
            k, measuring = divmod(self._at, 2)
            if k > 0 and not measuring:  # the previous segment's measure window has ended
                self._publish_figures(k - 1)
            if k >= n:
                self.finish("completed")
                return
            seg = script.segments[k]
            where = f"{self.name} #{k + 1}/{n} {seg.label}"
            if measuring:
                self.host.add_marker(self.who, f"{where}: measure")
                continue
            mode = seg.mode or self._mode
            if self.host.mode() != mode:
                self.host.set_mode(self.who, mode)
            sp = seg.setpoints
            self.host.set_setpoints(self.who, velocity=sp.velocity, depth=sp.depth, yaw_rate=sp.yaw_rate)
            self.host.add_marker(self.who, f"{where}: settle")

    def _publish_figures(self, k: int) -> None:
        script = self.script
        seg = script.segments[k]
        m0 = self._t0 + script.starts[k] + seg.settle_s
        m1 = m0 + seg.measure_s
        label = f"{self.name} #{k + 1} {seg.label}"
        with self._data_lock:
            data = self._data
            try:
                row = table_row(data, m0, m1, self.host.metrics, label)
            except ValueError as e:  # no power messages: said, never a zero
                row = None
                why = str(e)
            data.drop_before(m1 - 1.0)
        info: dict[str, Any] = {
            "manoeuvre": self.name, "index": k, "label": seg.label, "mode": seg.mode or self._mode,
            "setpoints": {"velocity": seg.setpoints.velocity, "depth": seg.setpoints.depth,
                          "yaw_rate": seg.setpoints.yaw_rate},
            "t0": m0, "t1": m1,
        }
        if row is None:
            info.update(figures=None, error=why)
            line = f"{seg.label}: no figures ({why})"
        else:
            info.update(cycles=row.cycles, power_source=row.source_label, confidence=self.host.metrics.confidence,
                        figures={key: {"value": _json(row.figures[key].value), "lo": _json(row.figures[key].lo),
                                       "hi": _json(row.figures[key].hi)} for key in SEGMENT_FIGURES})
            line = f"{seg.label}: {segment_line(row)}"
        message = f"{self.name} #{k + 1} {line}"
        self.results.append(info)
        self.lines.append(line)
        self.host.publish_event(Event(self.host.time(), "manoeuvre", "segment", message, "info", info))

    def finish(self, reason: str = "stopped") -> list[Path]:
        """End it now: the mode and setpoints it found put back, an end marker, its own
        recording stopped (once, whichever thread comes first); the session's files."""
        with self._lock:
            if self._finished:
                return self.paths
            self._finished = True
            self.reason = reason
            host = self.host
            if self._unsubscribe is not None:
                self._unsubscribe()
            try:
                try:
                    if self._mode and host.mode() != self._mode:
                        host.set_mode(LOCAL, self._mode)
                    sp = self._setpoints
                    if sp is not None and host.setpoints() != sp:
                        host.set_setpoints(LOCAL, velocity=sp.velocity, depth=sp.depth, yaw_rate=sp.yaw_rate)
                except CommandRefused as e:  # a failsafe's hold keeps the setpoints: it owns them now
                    log.warning("manoeuvre %s: the setpoints it found were not put back: %s", self.name, e)
                except Exception:  # the loop has stopped: nothing to put back into
                    log.exception("manoeuvre %s: putting back the mode and setpoints failed", self.name)
                done = len(self.results)
                host.add_marker(LOCAL, f"{self.name}: end ({reason})")
                host.publish_event(Event(host.time(), "manoeuvre", "manoeuvre",
                                         f"manoeuvre {self.name} ended: {reason}; {done} of "
                                         f"{len(self.script.segments)} segments measured",
                                         "info" if reason == "completed" else "warning",
                                         {"manoeuvre": self.name, "reason": reason, "measured": done,
                                          "segments": len(self.script.segments)}))
            finally:
                if self._own_session and host.recording() == self.session:
                    self.paths = host.stop_recording(LOCAL)
            return self.paths

    def wait(self, poll_s: float = 0.2) -> list[Path]:
        """Block until it ends (a supervisor running in its own thread)."""
        while not self.poll():
            time.sleep(poll_s)
        return self.paths
