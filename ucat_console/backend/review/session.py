"""One page's review of recorded sessions, without the page: what the Review tab renders.

A :class:`ReviewSession` lists the sessions folder, repairs a truncated session, opens a
session (every part of it, from the console's shared readers) into a
:class:`~ucat_console.backend.sessions.player.Player` publishing onto ``stream``, plays,
seeks, steps and jumps to events and markers, adds review markers, exports the channels of a
time window as a zip of CSV files, and runs a counterfactual replay with other MPC weights
in the console's replay slot. Every command raises ValueError naming what is wrong (a bad
value, no session open) and changes nothing then; what it did is described by its return
value and by :attr:`said` (the last sentence for the operator). Names a page sends are plain
names inside the sessions folder (a path is refused).

A session split into parts (``<id>_001.mcap``, ``_002`` ...) is read as one recording
(:class:`~ucat_console.backend.sessions.reader.SessionParts`), so playing, seeking, frame
steps, event jumps and counterfactual replay run across the part boundaries. A truncated
part is repaired here (the session then opens; the original stays beside it, listed as
``<part>.orig.mcap``); only when ``may_repair()`` allows (the pilot's page), and a part
being recorded never (:mod:`~ucat_console.backend.sessions.repair`). A counterfactual replay
runs in a child process at a lower CPU priority
(:class:`~ucat_console.backend.sessions.replay_job.ReplayJob`), one at a time per console
(its :class:`~ucat_console.backend.sessions.replay_job.ReplaySlot`).

With the console's run library (:class:`RunsAccess`, the supervisor's methods for this page)
it lists the runs a query finds, sorted (:meth:`ReviewSession.find_runs`; a bad query is
refused with the library's error and the last list stands), writes a run's tags and notes,
reads a run's report file for the page to download, and gives a figure's trend over the runs
found (:meth:`ReviewSession.trend`).

The page (``ui.playback.PlaybackPanel``) renders it: the inputs, the plots and the robot of
the stream; it runs the commands that read files in the page's jobs. Tests drive it directly.
"""

from __future__ import annotations

import io
import math
import tempfile
import threading
import time
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Collection

from ucat_console.backend.review import trend as trends
from ucat_console.backend.sessions import export, files, images, index, repair
from ucat_console.backend.sessions.markers import Marker, check_note
from ucat_console.backend.sessions.player import Player, check_speed
from ucat_console.backend.sessions.reader import SessionParts
from ucat_console.backend.sessions.replay import ReplayResult, parse_weights, recorded_config, replay_config
from ucat_console.backend.sessions.replay_job import ReplayJob, ReplaySlot
from ucat_console.backend.sessions.shared import SharedReaders
from ucat_console.telemetry.channels import CHANNELS
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.stream import TelemetryStream

#: a page adds at most one review marker this often (s)
MARKER_INTERVAL = 0.5


@dataclass(frozen=True)
class Export:
    """A window of a session's channels as CSV files, zipped."""

    name: str  # the zip's name, without ``.zip``
    content: bytes
    rows: dict[str, int]  # channel -> rows
    start: float  # s from the session's start
    end: float


#: the largest report file a page downloads (bytes)
MAX_REPORT_BYTES = 64 * 1024 * 1024


@dataclass(frozen=True)
class RunsAccess:
    """What a page's review may do with the run library: the supervisor's methods, bound
    to the page (who writes is checked there)."""

    find: Callable[[object, object, object], list[Any]]  # (query, sort, desc) -> RunView list
    refresh: Callable[[], Any]
    set_tags: Callable[[object, object], tuple[str, ...]]  # (session id, changes)
    set_notes: Callable[[object, object], str]  # (session id, notes)
    report: Callable[[object], Path | None]  # session id -> its report file
    #: (query, figure, axis) -> the library's TrendPoint list (None: no trends here)
    trend: Callable[[object, object, object], list[Any]] | None = None


@dataclass(frozen=True)
class ReplayEnd:
    """How this review's counterfactual replay ended."""

    result: ReplayResult | None
    weights: dict[str, float]
    cancelled: bool
    cancelled_by: str | None
    error: str


