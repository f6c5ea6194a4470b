# Over 600 lines: the Review tab's inputs, their callbacks and its view act on one open review; the review itself is backend/review/session.py.
"""The review panel: browse recorded sessions, play them back, mark them, replay them with
other MPC weights. What a page reviews is a viser-free
:class:`~ucat_console.backend.review.session.ReviewSession` (the folder, the open session,
its player, markers, export and counterfactual replay); this panel renders it.

Playback is the other end of the telemetry stream: a
:class:`~ucat_console.backend.sessions.player.Player` publishes a session onto a
:class:`~ucat_console.telemetry.TelemetryStream` of its own, and the review view is the
live view's code on that stream, a :class:`~ucat_console.ui.view.StreamView` (the robot
under ``/review``, drawn in place of the live one: while a page reviews, the live robot is
hidden for that page; its plots in the "Review plots" tab of the plot panel). The live
view keeps its own stream, scene and plots and never stops.

Review speaks session time (seconds from the session's start): the position, the timeline,
the plots' axis (the feeder's ``origin`` is the session's start), the events and markers; the
plots draw a playhead at the position. Opening or closing a session clears everything of
the one before. Rows of the review plots are taken on the recording's clock (one row per
``1 / plot_rate`` s of stream time, holding every message up to that time,
:class:`StreamSampler`), so the plots do not depend on the playback speed. After a jump
(seek, step back, event) the plot buffer is rebuilt from the file for the history window
before the new position.

The browser's table lists every part of a session; the session (every part) and the
repair are the review's (:mod:`~ucat_console.backend.review.session`).

Every page reviews on its own: the console builds one panel per page on that page's
``client.gui`` and ``client.scene``, so each page has its own player, position, speed and
review plots, and no page can change what another is reviewing. Playback controls do not
move the robot, so every page may use them, and any page may add review markers (they go
to the session's sidecar, shared by every page reviewing that session). The player's own
thread plays; a small UI thread here pushes the review scene (on each new body state, at
most ``scene_rate``), the plots (at ``plot_rate``) and the timeline and status (4 Hz)
while a session is open.

What reads or writes session files (listing, opening, repairing, seeking, stepping back,
jumping to an event, adding a marker, exporting CSV, starting a replay) does not run in the
page's callback: the callback hands it to the console's
:class:`~ucat_console.ui.page_jobs.PageJobs` (``jobs``), which runs a page's jobs one at a
time, in the order asked, and rations them; one asked for too soon is refused with the
reason shown on the page. A job takes the value the page sent when it sent it, so a seek or
a marker asked while a session opens lands once it is open. The sessions' listing is the
console's shared :class:`~ucat_console.ui.session_list.SessionList`.

A counterfactual replay's progress shows in the panel, with a Cancel.
"""

from __future__ import annotations

import logging
import threading
import time
from pathlib import Path
from typing import Any, Callable

from ucat_console.backend.review.metrics import MetricsConfig
from ucat_console.backend.review.session import ReviewSession, RunsAccess
from ucat_console.backend.sessions import index
from ucat_console.backend.sessions.markers import MAX_NOTE_BYTES, Marker
from ucat_console.backend.sessions.player import MAX_SPEED, MIN_SPEED, Player
from ucat_console.backend.sessions.reader import SessionParts
from ucat_console.backend.sessions.replay import ReplayResult
from ucat_console.backend.sessions.repair import RepairReport
from ucat_console.backend.sessions.replay_job import ReplayJob, ReplaySlot
from ucat_console.backend.sessions.shared import SharedReaders
from ucat_console.robot.geometry import Geometry
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.stream import TelemetryStream
from ucat_console.ui.camera_panel import CameraPanel
from ucat_console.ui.markdown import _describe, esc, replay_markdown, sessions_markdown, within
from ucat_console.ui.metrics_panel import MetricsPanel
from ucat_console.ui.plots import CHANNELS as PLOT_CHANNELS
from ucat_console.ui.run_list import RunList
from ucat_console.ui.scene import LIVE_ROOT, REVIEW_ROOT
from ucat_console.ui.view import StreamSampler, StreamView, from_page
from ucat_console.ui.viser_compat import set_slider_marks

