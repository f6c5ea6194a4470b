"""One robot's view of one telemetry stream: the live view and each page's review are both a
:class:`StreamView`.

A view subscribes to a stream, keeps the latest body state and fin states (O(1) per
message), draws them in a :class:`~ucat_console.ui.scene.RobotScene` and fills the plots
(:class:`~ucat_console.ui.plots.LivePlots` on a :class:`~ucat_console.ui.plots.PlotFeeder`),
from a UI thread of its own that pushes, whatever the telemetry rate:

* the robot's pose on each new body state, at most ``scene_rate`` times a second (inside
  ``atomic()``, so a page applies the pose and the fins together);
* the plots at ``plot_rate`` when rows were added;
* the trail, the depth label and the view's own slow work (``on_slow``) at 4 Hz.

Rows of the plots are taken at the UI's pace (``sample_rows=True``: the live view) or by the
stream's clock (a :class:`StreamSampler` on the stream: review, so that the plots do not
depend on the playback speed).

:func:`from_page` is the one guard of the views' callbacks: it runs a command only for an
event that came from a page, not for a value set from code.
"""

from __future__ import annotations

import contextlib
import logging
import math
import threading
import time
from typing import Any, Callable

from ucat_console.robot.fins import N_FINS
from ucat_console.robot.geometry import Geometry
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.messages import BodyState, FinState
from ucat_console.telemetry.stream import TelemetryStream
from ucat_console.ui.plots import CHANNELS as PLOT_CHANNELS
from ucat_console.ui.plots import LivePlots, PlotFeeder
from ucat_console.ui.scene import LIVE_ROOT, RobotScene

log = logging.getLogger(__name__)

SLOW_PERIOD = 0.25  # s: trail, label, status
_TICK = 0.05  # s: the UI thread's longest sleep (``on_tick`` runs at least this often)


def from_page(fn: Callable[[], Any], act: Callable[[Callable[[], Any]], Any]) -> Callable[[Any], None]:
    """A viser callback running ``act(fn)`` for page events only (values set from code,
    which viser also reports, are ignored)."""

    def cb(event: Any) -> None:
        if getattr(event, "client_id", None) is None and getattr(event, "client", None) is None:
            return
        act(fn)

    return cb


class StreamSampler:
    """A stream subscriber feeding a :class:`PlotFeeder` with rows on the stream's clock.

    When a message newer than every message seen arrives and at least ``period`` s of stream
    time have passed since the last row, the feeder's latest values (every message up to
    then) become a row, before the new message is applied. The rows depend on the messages
    and their times only, not on when or how fast they are published.
    """

    def __init__(self, feeder: PlotFeeder, period: float) -> None:
        if not period > 0.0:
            raise ValueError(f"period: {period!r} must be a positive number of seconds")
        self.feeder = feeder
        self.period = float(period)
        self._lock = threading.Lock()
        self._t_max = -math.inf
        self._t_row = -math.inf
        self.rows = 0

    def on_message(self, channel: str, msg: Any) -> None:
        with self._lock:
            t = msg.t
            if t > self._t_max:
                if math.isfinite(self._t_max) and self._t_max >= self._t_row + self.period:
                    if self.feeder.sample():
                        self._t_row = self._t_max
                        self.rows += 1
                self._t_max = t
            self.feeder.on_message(channel, msg)

    def flush(self) -> bool:
        """A row of everything seen so far (the position reached); False when nothing new."""
        with self._lock:
            if self.feeder.sample():
                self._t_row = self._t_max
                self.rows += 1
                return True
            return False

    def reset(self) -> None:
        with self._lock:
            self.feeder.reset()
            self._t_max = self._t_row = -math.inf


