"""The console's web page: a viser server showing the supervisor's telemetry stream.

:class:`ConsoleApp` subscribes to the supervisor's stream (it never reads the loop
directly) and runs one UI thread that pushes, at fixed rates whatever the telemetry rate:

* the 3-D view at ``console.scene_rate`` (pose, fins, commanded fins; grouped in one
  ``server.atomic()`` batch), the trail and the depth label at 4 Hz;
* the plots at ``console.plot_rate`` (a row into the ring buffers, then the chosen window);
* the status line, MPC introspection, failsafes, journal and events at 4 Hz, and every
  page's controls when the supervisor's state changed.

Shared elements (3-D view, plots, status, introspection) are server-wide; each page's
controls are its own (:class:`~ucat_console.ui.panels.ControlPanel`), and so is its review
of recorded sessions (:class:`~ucat_console.ui.playback.PlaybackPanel`: every page reviews
on its own, with its own player, position and review plots, so no page can move what
another is reviewing). A page's panels are built when it connects, one page at a time
(viser runs connect callbacks concurrently, and the shared tabs they fill are not safe to
enter from two threads at once).

Every page passes through a :class:`~ucat_console.ui.guard.PageGuard`: its handshake's
Origin, every message it sends (only the values of its own inputs, pilot-only inputs only
while it is the pilot's) and its heartbeat; a page that stops answering is gone, and when
it was the pilot's the pilot-gone failsafe acts. The server binds to ``console.host``
(127.0.0.1 by default) and warns when that is not a loopback address: viser has no
authentication of its own, and the pilot token guards only the controls, not what the
page shows.

With ``probe=True`` a tiny HTML element carries, with every pose update and in the same
batch, the wall-clock time at which the shown BodyState was published; the UI benchmark
reads it in the page to measure update rates and latency.
"""

from __future__ import annotations

import collections
import ipaddress
import logging
import math
import threading
import time
from typing import Any, Callable

import viser

from ucat_console.backend.sessions.replay_job import ReplaySlot
from ucat_console.backend.supervisor import CommandRefused, Supervisor
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.messages import BodyState, FinPlan, FinState
from ucat_console.ui import panels
from ucat_console.ui.guard import PageGuard
from ucat_console.ui.playback import PlaybackPanel
from ucat_console.ui.plots import CHANNELS as PLOT_CHANNELS
from ucat_console.ui.plots import LivePlots, PlotFeeder
from ucat_console.ui.scene import RobotScene

log = logging.getLogger(__name__)