class ReviewSession:
    """One page's review (module docstring).

    ``readers``: the console's shared readers (and its memory budget); ``replay_slot``: the
    console's one replay at a time; ``may_repair()`` raises PermissionError when this review
    may not repair; ``may_replay()`` is true when this review's replay pre-empts another
    (the pilot's); ``sessions()`` the folder's listing (default: read it each time);
    ``on_play_error(text)``: the player stopped on a failure (its thread)."""

    def __init__(self, directory: str | Path | None, stream: TelemetryStream, *,
                 readers: SharedReaders | None = None, replay_slot: ReplaySlot | None = None,
                 may_repair: Callable[[], None] = lambda: None,
                 may_replay: Callable[[], bool | None] = lambda: None,
                 sessions: Callable[[], index.Listing] | None = None,
                 on_play_error: Callable[[str], None] = lambda text: None,
                 clock: Callable[[], float] = time.monotonic, runs: RunsAccess | None = None) -> None:
        self.directory = files.sessions_dir(directory)
        self.stream = stream
        self.readers = readers if readers is not None else SharedReaders()
        self.replay_slot = replay_slot if replay_slot is not None else ReplaySlot(self.readers.budget.config)
        self.may_repair = may_repair
        self.may_replay = may_replay
        self._sessions = sessions or (lambda: index.scan(self.directory, self.readers.budget))
        self._on_play_error = on_play_error
        self._clock = clock
        self._lock = threading.RLock()
        self.reader: SessionParts | None = None
        self.player: Player | None = None
        self.speed = 1.0  # the last speed accepted
        self.loop = False
        self.job: ReplayJob | None = None
        self.job_weights: dict[str, float] = {}
        self._last_marker = -math.inf
        self.said = ""
        self.runs = runs
        #: the run list's query, sort field and direction last accepted
        self.query: tuple[str, str, bool] = ("", "start", True)

    # ------------------------------------------------------------------ the folder
    def listing(self) -> index.Listing:
        return self._sessions()

    def _name(self, name: object) -> str:
        """``name`` when it is a plain name (a session id or a file name), else ValueError."""
        if not isinstance(name, str) or not name or "/" in name or "\\" in name or name in (".", ".."):
            raise ValueError(f"session: {name!r} is not a session or a file name in {self.directory}")
        return name

    def _path(self, name: str) -> Path:
        p = files.inside_sessions(self.directory / self._name(name), self.directory)
        if not p.is_file():
            raise ValueError(f"{name}: no such session file in {self.directory}")
        return p

    def files_of(self, name: str) -> list[Path]:
        """The files ``name`` names: a part file, or every part of a session id."""
        if self._name(name).endswith(files.SUFFIX):
            return [self._path(name)]
        parts = files.part_paths(name, self.directory)
        if not parts:
            raise ValueError(f"session {name!r}: no files in {self.directory}")
        return [p for _, p in sorted(parts.items())]

    def repair(self, name: str) -> list[repair.RepairReport]:
        """Repair the truncated files of a session (or one named part file); only when
        ``may_repair()`` allows, and never a part being recorded."""
        self.may_repair()
        paths = self.files_of(name)
        budget = self.readers.budget
        todo = [p for p in paths if len(paths) == 1 or repair.needs_repair(p, budget)]
        reports = [repair.repair(p, self.directory, budget=budget) for p in todo]
        done = [r for r in reports if r.repaired]
        self.said = ("; ".join(f"repaired {r.path.name}: {r.messages} messages recovered"
                               + (f", the original kept as {r.original.name}" if r.original else "")
                               for r in done) if done else f"{name} was complete; nothing to repair")
        return reports

    # ------------------------------------------------------------------ the run library
    def _runs(self) -> RunsAccess:
        if self.runs is None:
            raise ValueError("the run library is not available here")
        return self.runs

    def find_runs(self, query: object = None, sort: object = None, desc: object = None,
                  refresh: bool = False) -> list[Any]:
        """The runs ``query`` finds, sorted by ``sort`` (``desc``: largest or latest first);
        None: the last accepted. ``refresh``: bring the library up to the folder first. A
        refusal (ValueError, the library's text) leaves the last accepted query."""
        runs = self._runs()
        q0, s0, d0 = self.query
        q = q0 if query is None else query
        s = s0 if sort is None else sort
        d = d0 if desc is None else desc
        if refresh:
            runs.refresh()
        rows = runs.find(q, s, d)
        self.query = (q, s, d)  # type: ignore[assignment]  # checked by find
        return rows

    @staticmethod
    def tag_changes(text: object) -> list[str]:
        """``"+pool-3 -draft"`` (spaces or commas between) -> ``["+pool-3", "-draft"]``."""
        if not isinstance(text, str):
            raise ValueError(f"tags: expected text such as +pool-3 -draft, got {type(text).__name__}")
        return [c for c in text.replace(",", " ").split() if c]

    def set_tags(self, session_id: object, text: object) -> tuple[str, ...]:
        tags = self._runs().set_tags(session_id, self.tag_changes(text))
        self.said = f"{session_id}: tags now {' '.join(tags) or '(none)'}"
        return tags

    def set_notes(self, session_id: object, notes: object) -> str:
        text = self._runs().set_notes(session_id, notes)
        self.said = f"{session_id}: notes saved"
        return text

    def trend(self, figure: object, by: object) -> tuple[str, str, list[Any]]:
        """(field, axis, points): ``figure`` of the runs the last accepted query finds against
        ``by``; a figure or axis not among the trend's choices is refused (ValueError naming
        it) before the library is asked."""
        name, axis = trends.check_choice(figure, by)
        runs = self._runs()
        if runs.trend is None:
            raise ValueError("trends are not available here")
        return name, axis, runs.trend(self.query[0], name, axis)

    def report(self, session_id: object) -> tuple[str, bytes]:
        """The session's report file (name, content); ValueError when it has none."""
        p = self._runs().report(session_id)
        if p is None:
            raise ValueError(f"{session_id}: no report file beside it")
        with open(p, "rb") as fh:
            content = fh.read(MAX_REPORT_BYTES + 1)
        if len(content) > MAX_REPORT_BYTES:
            raise ValueError(f"{p.name}: larger than {MAX_REPORT_BYTES // 2**20} MiB: open it from the folder")
        self.said = f"report {p.name} sent"
        return p.name, content

    # ------------------------------------------------------------------ open / close
    def open(self, name: str) -> tuple[SessionParts, Player]:
        """Open a session for review at its start (paused): every part of the session named
        by its id or by any one of its part files. The session open before is closed."""
        target: str | Path = self._path(name) if self._name(name).endswith(files.SUFFIX) else name
        reader = self.readers.acquire(target, self.directory)  # a truncated part: TruncatedSessionError
        try:
            player = Player(reader, self.stream, speed=self.speed, loop=self.loop, on_error=self._on_play_error)
        except BaseException:
            self.readers.release(reader)
            raise
        self.close()
        with self._lock:
            self.reader, self.player = reader, player
        n = len(reader.parts)
        what = "" if name == reader.session_id else f" (session {reader.session_id})"
        self.said = (f"opened {name}{what}: {n} part{'s' if n > 1 else ''}, {reader.duration:.1f} s, "
                     f"notes: {reader.notes or '-'}")
        return reader, player

    def close(self) -> bool:
        """Close the player and give the reader back; whether a session was open."""
        with self._lock:
            player, reader = self.player, self.reader
            self.player = self.reader = None
        if player is not None:
            player.close()
        if reader is not None:
            self.readers.release(reader)
        return player is not None

    def stop(self) -> None:
        """Close the session and cancel this review's replay (the page has gone)."""
        job, self.job = self.job, None
        if job is not None and self.replay_slot.job is job:
            job.cancel()
        self.close()

    @property
    def reviewing(self) -> str:
        """The session open ("" when none is)."""
        r = self.reader
        return r.session_id if r is not None else ""

    def position(self) -> float | None:
        """The playback position in seconds from the session's start (None: none open)."""
        p = self.player
        return None if p is None else min(max(p.position - p.start, 0.0), p.end - p.start)

    # ------------------------------------------------------------------ playback
    def need(self) -> Player:
        p = self.player
        if p is None:
            raise ValueError("no session open: choose one and press Open")
        return p

    def set_speed(self, speed: object) -> float:
        v = check_speed(speed)  # type: ignore[arg-type]
        if self.player is not None:
            self.player.speed = v
        self.speed = v
        return v

    def set_loop(self, loop: object) -> None:
        if not isinstance(loop, bool):
            raise ValueError(f"loop: expected true or false, got {loop!r}")
        if self.player is not None:
            self.player.loop = loop
        self.loop = loop

    @staticmethod
    def check_time(t: object) -> float:
        if isinstance(t, bool) or not isinstance(t, (int, float)) or not math.isfinite(t):
            raise ValueError(f"time: expected a number of seconds, got {t!r}")
        return float(t)

    @staticmethod
    def check_step(n: object) -> int:
        if isinstance(n, bool) or n not in (1, -1):
            raise ValueError(f"step: {n!r} must be +1 or -1")
        return int(n)  # type: ignore[arg-type]

    def add_marker(self, note: object) -> Marker:
        """A review marker at the position (at most one every :data:`MARKER_INTERVAL` s)."""
        note = check_note(note)
        now = self._clock()
        if now - self._last_marker < MARKER_INTERVAL:
            raise ValueError(f"marker: at most one every {MARKER_INTERVAL:g} s from a page")
        p = self.need()
        self._last_marker = now
        m = p.add_marker(note)
        self.said = f"marker at {m.t - p.start:.2f} s saved to {p.markers.path.name}"
        return m

    def jump(self, forward: bool, levels: Collection[str] | None) -> Event | Marker | None:
        """The player at the next (or previous) event at ``levels`` or marker (None: none)."""
        p = self.need()
        return p.next_event(levels) if forward else p.prev_event(levels)

    def export(self, history: float) -> Export:
        """The open session's channels over the ``history`` s before the position, as
        ``sessions export`` writes them, one CSV per channel, zipped."""
        p, r = self.player, self.reader
        if p is None or r is None:
            raise ValueError("no session open: choose one and press Open")
        end = p.position
        start = max(end - float(history), p.start)
        name = f"{r.session_id}_{start - p.start:.1f}-{end - p.start:.1f}s_csv"
        buf = io.BytesIO()
        with tempfile.TemporaryDirectory() as d:
            got = export.export_csv(r, [c for c in CHANNELS if c in r.channels and not images.is_image(CHANNELS[c])], d, start,
                                    math.nextafter(end, math.inf))
            with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
                for f in sorted(Path(d).iterdir()):
                    z.write(f, f"{name}/{f.name}")
        self.said = f"exported {len(got)} channels, {start - p.start:.2f} to {end - p.start:.2f} s, as {name}.zip"
        return Export(name, buf.getvalue(), {c: n for c, (_, n) in got.items()}, start - p.start, end - p.start)

    # ------------------------------------------------------------------ counterfactual
    def run_counterfactual(self, text: object, owner: Any = None) -> ReplayJob:
        """Start replaying the open session's plans with other weights (in the background)."""
        r = self.reader
        if r is None:
            raise ValueError("no session open: choose one and press Open")
        weights = parse_weights(text)  # type: ignore[arg-type]
        replay_config(recorded_config(r), weights)  # a weight out of range: refused here, at once
        job = self.replay_slot.start(r.session_id, self.directory, weights, owner=owner,
                                     preempt=bool(self.may_replay()))
        self.job, self.job_weights = job, weights
        self.said = "counterfactual replay started"
        return job

    def cancel_counterfactual(self) -> None:
        job = self.job
        if job is None or job.done:
            raise ValueError("no counterfactual replay of this page is running")
        job.cancel()

    def replay_ended(self) -> ReplayEnd | None:
        """This review's replay once it has ended (once; None while it runs or when none does)."""
        with self._lock:
            job = self.job
            if job is None or not job.done:
                return None
            self.job = None
        return ReplayEnd(job.result, self.job_weights, job.cancelled, job.cancelled_by, job.error)
