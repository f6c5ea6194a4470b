"""The player: the other end of the telemetry stream, publishing a session onto it.

A :class:`Player` publishes a session's messages onto a
:class:`~ucat_console.telemetry.TelemetryStream` on its own clock, so every subscriber
(the 3-D view, the plots, the metrics) shows a recording exactly as it showed live. It
reads one part file, or every part of a split session as one recording through
:class:`~ucat_console.backend.sessions.reader.SessionParts` (playing, seeking, stepping
and jumping across the part boundaries).

Playback position ``position`` is on the recorded stream's clock (seconds, the messages'
``t``). Invariant: every message with a time at or before the position has been
published (or summarised by the state published on a seek). Controls: ``play``/``pause``,
``speed`` (0.1x to 5x), ``loop``, ``seek(t)`` (publishes the latest message of every
channel at ``t`` first), ``step(+1/-1)`` (one frame: the next/previous message on the
frame channel, by default the body state), ``next_event``/``prev_event`` (recorded events
and review markers). Markers added during review go to a sidecar file
(:mod:`ucat_console.backend.sessions.markers`); the session files are never modified.

:meth:`Player.advance` is the whole playback clock: the playing thread calls it with the
wall time elapsed; tests and offline tools may call it directly.
"""

from __future__ import annotations

import bisect
import logging
import threading
import time
from typing import Any, Callable, Collection, Iterator

from ucat_console.backend.sessions.markers import Marker, MarkerStore
from ucat_console.backend.sessions.reader import Record, SessionSource
from ucat_console.telemetry.channels import BODY_STATE, CHANNELS, EVENTS
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.stream import TelemetryStream

log = logging.getLogger(__name__)

MIN_SPEED = 0.1
MAX_SPEED = 5.0
_MAX_WAIT = 0.05  # s, longest sleep of the playing thread between checks


def check_speed(speed: float) -> float:
    if isinstance(speed, bool) or not isinstance(speed, (int, float)) or not (
        MIN_SPEED <= speed <= MAX_SPEED
    ):
        raise ValueError(f"speed: {speed!r} is out of range; allowed: [{MIN_SPEED}, {MAX_SPEED}]")
    return float(speed)