class StreamView:
    """The view of one robot on one stream (module docstring).

    ``scene`` and ``gui`` are viser APIs (server-wide, or one page's); ``history()`` is the
    plots' window (s); ``atomic`` the context grouping one pose update; ``root`` the scene
    node of the robot. The scene is built by :meth:`show` (at once for the live view; when
    a session opens for a review)."""

    def __init__(self, scene: Any, gui: Any, geometry: Geometry, *, plot_rate: float, scene_rate: float,
                 max_plot_points: int, history: Callable[[], float], max_history: float,
                 corridor: Callable[[], tuple[float, float]], trail_points: int, trail_spacing: float,
                 root: str = LIVE_ROOT, sample_rows: bool = True, atomic: Callable[[], Any] | None = None,
                 on_slow: Callable[[], None] | None = None, on_tick: Callable[[], None] | None = None,
                 on_pose: Callable[[], None] | None = None, plot_height: int = 170, name: str = "view",
                 present: Callable[[], bool] = lambda: True,
                 playhead: Callable[[], float | None] | None = None) -> None:
        self.scene_api = scene
        self.geometry = geometry
        self.plot_rate = float(plot_rate)
        self.scene_rate = float(scene_rate)
        self.history = history
        self.root = root
        self._trail = (int(trail_points), float(trail_spacing))
        self._atomic = atomic or contextlib.nullcontext
        self.on_slow = on_slow
        self.on_tick = on_tick
        self.on_pose = on_pose
        self.name = name
        self.present = present  # whether the page it draws on is still there (a review's)
        self.sample_rows = sample_rows
        self.scene: RobotScene | None = None
        self.body: BodyState | None = None
        self.body_wall = 0.0
        self.body_seq = 0
        self.fins: list[FinState | None] = [None] * N_FINS
        self.feeder = PlotFeeder(int(math.ceil(max_history * plot_rate)) + 2)
        self.sampler = StreamSampler(self.feeder, 1.0 / self.plot_rate)
        self.plots = LivePlots(gui, self.feeder, rate=plot_rate, max_points=max_plot_points, corridor=corridor,
                               height=plot_height, playhead=playhead)
        self._stop = threading.Event()
        self._wake = threading.Event()  # a new body state, or stop()
        self._thread: threading.Thread | None = None
        self.tick_errors = 0

    # ------------------------------------------------------------------ stream side
    def subscribe(self, stream: TelemetryStream) -> list[Callable[[], None]]:
        """Feed this view from ``stream``; the unsubscribers."""
        plots = self.feeder.on_message if self.sample_rows else self.sampler.on_message
        return [stream.subscribe(plots, PLOT_CHANNELS),
                stream.subscribe_batches(self.on_messages, [ch.BODY_STATE, *(ch.fin_state(i) for i in range(N_FINS))])]

    def on_messages(self, items: Any) -> None:
        """The latest body state and fin states of ``items`` ((channel, message) pairs)."""
        body = None
        fins = self.fins
        for _, msg in items:
            tp = type(msg)
            if tp is BodyState:
                body = msg
            elif tp is FinState:
                fins[msg.fin] = msg
        if body is not None:
            self.body = body
            self.body_wall = time.time()
            self.body_seq += 1
            self._wake.set()

    def on_message(self, channel: str, msg: Any) -> None:
        self.on_messages(((channel, msg),))

    def reset(self) -> None:
        """Forget the robot's state and the plot rows (a new source)."""
        self.body, self.fins = None, [None] * N_FINS
        self.sampler.reset()
        self.plots.clear()

    # ------------------------------------------------------------------ scene
    def show(self) -> RobotScene:
        """Build the robot's scene nodes afresh (a fresh trail)."""
        if self.scene is not None:
            self.scene.remove()
        w, spacing = self._trail
        self.scene = RobotScene(self.scene_api, self.geometry, trail_points=w, trail_spacing=spacing, root=self.root)
        return self.scene

    def hide(self) -> None:
        if self.scene is not None:
            try:
                self.scene.remove()
            except Exception:  # the page has gone, and its nodes with it
                log.debug("removing the %s's scene failed", self.name, exc_info=True)
            self.scene = None

    def tick_scene(self) -> None:
        """The robot's pose and fins, as one update of the pages."""
        with self._atomic():
            self._pose()

    def _pose(self) -> None:
        s = self.scene
        if s is not None:
            s.update_pose(self.body, list(self.fins))
            if self.on_pose is not None:
                self.on_pose()

    def refresh_plots(self) -> None:
        self.plots.refresh(float(self.history()))

    def tick_slow(self) -> None:
        s = self.scene
        if s is not None:
            s.update_label(self.body)
            s.update_trail()
        if self.on_slow is not None:
            self.on_slow()

    # ------------------------------------------------------------------ UI thread
    @property
    def running(self) -> bool:
        return self._thread is not None

    def start(self) -> None:
        if self._thread is not None:
            return
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name=f"ui-{self.name}", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._wake.set()
        t, self._thread = self._thread, None
        if t is not None and t is not threading.current_thread():
            t.join(timeout=5.0)

    def _run(self) -> None:
        scene_period, plot_period = 1.0 / self.scene_rate, 1.0 / self.plot_rate
        next_scene = next_plot = next_slow = time.perf_counter()
        last_seq, last_rows = -1, -1
        while not self._stop.is_set():
            self._wake.clear()  # a body state from here on wakes the wait below
            now = time.perf_counter()
            try:
                # one batch: the pages' server is woken once for all of this pass's messages
                with self._atomic():
                    posed = self.body_seq != last_seq and now >= next_scene
                    if posed:
                        last_seq = self.body_seq
                        next_scene = max(next_scene + scene_period, now - scene_period)
                        self._pose()  # (inside this pass's atomic())
                    # plots and slow work due before the next pose go with this one (one
                    # batch for the pages' server to send instead of two)
                    early = scene_period if posed else 0.0
                    if now >= next_plot - early:
                        next_plot = max(next_plot + plot_period, now - plot_period)
                        if self.sample_rows:
                            if self.feeder.sample():
                                self.refresh_plots()
                        elif self.sampler.rows != last_rows:
                            last_rows = self.sampler.rows
                            self.refresh_plots()
                    if now >= next_slow - early:
                        next_slow = now + SLOW_PERIOD
                        self.tick_slow()
                    if self.on_tick is not None:
                        self.on_tick()
            except Exception:
                if not self.present():  # its page closed under it: nothing to draw on
                    log.debug("%s: the page has gone", self.name, exc_info=True)
                    self._stop.wait(_TICK)
                    continue
                self.tick_errors += 1
                log.exception("%s update failed", self.name)
            # wake when something is due, not to poll (each wake-up costs CPU): before the
            # next pose may go, at that time, whether a body state came meanwhile or not;
            # after it, at the body state's arrival; for the plots and the slow work a
            # pose's time later (a pose pass takes them before then while poses come)
            # (a timed wait sleeps: on a virtual machine a sleep's wake-up costs half of an
            # Event.wait's, and stop() waits for it at most _TICK)
            now = time.perf_counter()
            later = min(next_plot, next_slow) + scene_period
            if now < next_scene or self.body_seq != last_seq:
                time.sleep(min(max(min(next_scene, later) - now, 0.001), _TICK))
            else:
                self._wake.wait(min(max(later - now, 0.001), _TICK))