N_FINS = ch.N_FINS
_SLOW_PERIOD = 0.25  # s, status / introspection / label / trail
_EVENTS_SHOWN = 12
_QUIET_EVENTS = frozenset({"stroke_timeout"})


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class ConsoleApp:
    """The viser app of one supervisor (module docstring)."""

    def __init__(self, supervisor: Supervisor, *, host: str | None = None, port: int | None = None,
                 probe: bool = False) -> None:
        self.sup = supervisor
        cfg = supervisor.cfg.console
        self.cfg = cfg
        self.host = cfg.host if host is None else host
        if not is_loopback(self.host):
            log.warning("the console binds to %s: anyone who reaches it sees the live page "
                        "(control still needs the pilot token); use 127.0.0.1 unless you mean it",
                        self.host)
        self.history = cfg.history
        self._lock = threading.Lock()
        self._body: BodyState | None = None
        self._body_wall = 0.0
        self._body_seq = 0
        self._fins: list[FinState | None] = [None] * N_FINS
        self._plans: list[FinPlan | None] = [None] * N_FINS
        self._events: collections.deque[Event] = collections.deque(maxlen=_EVENTS_SHOWN)
        self._dirty = threading.Event()
        self.panels: dict[int, panels.ControlPanel] = {}
        self.reviews: dict[int, PlaybackPanel] = {}
        self._build_lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.tick_errors = 0
        #: a session every new page opens in its Review tab (``run --playback``)
        self.initial_session: str | None = None
        self.sessions_dir = supervisor.recorder.directory
        self.replay_slot = ReplaySlot()

        self.guard = PageGuard(
            is_pilot=supervisor.access.is_pilot,
            pilot_timeout=lambda: supervisor.cfg.failsafe.pilot_gone.timeout,
            page_timeout=cfg.page_timeout, heartbeat_period=cfg.heartbeat_period,
            allowed_origins=cfg.allowed_origins,
            on_connect=supervisor.client_connected,
            on_disconnect=supervisor.client_disconnected,
            on_gone=lambda cid, silent: supervisor.client_disconnected(cid, silent_for=silent),
        )
        server = self.guard.serve(host=self.host, port=cfg.port if port is None else port, verbose=False,
                                  label="U-CAT console")
        self.server = server
        server.gui.configure_theme(control_width="large", show_share_button=False, dark_mode=False)
        server.request_share_url = _no_share_url  # type: ignore[method-assign]
        z = -max(cfg.sim_depth, 0.3)
        # from behind and to port, the vehicle left of the middle (the controls are on the right)
        server.initial_camera.position = (-1.0, -1.3, z + 0.3)
        server.initial_camera.look_at = (0.35, -0.45, z)
        self.scene = RobotScene(server.scene, supervisor.cfg.plant.geometry, trail_points=cfg.trail_points,
                                trail_spacing=cfg.trail_spacing, shadows=cfg.shadows,
                                environment_map=cfg.environment_map)
        gui = server.gui
        self.status = gui.add_markdown("Starting ...", order=0.0)
        self.probe = gui.add_html("", order=0.5) if probe else None
        self.tabs = gui.add_tab_group(order=5.0)
        self.tab_tuning = self.tabs.add_tab("Tuning")
        self.tab_mpc = self.tabs.add_tab("MPC")
        self.tab_safety = self.tabs.add_tab("Safety")
        self.tab_session = self.tabs.add_tab("Session")
        self.tab_review = self.tabs.add_tab("Review")
        with self.tab_tuning:
            self.journal = gui.add_markdown("Journal: no changes yet.", order=100.0)
        with self.tab_mpc:
            self.introspection = gui.add_markdown("No plans yet.")
        with self.tab_safety:
            self.failsafes = gui.add_markdown("")
        with self.tab_session:
            self.events = gui.add_markdown("No events yet.", order=100.0)

        self.plot_panel = gui.add_panel(order=50.0)
        self.feeder = PlotFeeder(int(math.ceil(cfg.max_history * cfg.plot_rate)) + 2)
        with self.plot_panel.add_tab("Plots"):
            self.plots = LivePlots(gui, self.feeder, rate=cfg.plot_rate, max_points=cfg.max_plot_points,
                                   corridor=self._corridor)
        # each page's review of recorded sessions goes here (its plots in this tab)
        self.review_plot_tab = self.plot_panel.add_tab("Review plots")
        self.plot_panel.dock_left()
        self.plot_panel.set_width(460)

        self._unsubs = [
            supervisor.stream.subscribe(self.feeder.on_message, PLOT_CHANNELS),
            supervisor.stream.subscribe(self._on_message, [
                ch.BODY_STATE, ch.EVENTS, *(ch.fin_state(i) for i in range(N_FINS)),
                *(ch.fin_plan(i) for i in range(N_FINS)),
            ]),
        ]
        supervisor.add_listener(self.request_refresh)
        server.on_client_connect(self._on_connect)
        server.on_client_disconnect(self._on_disconnect)
        self._unsubs.append(lambda: self.replay_slot.cancel())

    # ------------------------------------------------------------------ lifecycle
    @property
    def port(self) -> int:
        return self.server.get_port()

    @property
    def url(self) -> str:
        host = self.host if self.host not in ("0.0.0.0", "::") else "127.0.0.1"
        if ":" in host:
            host = f"[{host}]"
        return f"http://{host}:{self.port}"

    def start(self) -> None:
        if self._thread is not None:
            raise RuntimeError("the console app is already running")
        self._thread = threading.Thread(target=self._run, name="console-ui", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        for unsub in self._unsubs:
            unsub()
        self.guard.stop()
        with self._build_lock:
            reviews, self.reviews = list(self.reviews.values()), {}
        for r in reviews:
            r.stop()
        self.server.stop()

    # ------------------------------------------------------------------ stream side
    def _on_message(self, channel: str, msg: Any) -> None:
        tp = type(msg)
        if tp is BodyState:
            self._body = msg
            self._body_wall = time.time()
            self._body_seq += 1
        elif tp is FinState:
            self._fins[msg.fin] = msg
        elif tp is FinPlan:
            self._plans[msg.fin] = msg
        elif tp is Event:
            if msg.code not in _QUIET_EVENTS:
                self._events.append(msg)

    def _corridor(self) -> tuple[float, float]:
        m = self.sup.tuning()["mpc"]
        return m.st_low, m.st_high

    # ------------------------------------------------------------------ pages
    def _on_connect(self, client: viser.ClientHandle) -> None:
        """A page has shown (its first camera report): build its controls and its review."""
        cid = client.client_id
        containers = {"tuning": self.tab_tuning, "session": self.tab_session, "safety": self.tab_safety}
        with self._build_lock:
            if cid not in self.guard.clients:
                return  # gone while waiting
            panel = panels.ControlPanel(self, cid, client.gui, client, containers, allow=self._allow(cid))
            review = self.build_review(client.gui, client.scene, cid)
            with self._lock:
                self.panels[cid] = panel
            self.reviews[cid] = review
        log.info("page connected: client %s (%s)", cid, self.guard.address(cid) or "?")
        if self.initial_session is not None:
            review.act(lambda: review.open(self.initial_session))

    def _allow(self, cid: int) -> Callable[..., None]:
        def allow(handle: Any, pilot_only: bool, max_len: int = 200) -> None:
            if handle is not None:
                self.guard.allow(handle, cid, pilot_only=pilot_only, max_len=max_len)
        return allow

    def build_review(self, gui: Any, scene: Any, cid: int | None = None) -> PlaybackPanel:
        """One page's review of recorded sessions, in the Review tab and the review plots."""
        cfg = self.cfg
        return PlaybackPanel(
            gui, scene, self.sup.cfg.plant.geometry, directory=self.sessions_dir,
            plot_rate=cfg.plot_rate, scene_rate=cfg.scene_rate, max_plot_points=cfg.max_plot_points,
            history=lambda: self.history, max_history=cfg.max_history, corridor=self._corridor,
            trail_points=cfg.trail_points, trail_spacing=cfg.trail_spacing,
            container=self.tab_review, plot_container=self.review_plot_tab,
            allow=self._allow(cid) if cid is not None else None,
            replay_slot=self.replay_slot, may_replay=lambda: self._may_replay(cid),
        )

    def _may_replay(self, cid: int | None) -> None:
        """CommandRefused unless page ``cid`` may start a counterfactual replay now: any page
        while the robot is disarmed; only the pilot while it is armed (the replay takes CPU)."""
        if self.sup.armed and (cid is None or not self.sup.access.is_pilot(cid)):
            raise CommandRefused("counterfactual replay: while the robot is armed only the pilot may start one")

    def _on_disconnect(self, client: viser.ClientHandle) -> None:
        cid = client.client_id
        with self._build_lock:
            with self._lock:
                self.panels.pop(cid, None)
            review = self.reviews.pop(cid, None)
        if review is not None:
            review.stop(page_gone=True)
        log.info("page gone: client %s", cid)

    def request_refresh(self) -> None:
        """Refresh every page's controls at the next UI tick (any thread)."""
        self._dirty.set()

    def set_history(self, who: Any, seconds: object) -> None:
        """The plots' time window (the pilot's choice; every page shows the same plots)."""
        self.sup.access.require_pilot(who, "plot history")
        if isinstance(seconds, bool) or not isinstance(seconds, (int, float)) or not math.isfinite(seconds):
            raise CommandRefused(f"history: expected a number of seconds, got {seconds!r}")
        if not 5.0 <= seconds <= self.cfg.max_history:
            raise CommandRefused(f"history: {seconds!r} s is out of range; allowed: [5, {self.cfg.max_history:g}] s")
        self.history = float(seconds)
        self.request_refresh()

    # ------------------------------------------------------------------ UI thread
    def _run(self) -> None:
        cfg = self.cfg
        period = 1.0 / cfg.scene_rate
        plot_period = 1.0 / cfg.plot_rate
        next_tick = time.perf_counter()
        next_plot = next_slow = next_tick
        last_seq = -1
        while not self._stop.is_set():
            now = time.perf_counter()
            try:
                seq = self._body_seq
                if seq != last_seq:
                    last_seq = seq
                    self._tick_scene()
                if now >= next_plot:
                    next_plot += plot_period
                    if self.feeder.sample():
                        self.plots.refresh(self.history)
                if now >= next_slow:
                    next_slow = now + _SLOW_PERIOD
                    self._tick_slow()
                if self._dirty.is_set():
                    self._dirty.clear()
                    self._refresh_panels()
            except Exception:
                self.tick_errors += 1
                log.exception("UI update failed")
            next_tick += period
            delay = next_tick - time.perf_counter()
            if delay < -1.0:  # far behind (machine suspended): do not try to catch up
                next_tick = time.perf_counter()
                next_plot = next_slow = next_tick
            self._stop.wait(max(delay, 0.0))

    def _tick_scene(self) -> None:
        body = self._body
        with self.server.atomic():
            self.scene.update_pose(body, list(self._fins))
            if self.probe is not None and body is not None:
                self.probe.content = (f'<span id="ucat-probe" data-seq="{self._body_seq}" '
                                      f'data-wall="{self._body_wall * 1e3:.1f}" data-t="{body.t:.3f}"></span>')

    def _tick_slow(self) -> None:
        sup = self.sup
        body = self._body
        self.scene.update_label(body)
        self.scene.update_trail()
        h = sup.health()
        _set(self.status, panels.status_markdown(
            armed=h.armed, mode=h.mode, pilot=sup.access.pilot, t=h.t,
            depth=body.depth if body else None, velocity=body.velocity[0] if body else None,
            failsafes=h.failsafes, recording=h.recording, fault=h.fault,
        ))
        _set(self.introspection, panels.introspection_markdown(list(self._plans), h.late_plans,
                                                              h.plan_overruns, h.mode))
        _set(self.failsafes, panels.failsafe_markdown(sup.safety.states(), h.t))
        _set(self.journal, panels.journal_markdown(sup.journal(12)))
        _set(self.events, panels.events_markdown(list(self._events)))

    def _refresh_panels(self) -> None:
        live = set(self.guard.clients)
        with self._lock:
            for cid in [c for c in self.panels if c not in live]:
                del self.panels[cid]  # a page that went while its panel was being built
            ps = list(self.panels.values())
        for p in ps:
            try:
                p.refresh()
            except Exception:
                log.exception("refreshing the controls of client %s failed", p.cid)


def _no_share_url(*args: Any, **kwargs: Any) -> None:
    """A page may not open a public share tunnel to the console."""
    log.warning("a page asked for a public share URL: refused")
    return None


def _set(handle: Any, content: str) -> None:
    if handle.content != content:
        handle.content = content