__all__ = ["PlaybackPanel", "StreamSampler"]

log = logging.getLogger(__name__)

DEFAULT_WEIGHTS = "lam_st=2.0"
_SLOW_PERIOD = 0.25  # s, timeline, status, label, trail
#: what Previous / Next event stop at: name -> event levels (None: every event)
JUMP_LEVELS: dict[str, frozenset[str] | None] = {
    "all events": None,
    "warnings and errors": frozenset({"warning", "error", "fatal"}),
    "errors": frozenset({"error", "fatal"}),
}
#: the most event ticks the timeline shows
MAX_TIMELINE_MARKS = 200


class PlaybackPanel:
    """The review tab: session browser, playback controls, markers, counterfactual replay.

    ``gui``/``scene``: the viser APIs to build on (server-wide in the console);
    ``container``: where the controls go (a tab); ``plot_container``: where the review plots go.
    Every command is a method (``open``, ``seek``, ``set_speed``, ...) raising ValueError on
    bad input; the page's callbacks run them through :meth:`act`, which shows a refusal.
    """

    def __init__(
        self,
        gui: Any,
        scene: Any,
        geometry: Geometry,
        *,
        directory: str | Path | None = None,
        plot_rate: float = 10.0,
        scene_rate: float = 30.0,
        max_plot_points: int = 400,
        history: Callable[[], float] = lambda: 30.0,
        max_history: float = 300.0,
        corridor: Callable[[], tuple[float, float]] = lambda: (0.2, 0.4),
        trail_points: int = 500,
        trail_spacing: float = 0.02,
        container: Any = None,
        plot_container: Any = None,
        allow: Callable[..., None] | None = None,
        replay_slot: ReplaySlot | None = None,
        may_replay: Callable[[], bool | None] = lambda: None,
        plot_height: int = 170,
        metrics: MetricsConfig | None = None,
        jobs: Callable[[str, Callable[[], Any], bool], str | None] | None = None,
        present: Callable[[], bool] = lambda: True,
        sessions: Callable[[], index.Listing] | None = None,
        may_repair: Callable[[], None] = lambda: None,
        readers: SharedReaders | None = None,
        runs: RunsAccess | None = None,
    ) -> None:
        """``jobs(what, job, coalesce)``: queue an action that reads files (None when queued,
        else why not; None: run it in the callback); ``present()``: whether the page is
        still connected; ``sessions()``: the folder's listing, with what it skipped (default:
        read it each time); ``may_repair()``: raises (PermissionError) when this page may not
        repair (the console: unless it is the pilot's); ``readers``: the console's open
        readers, within its memory budget (default: readers of the panel's own); ``runs``:
        the run library (the Runs list above the chooser, which then holds the runs found)."""
        self.gui = gui
        self.jobs = jobs
        self.present = present
        self.stream = TelemetryStream()
        #: what this page reviews, without the page
        self.session = ReviewSession(directory, self.stream, readers=readers, replay_slot=replay_slot,
                                     may_repair=may_repair, may_replay=may_replay, sessions=sessions,
                                     on_play_error=self._play_failed, runs=runs)
        self.directory = self.session.directory
        self.replay_slot = self.session.replay_slot
        self.plot_rate = float(plot_rate)
        self.scene_rate = float(scene_rate)
        self.history = history
        self.messages: list[str] = []
        self.last_replay: ReplayResult | None = None
        self._lock = threading.RLock()
        self._hide_live: Any = None  # this page's invisible shadow of the live robot
        with within(plot_container):
            self.view = StreamView(
                scene, gui, geometry, plot_rate=plot_rate, scene_rate=scene_rate, max_plot_points=max_plot_points,
                history=history, max_history=max_history, corridor=corridor, trail_points=trail_points,
                trail_spacing=trail_spacing, root=REVIEW_ROOT, sample_rows=False, on_slow=self._tick_slow,
                plot_height=plot_height, name="review", present=present, playhead=self.position,
            )
            # the reviewed robot's efficiency figures above its plots, as the live ones
            self.metrics = MetricsPanel(gui, metrics or MetricsConfig(), order=0.0)
        self.sampler = self.view.sampler
        self.feeder = self.view.feeder
        self.plots = self.view.plots
        with within(container):  # the recorded camera's frame at the playhead
            self.camera = CameraPanel(gui, width=320, height=180, order=2.5, allow=allow, label="Camera",
                                      show_label="Show recorded camera", origin=self._start)
        self._unsubs = [*self.view.subscribe(self.stream), self.metrics.subscribe(self.stream),
                        self.camera.subscribe(self.stream)]

        with within(container):
            with gui.add_folder("Sessions", order=1.0):
                self.browser = gui.add_markdown("")
                self.choice = gui.add_dropdown("Session", ("",), initial_value="",
                                               hint="a session, every part of it")
                self.refresh_list = gui.add_button("Refresh list")
                self.open_button = gui.add_button("Open", color="blue")
                self.repair_button = gui.add_button("Repair", color="orange",
                                                    hint="the pilot's: rewrite the session's truncated files "
                                                         "fully indexed (the originals are kept, listed)")
                self.close_button = gui.add_button("Close")
            with gui.add_folder("Playback", order=2.0):
                self.status = gui.add_markdown("No session open.")
                self.timeline = gui.add_slider("Time (s)", 0.0, 1.0, 0.01, 0.0, disabled=True)
                self.play_button = gui.add_button("Play", color="green")
                self.pause_button = gui.add_button("Pause")
                self.speed = gui.add_number(f"Speed [{MIN_SPEED:g}, {MAX_SPEED:g}]", 1.0, step=0.1,
                                            hint="playback speed, times real time")
                self.loop = gui.add_checkbox("Loop", False)
                self.step_back = gui.add_button("Frame back")
                self.step_fwd = gui.add_button("Frame forward")
                self.jump_levels = gui.add_dropdown("Jump to", tuple(JUMP_LEVELS), initial_value="all events",
                                                    hint="which events Previous / Next event stop at (markers always)")
                self.prev_button = gui.add_button("Previous event")
                self.next_button = gui.add_button("Next event")
                self.note = gui.add_text("Review note", "", hint=f"the note of a review marker, at most {MAX_NOTE_BYTES} bytes")
                self.marker_button = gui.add_button("Add review marker",
                                                    hint="saved beside the session (any page reviewing may add one); "
                                                         "the recording itself is untouched")
                self.export_button = gui.add_button("Export CSV",
                                                    hint="the session's channels over the plots' time window, "
                                                         "one CSV per channel (zip)")
                self.message = gui.add_markdown("")
            with gui.add_folder("Counterfactual replay", order=3.0, expand_by_default=False):
                self.weights = gui.add_text("Weights", DEFAULT_WEIGHTS,
                                            hint="e.g. lam_st=2.0,lam_f=1.5 (lam_f, lam_st, lam_a, lam_d)")
                self.replay_button = gui.add_button("Replay with these weights",
                                                    hint="runs in the background at a lower priority, one at a time")
                self.replay_progress = gui.add_progress_bar(0.0, visible=False)
                self.cancel_button = gui.add_button("Cancel replay", visible=False)
                self.replay_table = gui.add_markdown("")
            # above the Sessions folder (order), made after it: a page's "Open" is the chooser's
            self.run_list: RunList | None = None
            if runs is not None:
                self.run_list = RunList(gui, self.session, chosen=lambda: self.choice.value, job=self._job,
                                        show=self.show, listed=self._runs_listed, allow=allow)
        self._wire()
        if allow is not None:
            for h in (self.choice, self.refresh_list, self.open_button, self.repair_button, self.close_button,
                      self.timeline, self.play_button, self.pause_button, self.speed, self.loop, self.step_back,
                      self.step_fwd, self.jump_levels, self.prev_button, self.next_button, self.marker_button,
                      self.export_button, self.replay_button,
                      self.cancel_button):
                allow(h, False)
            allow(self.note, False, MAX_NOTE_BYTES)
            allow(self.weights, False, 500)
        if jobs is None:
            self.refresh_sessions()
        else:
            jobs("Refresh list", lambda: self.act(self.refresh_sessions), True)
        self._set_enabled()

    # ------------------------------------------------------------------ callbacks
    def _wire(self) -> None:
        self.refresh_list.on_click(self._job("Refresh list", self.refresh_sessions))
        self.open_button.on_click(self._job("Open", lambda: self.open(self.choice.value)))
        self.repair_button.on_click(self._job("Repair", lambda: self.repair(self.choice.value)))
        self.close_button.on_click(self._page(self.close_session))
        if self.run_list is not None:
            self.choice.on_update(self._page(lambda: self.run_list and self.run_list.chose(self.choice.value)))
            self.run_list.report_button.on_click(self._report)
        # a dragged timeline: the latest position wins; the value the page sent, read now (by
        # the time the job runs, the timeline may show the player's position again)
        self.timeline.on_update(self._job("Seek", self.seek, coalesce=True, value=lambda: self.timeline.value))
        self.play_button.on_click(self._page(self.play))
        self.pause_button.on_click(self._page(self.pause))
        self.speed.on_update(self._page(lambda: self.set_speed(self.speed.value)))
        self.loop.on_update(self._page(lambda: self.set_loop(self.loop.value)))
        self.step_back.on_click(self._job("Frame back", lambda: self.step(-1)))
        self.step_fwd.on_click(self._page(lambda: self.step(1)))
        self.prev_button.on_click(self._job("Previous event", self.prev_event))
        self.next_button.on_click(self._job("Next event", self.next_event))
        # after the jobs asked before it (an open, a seek): the marker goes where they leave the player
        self.marker_button.on_click(self._job("Add marker", self.add_marker, value=lambda: self.note.value))
        self.export_button.on_click(self._export)
        self.replay_button.on_click(self._job("Replay", lambda: self.run_counterfactual(self.weights.value)))
        self.cancel_button.on_click(self._page(self.cancel_counterfactual))

    def _page(self, fn: Callable[[], Any]) -> Callable[[Any], None]:
        return from_page(fn, self.act)

    def _job(self, what: str, fn: Callable[..., Any], coalesce: bool = False,
             value: Callable[[], Any] | None = None) -> Callable[[Any], None]:
        """A callback handing ``fn`` to the console's page jobs (refused: the reason shown);
        with ``value``, ``fn(value())``, the value read in the callback."""
        jobs = self.jobs

        def submit(f: Callable[[], Any]) -> None:
            if value is not None:
                v = value()
                f = lambda: fn(v)  # noqa: E731
            if jobs is None:
                self.act(f)
                return
            why = jobs(what, lambda: self.act(f), coalesce)
            if why is not None:
                self.act(lambda: self.show(why, error=True))

        return from_page(fn, submit)

    def _export(self, event: Any) -> None:
        """Export CSV: the file goes to the page that asked."""
        client = getattr(event, "client", None)
        if client is not None:
            self._job("Export CSV", lambda: self.export_csv(
                lambda name, content: client.send_file_download(name, content, save_immediately=True)))(event)

    def _report(self, event: Any) -> None:
        """Open report: the chosen run's report file goes to the page that asked."""
        client, runs = getattr(event, "client", None), self.run_list
        if client is not None and runs is not None:
            self._job("Open report", lambda name: runs.send_report(name, lambda n, content: client.send_file_download(
                n, content, save_immediately=False)), value=lambda: self.choice.value)(event)

    def act(self, fn: Callable[[], Any]) -> bool:
        """Run one command; a refusal (ValueError) is shown and the inputs show the state.
        When the page has gone meanwhile, nothing is shown and nothing is an error."""
        try:
            try:
                fn()
            except (ValueError, RuntimeError, OSError) as e:
                self.show(str(e), error=True)
                self._sync_inputs()
                return False
            except Exception as e:
                if not self.present():
                    raise
                log.exception("playback command failed")
                self.show(f"internal error: {e}", error=True)
                return False
        except Exception:
            if self.present():
                raise
            log.debug("a page left during a review command", exc_info=True)
            return False
        return True

    def show(self, text: str, error: bool = False) -> None:
        self.messages.append(text)
        self.message.content = time.strftime("%H:%M:%S ") + ("**Refused:** " if error else "") + esc(text)

    # ------------------------------------------------------------------ browser
    def refresh_sessions(self) -> list[index.SessionInfo]:
        """List the sessions (the table shows every part; the chooser, the sessions)."""
        listing = self.session.listing()
        sessions = listing.sessions
        self.browser.content = sessions_markdown(sessions, listing.skipped)
        self.repair_button.disabled = not any(p.repairable for s in sessions for p in s.parts)
        if self.run_list is not None:  # the chooser holds the runs the library finds
            self.run_list.find(refresh=True)
        else:
            self._runs_listed(tuple(s.session_id for s in sessions))
        return sessions

    def _runs_listed(self, ids: tuple[str, ...]) -> None:
        """The Session chooser's options: ``ids`` (the one chosen stays when it is among them)."""
        names = ids or ("",)
        current = self.choice.value
        if self.choice.options != names:
            self.choice.options = names
        chosen = current if current in names else names[0] if self.run_list is not None else names[-1]
        if self.choice.value != chosen:
            self.choice.value = chosen
        if self.run_list is not None:
            self.run_list.chose(chosen)

    def repair(self, name: str) -> list[RepairReport]:
        """Repair the truncated files of a session (or one named part file); only the pilot's
        page may, and never a part being recorded."""
        try:
            reports = self.session.repair(name)
        finally:
            self.refresh_sessions()
        self.show(self.session.said)
        return reports

    # ------------------------------------------------------------------ open / close
    def open(self, name: str) -> Player:
        """Open a session for review at its start (paused): every part of the session named
        by its id or by any one of its part files."""
        with self._lock:
            reader, player = self.session.open(name)  # the session open before is closed
            self.close_session(quiet=True, closed=True)
            self.feeder.origin = player.start  # the plots in seconds from the session's start
            self.view.show()  # a fresh robot and trail
            if self._hide_live is None:  # the reviewed robot in place of the live one
                self._hide_live = self.view.scene_api.add_frame(LIVE_ROOT, show_axes=False, visible=False)
        self.timeline.min = 0.0
        self.timeline.max = max(player.end - player.start, 0.01)
        self._mark_events(reader)
        self._jumped(player.seek(player.start))
        self._set_enabled()
        self.view.start()
        self.show(self.session.said)
        return player

    @property
    def reader(self) -> SessionParts | None:
        return self.session.reader

    @property
    def player(self) -> Player | None:
        return self.session.player

    @property
    def job(self) -> ReplayJob | None:
        return self.session.job

    def _play_failed(self, text: str) -> None:
        """The player stopped on a failure (its thread): the page shows why."""
        try:
            self.show(f"playback stopped: {text}", error=True)
        except Exception:
            log.debug("a playback failure was not shown", exc_info=True)

    def close_session(self, quiet: bool = False, closed: bool = False) -> None:
        """Close the session: nothing of it stays (plots, timeline ticks, replay table, robot);
        ``closed``: the session has closed it already (another opened)."""
        self.view.stop()
        was_open = False if closed else self.session.close()
        self._show_live()
        self.view.hide()
        self.view.reset()
        self.metrics.reset()
        self.camera.reset()
        self._mark_times([])
        if self.job is None:
            self.replay_table.content = ""
            self.last_replay = None
        if self.job is not None:
            self.view.start()  # the replay's progress still shows
        self._set_enabled()
        if was_open and not quiet:
            self.show("session closed")

    def stop(self, page_gone: bool = False) -> None:
        """Close the session and let go of the stream (the app is stopping, or with
        ``page_gone`` the page has gone and its elements with it)."""
        self.view.stop()
        self.session.stop()
        if not page_gone:
            self._set_enabled()
            self._show_live()
            self.view.hide()
        for unsub in self._unsubs:
            unsub()
        self._unsubs = []

    # ------------------------------------------------------------------ playback
    def play(self) -> None:
        self.session.need().play()

    def pause(self) -> None:
        p = self.session.need()
        p.pause()
        self.sampler.flush()

    def set_speed(self, speed: object) -> None:
        v = self.session.set_speed(speed)
        if self.speed.value != v:
            self.speed.value = v

    def set_loop(self, loop: object) -> None:
        self.session.set_loop(loop)
        self.loop.value = loop

    def seek(self, t: object) -> None:
        """Go to ``t`` seconds from the session's start (clamped to the session)."""
        t = self.session.check_time(t)
        p = self.session.need()
        self._moved(lambda: p.seek(p.start + t))

    def step(self, n: int) -> bool:
        n = self.session.check_step(n)
        p = self.session.need()
        if n > 0:
            ok = p.step(1)
            self.sampler.flush()
        else:
            ok = self._moved(lambda: p.step(-1))
        if not ok:
            self.show("no frame " + ("after" if n > 0 else "before") + " this one")
        return ok

    def _levels(self) -> frozenset[str] | None:
        return JUMP_LEVELS.get(self.jump_levels.value)

    def next_event(self) -> Event | Marker | None:
        return self._jump(True)

    def prev_event(self) -> Event | Marker | None:
        return self._jump(False)

    def _jump(self, forward: bool) -> Event | Marker | None:
        p = self.session.need()
        what = self._moved(lambda: self.session.jump(forward, self._levels()))
        self.show(_describe(what, p.start) if what is not None
                  else f"no event {'after' if forward else 'before'} this one")
        return what

    def add_marker(self, note: object) -> Marker:
        m = self.session.add_marker(note)
        self.note.value = ""
        self.show(self.session.said)
        return m

    def _start(self) -> float | None:
        """The open session's start (stream seconds; None: none open)."""
        p = self.session.player
        return None if p is None else p.start

    def position(self) -> float | None:
        """The playback position in seconds from the session's start (None: none open)."""
        return self.session.position()

    @property
    def reviewing(self) -> str:
        """The session this page plays ("" when none is open)."""
        return self.session.reviewing

    def export_csv(self, send: Callable[[str, bytes], Any]) -> dict[str, int]:
        """The open session's channels over the plots' time window (the history before the
        position), as ``sessions export`` writes them, zipped and handed to ``send(name,
        content)``; channel -> rows."""
        x = self.session.export(float(self.history()))
        send(f"{x.name}.zip", x.content)
        self.show(self.session.said)
        return x.rows

    def _moved(self, fn: Callable[[], Any]) -> Any:
        """Run a jump with playback paused, then rebuild the plots before the new position."""
        p = self.session.need()
        was_playing = p.playing
        p.pause()
        with self._lock:
            self.sampler.reset()
            out = fn()
            self._jumped(out)
        if was_playing:
            p.play()
        return out

    def _jumped(self, _: Any) -> None:
        """The plots after a jump: the history window before the position, from the file."""
        p, r = self.player, self.reader
        if p is None or r is None:
            return
        self.sampler.reset()
        window = max(float(self.history()), 1.0 / self.plot_rate)
        pos = r.to_ns(p.position)
        first = r.to_ns(p.position - window)
        before = r.state_records_at_ns(first - 1, PLOT_CHANNELS)  # values from before the window
        for rec in sorted(before.values(), key=lambda x: x.log_time_ns):
            self.sampler.on_message(rec.channel, rec.message)
        for rec in r.records(PLOT_CHANNELS, start_ns=first, end_ns=pos + 1):
            self.sampler.on_message(rec.channel, rec.message)
        self.sampler.flush()

    # ------------------------------------------------------------------ counterfactual
    def run_counterfactual(self, text: object) -> ReplayJob:
        """Start replaying the open session's plans with other weights (in the background)."""
        job = self.session.run_counterfactual(text, owner=self)
        self.replay_progress.value = 0.0
        self.replay_progress.visible = self.cancel_button.visible = True
        self.replay_table.content = "Counterfactual replay running ..."
        self.show(self.session.said)
        self.view.start()
        return job

    def cancel_counterfactual(self) -> None:
        self.session.cancel_counterfactual()
        self._job_finished()

    def wait_replay(self, timeout: float = 300.0) -> ReplayResult | None:
        """Wait for this page's replay to end and show it (the panel's UI thread does the same)."""
        job = self.job
        if job is not None:
            job.wait(timeout)
            self._job_finished()
        return self.last_replay

    def _job_finished(self) -> None:
        """Show the end of this page's replay (once)."""
        end = self.session.replay_ended()
        if end is None:
            return
        self.replay_progress.visible = self.cancel_button.visible = False
        if end.result is not None:
            self.last_replay = end.result
            self.replay_table.content = replay_markdown(end.result, end.weights)
            self.show(f"counterfactual replay: {len(end.result.rows)} plans")
        elif end.cancelled:
            self.replay_table.content = ("Counterfactual replay cancelled." if end.cancelled_by is None
                                         else f"Counterfactual replay cancelled: {end.cancelled_by}.")
            self.show("counterfactual replay cancelled")
        else:
            self.replay_table.content = ""
            self.show(f"counterfactual replay failed: {end.error}", error=True)

    def _tick_job(self) -> None:
        job = self.job
        if job is None:
            return
        if job.done:
            self._job_finished()
            return
        pr = job.progress
        self.replay_progress.value = round(100.0 * pr.fraction, 1)
        self.replay_table.content = (f"Counterfactual replay running: {pr.done} of {pr.total} plans"
                                     if pr.total else "Counterfactual replay starting ...")

    # ------------------------------------------------------------------ the view's slow work
    def _show_live(self) -> None:
        """This page sees the live robot again."""
        h, self._hide_live = self._hide_live, None
        if h is not None:
            try:
                h.remove()
            except Exception:
                log.debug("showing the live robot again failed", exc_info=True)

    def _mark_events(self, reader: Any) -> None:
        """Ticks on the timeline at the session's warnings and errors (and markers)."""
        start = reader.start_ns
        times = sorted({round((ns - start) * 1e-9, 2)
                        for ns in reader.event_index().at_levels(("warning", "error", "fatal"))})
        if len(times) > MAX_TIMELINE_MARKS:  # keep the slider readable
            step = len(times) / MAX_TIMELINE_MARKS
            times = [times[int(i * step)] for i in range(MAX_TIMELINE_MARKS)]
        self._mark_times(times)

    def _mark_times(self, times: list[float]) -> None:
        try:
            set_slider_marks(self.timeline, times)
        except Exception:
            log.debug("timeline marks not shown", exc_info=True)

    def _tick_slow(self) -> None:
        self.camera.tick()
        self._sync_inputs()
        self.metrics.refresh()
        self._tick_job()

    @property
    def tick_errors(self) -> int:
        return self.view.tick_errors

    def _sync_inputs(self) -> None:
        """Timeline, speed, loop and status show the player's state (set from code)."""
        p = self.player
        if p is None:
            self.status.content = "No session open."
            if self.speed.value != self.session.speed:
                self.speed.value = self.session.speed
            return
        rel = self.position() or 0.0
        if abs(self.timeline.value - rel) > 1e-9:
            self.timeline.value = rel
        if self.speed.value != p.speed:
            self.speed.value = p.speed
        if self.loop.value != p.loop:
            self.loop.value = p.loop
        r = self.reader
        state = "playing" if p.playing else "**stopped on an error** (below)" if p.error else "paused"
        name = ""
        if r is not None:
            name = r.session_id
            if len(r.parts) > 1:
                name += f" (part {r.part_at_ns(r.to_ns(p.position))} of {len(r.parts)})"
        self.status.content = (f"**{esc(name)}** {state} at {rel:.2f} / {p.end - p.start:.2f} s, "
                               f"speed {p.speed:g}x{', loop' if p.loop else ''}; "
                               f"{len(p.markers.markers)} review markers")

    def _set_enabled(self) -> None:
        closed = self.player is None
        for h in (self.timeline, self.play_button, self.pause_button, self.step_back, self.step_fwd,
                  self.prev_button, self.next_button, self.note, self.marker_button, self.export_button,
                  self.replay_button, self.close_button):
            h.disabled = closed
        self._sync_inputs()
