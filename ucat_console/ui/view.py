"""One robot's view of one telemetry stream: the live view and each page's review are both a
:class:`StreamView`.

A view subscribes to a stream, keeps the latest body state and fin states (O(1) per
message), draws them in a :class:`~ucat_console.ui.scene.RobotScene` and fills the plots
(:class:`~ucat_console.ui.plots.LivePlots` on a :class:`~ucat_console.ui.plots.PlotFeeder`)
in passes that push, whatever the telemetry rate:

* the robot's pose on each new body state, at most ``scene_rate`` times a second (inside
  ``atomic()``, so a page applies the pose and the fins together);
* the plots at ``plot_rate`` when rows were added;
* the trail, the depth label and the view's own slow work (``on_slow``) at 4 Hz.

The passes run in a UI thread of the view's own (each page's review: its callbacks wait for
the review's player), or as callbacks of the pages' server's event loop (the live view,
``start(loop)``): there a pass and the sending of its messages share one wake-up of one
thread, where a thread of its own wakes for the pass and then wakes the server's thread
(``ucat-console bench ui``, README). A pass on the server's loop must not block: the
pages' sockets wait while it runs.

Rows of the plots are taken at the UI's pace (``sample_rows=True``: the live view) or by the
stream's clock (a :class:`StreamSampler` on the stream: review, so that the plots do not
depend on the playback speed).

:func:`from_page` is the one guard of the views' callbacks: it runs a command only for an
event that came from a page, not for a value set from code.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
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
_TICK = 0.05  # s: the longest time between two passes (``on_tick`` runs at least this often)


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
                 on_pose: Callable[[], None] | None = None, plot_height: int = 170, name: str = "view") -> None:
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
        self.sample_rows = sample_rows
        self.scene: RobotScene | None = None
        self.body: BodyState | None = None
        self.body_wall = 0.0
        self.body_seq = 0
        self.fins: list[FinState | None] = [None] * N_FINS
        self.feeder = PlotFeeder(int(math.ceil(max_history * plot_rate)) + 2)
        self.sampler = StreamSampler(self.feeder, 1.0 / self.plot_rate)
        self.plots = LivePlots(gui, self.feeder, rate=plot_rate, max_points=max_plot_points, corridor=corridor,
                               height=plot_height)
        self._stop = threading.Event()
        self._wake = threading.Event()  # a new body state, or stop()
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._timer: asyncio.Handle | None = None
        self._waiting = False  # on the loop: the next pass waits for a body state
        self._pacing = _Pacing.from_now()
        self.tick_errors = 0

    # ------------------------------------------------------------------ stream side
    def subscribe(self, stream: TelemetryStream) -> list[Callable[[], None]]:
        """Feed this view from ``stream``; the unsubscribers."""
        plots = self.feeder.on_message if self.sample_rows else self.sampler.on_message
        return [stream.subscribe(plots, PLOT_CHANNELS),
                stream.subscribe(self.on_message, [ch.BODY_STATE, *(ch.fin_state(i) for i in range(N_FINS))])]

    def on_message(self, channel: str, msg: Any) -> None:
        tp = type(msg)
        if tp is BodyState:
            self.body = msg
            self.body_wall = time.time()
            self.body_seq += 1
            loop = self._loop
            if loop is None:
                self._wake.set()
            elif self._waiting:
                self._waiting = False
                try:
                    loop.call_soon_threadsafe(self._on_loop)
                except RuntimeError:
                    pass  # the loop has closed (the server stopped)
        elif tp is FinState:
            self.fins[msg.fin] = msg

    def reset(self) -> None:
        """Forget the robot's state and the plot rows (a new source)."""
        self.body, self.fins = None, [None] * N_FINS
        self.sampler.reset()

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
        s = self.scene
        if s is not None:
            with self._atomic():
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

    # ------------------------------------------------------------------ passes
    @property
    def running(self) -> bool:
        return self._thread is not None or self._loop is not None

    def start(self, loop: asyncio.AbstractEventLoop | None = None) -> None:
        """Run the view's passes: in a UI thread of its own, or, given ``loop`` (the pages'
        server's event loop, running in its thread), as that loop's callbacks (module
        docstring). Only a view whose callbacks never block may run on the server's loop."""
        if self.running:
            return
        self._stop.clear()
        self._pacing = _Pacing.from_now()
        if loop is not None:
            self._loop = loop
            loop.call_soon_threadsafe(self._on_loop)
            return
        self._thread = threading.Thread(target=self._run, name=f"ui-{self.name}", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._wake.set()
        loop, self._loop = self._loop, None
        if loop is not None:
            try:
                loop.call_soon_threadsafe(self._cancel_timer)
            except RuntimeError:
                pass  # the loop has stopped, and its timers with it
        t, self._thread = self._thread, None
        if t is not None and t is not threading.current_thread():
            t.join(timeout=5.0)

    def _pass(self, p: _Pacing) -> tuple[float, bool]:
        """One pass: what is due of the pose, the plots and the slow work, as one batch (the
        pages' server is woken once for all of its messages). Returns when the next pass is
        due (``time.perf_counter``) and whether a body state arriving earlier should wake
        it: before the next pose may go, at that time, whether a body state came meanwhile
        or not; after it, at the body state's arrival; for the plots and the slow work a
        pose's time later (a pose pass takes them before then while poses come)."""
        scene_period, plot_period = 1.0 / self.scene_rate, 1.0 / self.plot_rate
        now = time.perf_counter()
        try:
            with self._atomic():
                posed = self.body_seq != p.last_seq and now >= p.next_scene
                if posed:
                    p.last_seq = self.body_seq
                    p.next_scene = max(p.next_scene + scene_period, now - scene_period)
                    self.tick_scene()
                # plots and slow work due before the next pose go with this one (one
                # batch for the pages' server to send instead of two)
                early = scene_period if posed else 0.0
                if now >= p.next_plot - early:
                    p.next_plot = max(p.next_plot + plot_period, now - plot_period)
                    if self.sample_rows:
                        if self.feeder.sample():
                            self.refresh_plots()
                    elif self.sampler.rows != p.last_rows:
                        p.last_rows = self.sampler.rows
                        self.refresh_plots()
                if now >= p.next_slow - early:
                    p.next_slow = now + SLOW_PERIOD
                    self.tick_slow()
                if self.on_tick is not None:
                    self.on_tick()
        except Exception:
            self.tick_errors += 1
            log.exception("%s update failed", self.name)
        later = min(p.next_plot, p.next_slow) + scene_period
        if time.perf_counter() < p.next_scene or self.body_seq != p.last_seq:
            return min(p.next_scene, later), False
        return later, True

    # the view's own thread: wakes when something is due, not to poll (each wake-up costs CPU)
    def _run(self) -> None:
        p = self._pacing
        while not self._stop.is_set():
            self._wake.clear()  # a body state from here on wakes the wait below
            wake, on_body = self._pass(p)
            event = self._wake if on_body else self._stop
            event.wait(min(max(wake - time.perf_counter(), 0.001), _TICK))

    # on the server's event loop: a timer for what is due, a body state's arrival for the pose
    def _on_loop(self) -> None:
        self._cancel_timer()
        loop = self._loop
        if loop is None or self._stop.is_set():
            return
        self._waiting = False
        p = self._pacing
        wake, on_body = self._pass(p)
        self._timer = loop.call_later(min(max(wake - time.perf_counter(), 0.001), _TICK), self._on_loop)
        if on_body:
            self._waiting = True  # on_message, in the stream's thread, calls the next pass
            if self.body_seq != p.last_seq:  # a body state came before the flag was up
                self._waiting = False
                self._cancel_timer()
                self._timer = loop.call_soon(self._on_loop)

    def _cancel_timer(self) -> None:
        timer, self._timer = self._timer, None
        if timer is not None:
            timer.cancel()


@dataclasses.dataclass
class _Pacing:
    """When a view's next pose, plot refresh and slow work are due, and what it has shown."""

    next_scene: float
    next_plot: float
    next_slow: float
    last_seq: int = -1  # the body state last posed
    last_rows: int = -1  # the sampler's rows last plotted (review)

    @classmethod
    def from_now(cls) -> _Pacing:
        now = time.perf_counter()
        return cls(now, now, now)