class Player:
    """Plays a session (a :class:`SessionReader` or :class:`SessionParts`) onto ``stream``.
    Thread-safe; ``close()`` when done (the reader stays open: its owner closes it)."""

    def __init__(
        self,
        reader: SessionSource,
        stream: TelemetryStream,
        *,
        speed: float = 1.0,
        loop: bool = False,
        frame_channel: str = BODY_STATE,
        clock: Callable[[], float] = time.monotonic,
        on_error: Callable[[str], None] | None = None,
    ) -> None:
        """``on_error(text)``: playing stopped on a failure (a damaged file, the memory cap),
        called from the playing thread; ``error`` keeps the text."""
        if frame_channel not in CHANNELS:
            raise ValueError(f"frame_channel: unknown telemetry channel {frame_channel!r}")
        self.reader = reader
        self.stream = stream
        self.frame_channel = frame_channel
        self._speed = check_speed(speed)
        self.loop = bool(loop)
        self._clock = clock
        self._lock = threading.RLock()
        self._wake = threading.Event()
        self._thread: threading.Thread | None = None
        self._playing = False
        self._start_ns = reader.start_ns
        self._end_ns = reader.end_ns
        self._pos_ns = self._start_ns - 1  # nothing published yet
        self._iter: Iterator[Record] | None = None
        self._next: Record | None = None
        self._events = reader.event_index()  # shared with everyone reading this session
        self._on_error = on_error
        self.error = ""
        self.markers = MarkerStore.shared(reader.path.parent, reader.session_id)

    # ------------------------------------------------------------------ state
    @property
    def start(self) -> float:
        return self.reader.from_ns(self._start_ns)

    @property
    def end(self) -> float:
        return self.reader.from_ns(self._end_ns)

    @property
    def position(self) -> float:
        """Playback position (stream seconds); before ``start`` until the first publish."""
        return self.reader.from_ns(self._pos_ns)

    @property
    def playing(self) -> bool:
        return self._playing

    @property
    def speed(self) -> float:
        return self._speed

    @speed.setter
    def speed(self, value: float) -> None:
        v = check_speed(value)
        with self._lock:
            self._speed = v
        self._wake.set()

    @property
    def at_end(self) -> bool:
        return self._pos_ns >= self._end_ns

    # ------------------------------------------------------------------ publishing
    def _publish(self, rec: Record) -> None:
        self.stream.publish(rec.channel, rec.message)

    def _restart(self) -> None:
        """Continue reading after the position."""
        self._iter = self.reader.records(start_ns=self._pos_ns + 1)
        self._next = None

    def _peek(self) -> Record | None:
        if self._next is None:
            if self._iter is None:
                self._restart()
            assert self._iter is not None
            self._next = next(self._iter, None)
            if self._next is None:
                self._iter = iter(())
        return self._next

    def _take(self) -> Record:
        rec = self._next
        assert rec is not None
        self._next = None
        return rec

    def _publish_until(self, target_ns: int) -> int:
        n = 0
        while True:
            rec = self._peek()
            if rec is None or rec.log_time_ns > target_ns:
                return n
            self._take()
            self._publish(rec)
            self._pos_ns = max(self._pos_ns, rec.log_time_ns)
            n += 1

    def advance(self, dt: float) -> int:
        """Play ``dt`` seconds of wall time at the current speed; returns messages published.

        At the end the player stops, or with ``loop`` starts again from the beginning.
        """
        if not dt >= 0.0:
            raise ValueError(f"dt: {dt!r} must be a non-negative number of seconds")
        with self._lock:
            target = self._pos_ns + round(dt * self._speed * 1e9)
            n = self._publish_until(target)
            if self._peek() is not None:
                self._pos_ns = max(self._pos_ns, target)
                return n
            # the end
            over = target - self._end_ns
            self._pos_ns = max(self._pos_ns, self._end_ns)
            if not self.loop:
                self._playing = False
                return n
            n += len(self._seek_ns(self._start_ns))
            rest = max(0, min(over, self._end_ns - self._start_ns))  # wrap around once at most
            n += self._publish_until(self._start_ns + rest)
            return n

    # ------------------------------------------------------------------ controls
    def play(self) -> None:
        """Start playing (from the start again when at the end)."""
        with self._lock:
            if self._playing:
                return
            if self.at_end:
                self._seek_ns(self._start_ns)
            self._playing = True
            self.error = ""
            self._wake.clear()
            self._thread = threading.Thread(target=self._run, name="player", daemon=True)
            self._thread.start()

    def pause(self) -> None:
        with self._lock:
            self._playing = False
            thread, self._thread = self._thread, None
        self._wake.set()
        if thread is not None and thread is not threading.current_thread():
            thread.join()

    def close(self) -> None:
        self.pause()

    def _run(self) -> None:
        last = self._clock()
        try:
            while True:
                with self._lock:
                    if not self._playing:
                        return
                    now = self._clock()
                    self.advance(max(0.0, now - last))
                    last = now
                    if not self._playing:
                        return
                    nxt = self._peek()
                    wait = _MAX_WAIT
                    if nxt is not None:
                        wait = (nxt.log_time_ns - self._pos_ns) * 1e-9 / self._speed
                        wait = min(max(wait, 0.0), _MAX_WAIT)
                if wait > 0.0:
                    self._wake.wait(wait)
                    self._wake.clear()
        except Exception as e:
            self._playing = False
            if isinstance(e, ValueError):  # the file or the memory cap: the reason is the message
                log.warning("playback of %s stopped: %s", self.reader.path, e)
                self.error = str(e)
            else:
                log.exception("playback of %s failed", self.reader.path)
                self.error = f"playback failed: {type(e).__name__}: {e}"
            if self._on_error is not None:
                try:
                    self._on_error(self.error)
                except Exception:
                    log.exception("reporting the playback failure failed")

    def _seek_ns(self, ns: int) -> dict[str, Any]:
        ns = min(max(ns, self._start_ns), self._end_ns)
        state = self.reader.state_records_at_ns(ns)
        for rec in sorted(state.values(), key=lambda r: r.log_time_ns):
            self._publish(rec)
        self._pos_ns = ns
        self._restart()
        return {c: r.message for c, r in state.items()}

    def seek(self, t: float) -> dict[str, Any]:
        """Go to ``t`` (clamped to the session), publishing the latest message of every
        channel at or before it; returns that state. Playing continues from there."""
        with self._lock:
            state = self._seek_ns(self.reader.to_ns(t))
        self._wake.set()
        return state

    def step(self, n: int = 1) -> bool:
        """Pause, then move ``n`` frames (+1 forward, -1 back); False when there is none."""
        if n not in (1, -1):
            raise ValueError(f"step: {n!r} must be +1 or -1")
        self.pause()
        with self._lock:
            if n > 0:
                frames = self.reader.records([self.frame_channel], start_ns=self._pos_ns + 1)
                frame = next(frames, None)
                if frame is None:
                    return False
                self._publish_until(frame.log_time_ns)
                self._pos_ns = frame.log_time_ns
                return True
            frame = next(
                self.reader.records([self.frame_channel], end_ns=self._pos_ns, reverse=True), None
            )
            if frame is None:
                return False
            self._seek_ns(frame.log_time_ns)
            return True

    # ------------------------------------------------------------------ events and markers
    def _jump_targets(self, levels: Collection[str] | None = None) -> list[tuple[int, Marker | None]]:
        """Recorded events (None: read when jumped to) and markers, in time order."""
        targets: list[tuple[int, Marker | None]] = [(ns, None) for ns in self._events.at_levels(levels)]
        targets += [(self.reader.to_ns(m.t), m) for m in self.markers.markers]
        return sorted(targets, key=lambda x: x[0])

    def _jump(self, target: tuple[int, Marker | None], levels: Collection[str] | None) -> Event | Marker:
        """Seek to a jump target; the marker, or the event recorded there."""
        ns, what = target
        self._seek_ns(ns)
        if what is not None:
            return what
        for r in self.reader.records([EVENTS], start_ns=ns, end_ns=ns + 1):
            if levels is None or r.message.level in levels:
                return r.message
        raise ValueError(f"{self.reader.path}: no event at {ns} ns, where its index has one")

    def next_event(self, levels: Collection[str] | None = None) -> Event | Marker | None:
        """Seek to the next recorded event (of one of ``levels``; default any) or marker
        after the position (None: none)."""
        with self._lock:
            targets = self._jump_targets(levels)
            i = bisect.bisect_right([ns for ns, _ in targets], self._pos_ns)
            if i >= len(targets):
                return None
            what = self._jump(targets[i], levels)
        self._wake.set()
        return what

    def prev_event(self, levels: Collection[str] | None = None) -> Event | Marker | None:
        """Seek to the latest recorded event (of one of ``levels``) or marker before the position."""
        with self._lock:
            targets = self._jump_targets(levels)
            i = bisect.bisect_left([ns for ns, _ in targets], self._pos_ns) - 1
            if i < 0:
                return None
            what = self._jump(targets[i], levels)
        self._wake.set()
        return what

    def add_marker(self, note: str = "", t: float | None = None) -> Marker:
        """A review marker at ``t`` (default: the position), saved to the sidecar file."""
        return self.markers.add(self.position if t is None else t, note)
