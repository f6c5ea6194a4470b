"""The console's web page: a viser server showing the supervisor's telemetry stream.

Layout: a fixed status bar at the top of every page (armed state, mode, pilot, link,
recording, failsafes, a light per sensor, the drives and the planner, DISARM: the page's
own script, :mod:`ucat_console.ui.page_script`); the plots docked on the left; the controls
docked on the right, the pilot's section (token, arming, mode, setpoints, key map) first
and the tabs (Tuning, MPC, Safety, Session, Review) below; the 3-D view in the middle.

:class:`ConsoleApp` subscribes to the supervisor's stream (it never reads the loop
directly). The live view is a :class:`~ucat_console.ui.view.StreamView` (the same class
each page's review uses) pushing the 3-D robot at up to ``console.scene_rate`` and the
plots at ``console.plot_rate``; at 4 Hz the app also sends every page its status bar, and
updates MPC introspection, failsafes, journal, events, the follow cameras, and every page's
controls when the supervisor's state changed.

Shared elements (3-D view, plots, introspection) are server-wide; each page's controls are
its own (:class:`~ucat_console.ui.panels.ControlPanel`), and so is its review of recorded
sessions (:class:`~ucat_console.ui.playback.PlaybackPanel`: every page reviews on its own,
with its own player, position and review plots, so no page can move what another is
reviewing; while it reviews, its 3-D view shows the reviewed robot in place of the live
one). A page's panels are built when it connects, one page at a time (viser runs connect
callbacks concurrently, and the shared tabs they fill are not safe to enter from two
threads at once). Each page chooses its theme (dark by default), remembered by its browser.

Every page passes through a :class:`~ucat_console.ui.guard.PageGuard`: its handshake's
Origin, every message it sends (only the values of its own inputs, pilot-only inputs only
while it is the pilot's) and its heartbeat; a page that stops answering is gone, and when
it was the pilot's the pilot-gone failsafe acts. The pilot's safety commands run on the
guard's own thread; the status bar goes to each page ahead of its telemetry, which a page
on a slow link gets thinned (the bar then says "link slow"). What reads session files runs
on the console's :class:`~ucat_console.ui.page_jobs.PageJobs`, rationed per page, with one
listing of the sessions folder shared by every page (:class:`~ucat_console.ui.session_list.SessionList`). The server binds to ``console.host``
(127.0.0.1 by default) and warns when that is not a loopback address: viser has no
authentication of its own, and the pilot token guards only the controls, not what the
page shows.

With ``probe=True`` a tiny HTML element carries, with every pose update and in the same
batch, the wall-clock time at which the shown BodyState was published; the UI benchmark
reads it in the page to measure update rates and latency.
"""

from __future__ import annotations

import collections
import contextlib
import ipaddress
import logging
import math
import threading
import time
from typing import TYPE_CHECKING, Any, Callable, Iterator

import viser

from ucat_console.backend.sessions.replay_job import ReplaySlot
from ucat_console.backend.access import LOCAL
from ucat_console.backend.supervisor import CommandRefused, ConsoleState, Supervisor
from ucat_console.robot.fins import N_FINS
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.messages import FinPlan
from ucat_console.ui import markdown, page_script, panels
from ucat_console.ui import viser_compat
from ucat_console.ui.compare_panel import ComparePanel
from ucat_console.ui.guard import Burst, PageGuard
from ucat_console.ui.metrics_panel import MetricsPanel, effects_markdown
from ucat_console.ui.page_jobs import PageJobs
from ucat_console.ui.playback import PlaybackPanel
from ucat_console.ui.run_list import describe_run, runs_access
from ucat_console.ui.scene import add_pool
from ucat_console.ui.session_list import SessionList
from ucat_console.ui.status_bar import bar_state
from ucat_console.ui.camera_panel import PageCameras
from ucat_console.ui.view import StreamView

if TYPE_CHECKING:
    from ucat_console.ui.loading import LoadingPage

log = logging.getLogger(__name__)
#: how far (m) the followed robot moves before the camera follows it
FOLLOW_STEP = 0.02

_EVENTS_KEPT = 200
_QUIET_EVENTS = frozenset({"stroke_timeout"})
#: events every page is notified of (source, code): what the operators must see at once
ALARMS = frozenset({("recorder", "write_failed")})
#: events that end an alarm's notification (source, code)
ALARM_ENDS = frozenset({("recorder", "failure_cleared")})
#: the docked panels' widths (px): plots on the left, controls on the right
PLOTS_WIDTH = 400
CONTROLS_WIDTH = 360
#: plot height (px): the five live plots fit a 1280x800 window below the status bar
PLOT_HEIGHT = 108
FOLLOW_PERIOD = 0.1  # s between follow-camera moves


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class _Page:
    """What the app keeps of one page besides its panels: theme and camera following."""

    def __init__(self, client: Any, dark: bool) -> None:
        self.client = client
        self.dark = dark
        self.followed: tuple[float, float, float] | None = None
        self.follow_failed = Burst()  # moves of its camera that failed


class ConsoleApp:
    """The viser app of one supervisor (module docstring)."""

    def __init__(self, supervisor: Supervisor, *, host: str | None = None, port: int | None = None,
                 probe: bool = False, loading_page: LoadingPage | None = None) -> None:
        self.sup = supervisor
        cfg = supervisor.cfg.console
        self.cfg = cfg
        self.host = loading_page.host if loading_page is not None else cfg.host if host is None else host
        if not is_loopback(self.host):
            log.warning("the console binds to %s: anyone who reaches it sees the live page "
                        "(control still needs the pilot token); use 127.0.0.1 unless you mean it",
                        self.host)
        self.history = cfg.history
        self._lock = threading.Lock()
        self._plans: list[FinPlan | None] = [None] * N_FINS
        self._events: collections.deque[Event] = collections.deque(maxlen=_EVENTS_KEPT)
        self._alarms: collections.deque[Event] = collections.deque(maxlen=10)  # to notify every page of
        self.events_seen = 0  # events kept so far: the pages' lists change with it
        self._dirty = threading.Event()
        self.panels: dict[int, panels.ControlPanel] = {}
        self.reviews: dict[int, PlaybackPanel] = {}
        self.pages: dict[int, _Page] = {}
        self._build_lock = threading.Lock()
        self._next_follow = 0.0
        #: a session every new page opens in its Review tab (``run --playback``)
        self.initial_session: str | None = None
        self.sessions_dir = supervisor.sessions_dir
        self.session_list = SessionList(self.sessions_dir, supervisor.readers.budget)
        self.jobs = PageJobs()  # what reads session files, for every page
        self.replay_slot = ReplaySlot(supervisor.readers.budget.config)
        #: what the planner light says while the planners load ("" when ready)
        self.loading = ""
        #: this run of the console, as the pages' bars carry it (a page that comes back to
        #: another run says the console restarted)
        self.run_id = {"id": f"{time.time_ns():x}", "started": time.strftime("%H:%M:%S")}

        pages = dict(
            is_pilot=supervisor.is_pilot,
            pilot_timeout=lambda: supervisor.cfg.failsafe.pilot_gone.timeout,
            on_connect=supervisor.client_connected,
            on_disconnect=supervisor.client_disconnected,
            on_gone=lambda cid, silent: supervisor.client_disconnected(cid, silent_for=silent),
        )
        if loading_page is not None:  # its server goes on as the console's: one server for the run
            self.guard, server = loading_page.hand_over(**pages)
        else:
            self.guard = PageGuard(page_timeout=cfg.page_timeout, heartbeat_period=cfg.heartbeat_period,
                                   allowed_origins=cfg.allowed_origins, max_per_address=cfg.max_pages_per_address,
                                   **pages)
            server = self.guard.serve(host=self.host, port=cfg.port if port is None else port, verbose=False,
                                      label="U-CAT console")
        self.server = server
        self._theme(server.gui, cfg.dark)
        server.request_share_url = _no_share_url  # type: ignore[method-assign]
        add_pool(server.scene, floor_depth=cfg.floor_depth, shadows=cfg.shadows, environment_map=cfg.environment_map)
        gui = server.gui
        gui.main_panel.dock_right()
        gui.main_panel.set_width(CONTROLS_WIDTH)
        self.probe = gui.add_html("", order=0.5) if probe else None
        self.tabs = gui.add_tab_group(order=5.0)
        self.tab_tuning = self.tabs.add_tab("Tuning")
        self.tab_mpc = self.tabs.add_tab("MPC")
        self.tab_safety = self.tabs.add_tab("Safety")
        self.tab_session = self.tabs.add_tab("Session")
        self.tab_review = self.tabs.add_tab("Review")
        with self.tab_tuning:
            self.journal = gui.add_markdown("Journal: no changes yet.", order=100.0)
            self.effects = gui.add_markdown("", order=101.0)
        with self.tab_mpc:
            self.introspection = gui.add_markdown("No plans yet.")
        with self.tab_safety:
            self.failsafes = gui.add_markdown("")

        self.plot_panel = gui.add_panel(order=50.0)
        with self.plot_panel.add_tab("Live plots"):
            self.metrics = MetricsPanel(gui, supervisor.cfg.metrics, order=0.0)
            self.view = StreamView(
                server.scene, gui, supervisor.cfg.plant.geometry, plot_rate=cfg.plot_rate,
                scene_rate=cfg.scene_rate, max_plot_points=cfg.max_plot_points, history=lambda: self.history,
                max_history=cfg.max_history, corridor=self._corridor, trail_points=cfg.trail_points,
                trail_spacing=cfg.trail_spacing, atomic=lambda: _sent_at_once(server), on_slow=self._tick_slow,
                on_tick=self._tick, on_pose=self._probe if probe else None, plot_height=PLOT_HEIGHT, name="live",
            )
        # each page's review of recorded sessions goes here (its plots in this tab)
        self.review_plot_tab = self.plot_panel.add_tab("Review plots")
        #: the shared containers the pages' own elements go into
        self.shared_tabs = (self.tab_tuning, self.tab_session, self.tab_safety, self.tab_review, self.review_plot_tab)
        self.plot_panel.dock_left()
        self.plot_panel.set_width(PLOTS_WIDTH)
        self.scene = self.view.show()
        self.plots = self.view.plots

        self._unsubs = [
            *self.view.subscribe(supervisor.stream),
            self.metrics.subscribe(supervisor.stream),
            supervisor.stream.subscribe(self._on_message, [ch.EVENTS, *(ch.fin_plan(i) for i in range(N_FINS))]),
        ]
        self.cameras = PageCameras(supervisor.stream, supervisor.cfg.camera)  # each page's camera picture
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

    @property
    def tick_errors(self) -> int:
        return self.view.tick_errors

    def start(self) -> None:
        if self.view.running:
            raise RuntimeError("the console app is already running")
        self.view.start()

    def stop(self) -> None:
        self.view.stop()
        for unsub in self._unsubs:
            unsub()
        self.cameras.close()
        self.guard.stop()
        self.jobs.stop()
        with self._build_lock:
            reviews, self.reviews = list(self.reviews.values()), {}
        for r in reviews:
            r.stop(page_gone=True)  # the server goes, and every page's elements with it
        self.server.stop()

    # ------------------------------------------------------------------ stream side
    def _on_message(self, channel: str, msg: Any) -> None:
        tp = type(msg)
        if tp is FinPlan:
            self._plans[msg.fin] = msg
        elif tp is Event and msg.code not in _QUIET_EVENTS:
            self._events.append(msg)
            self.events_seen += 1
            if (msg.source, msg.code) in ALARMS or (msg.source, msg.code) in ALARM_ENDS:
                self._alarms.append(msg)

    def recent_events(self) -> list[Event]:
        return list(self._events)

    def _corridor(self) -> tuple[float, float]:
        m = self.sup.tuning()["mpc"]
        return m.st_low, m.st_high

    # ------------------------------------------------------------------ pages
    def _on_connect(self, client: viser.ClientHandle) -> None:
        """A page has shown (its first camera report): its script, theme, controls and review.

        A page may go at any moment of this: viser forgets it first (:meth:`page_present`),
        then calls :meth:`_on_disconnect`, which waits for the build. So a page found gone
        after its build was gone before :meth:`_on_disconnect` could see its panels: what
        the build made is let go of here (:meth:`_let_go`)."""
        cid = client.client_id
        containers = {"tuning": self.tab_tuning, "session": self.tab_session, "safety": self.tab_safety}
        self.guard.send_first(cid, [viser_compat.run_javascript(page_script.INSTALL)])  # the bar first
        with self._build_lock:
            if not self.page_present(cid):
                return  # gone while waiting
            review: PlaybackPanel | None = None
            # one atomic batch: the page gets its controls only with the guard's rules for
            # them, so nothing it sends at once is refused as "not an input of this page"
            try:
                with client.atomic():
                    panel = panels.ControlPanel(self, cid, client.gui, client, containers, allow=self._allow(cid))
                    self.cameras.add(cid, client.gui, self._allow(cid))
                    review = self.build_review(client.gui, client.scene, cid)
                    compare = ComparePanel(
                        client.gui, self.tab_review, self.sessions_dir, cfg=self.sup.cfg.metrics,
                        sessions=self.session_list.sessions, allow=self._allow(cid), client=client,
                        jobs=self._jobs_of(cid), present=lambda: self.page_present(cid),
                        budget=self.sup.readers.budget, describe=lambda sid: describe_run(self.sup, sid))
                    # a recording that ends shows in the page's lists by itself
                    panel.session_lists += [lambda: review.act(review.refresh_sessions),
                                            lambda: compare.act(compare.refresh)]
            except Exception:
                if self.page_present(cid):
                    raise
                panel = None
            if panel is None or not self.page_present(cid):
                log.info("page %s went while its controls were built", cid)
                self._let_go(client, review)
                return
            with self._lock:
                self.panels[cid] = panel
                self.pages[cid] = _Page(client, self.cfg.dark)
            self.reviews[cid] = review
        log.info("page connected: client %s (%s)", cid, self.guard.address(cid) or "?")
        self._place_camera(client, self.view.scene)
        threading.Thread(target=self._remembered_theme, args=(cid,), name="page-theme", daemon=True).start()
        if self.initial_session is not None:
            review.act(lambda: review.open(self.initial_session))

    def _place_camera(self, client: Any, scene: Any) -> tuple[float, float, float]:
        """The page looks at the robot of ``scene`` from behind, to port and a little above it
        (where it is; without a pose yet, where the simulated robot starts); the point looked at.
        The position goes first: viser moves the point looked at with the position."""
        p = scene.world_position() if scene is not None else None
        x, y, z = p if p is not None else (0.0, 0.0, -max(self.sup.start_depth, 0.3))
        try:
            with client.atomic():
                client.camera.position = (x - 1.0, y + 0.8, z + 0.35)
                client.camera.look_at = (x, y, z)
        except Exception:
            log.debug("placing the camera of client %s failed", client.client_id, exc_info=True)
        return x, y, z

    def _shown_scene(self, cid: int) -> Any:
        """The robot page ``cid`` shows: the one it reviews, else the live one."""
        review = self.reviews.get(cid)
        return review.view.scene if review is not None and review.player is not None else self.view.scene

    def frame_robot(self, cid: int) -> None:
        """*Frame the robot*: page ``cid``'s camera looks at the robot it shows (following it
        from there when it follows)."""
        page = self.pages.get(cid)
        if page is not None:
            page.followed = self._place_camera(page.client, self._shown_scene(cid))

    def _allow(self, cid: int) -> Callable[..., None]:
        def allow(handle: Any, pilot_only: bool, max_len: int = 200, urgent: Callable[[], None] | None = None) -> None:
            if handle is not None:
                self.guard.allow(handle, cid, pilot_only=pilot_only, max_len=max_len, urgent=urgent)
        return allow

    def page_present(self, cid: int) -> bool:
        """Whether page ``cid`` is connected (viser forgets a page before it removes the
        page's elements: a callback that finds its element removed and this False only
        lost its page)."""
        return cid in self.server.get_clients()

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
            replay_slot=self.replay_slot, may_replay=lambda: self.sup.may_replay(cid), plot_height=PLOT_HEIGHT,
            metrics=self.sup.cfg.metrics, readers=self.sup.readers,
            jobs=self._jobs_of(cid) if cid is not None else None,
            present=(lambda: self.page_present(cid)) if cid is not None else (lambda: True),
            sessions=lambda: self.session_list.listing(),
            may_repair=(lambda: self.sup.require_pilot(cid, "repair")) if cid is not None else (lambda: None),
            runs=runs_access(self.sup, cid if cid is not None else LOCAL),
        )

    def submit_job(self, cid: int, what: str, job: Callable[[], Any], coalesce: bool = False) -> str | None:
        """Queue ``job`` (a kind ``what``) on the page jobs for page ``cid``: None when queued,
        else why not. A page that has gone has no job queued, and none of its jobs runs:
        whatever a job holds of its page (its panels, its elements) is let go of with the page."""
        if not self.page_present(cid):
            return f"{what}: the page has gone"
        why = self.jobs.submit(cid, what, lambda: job() if self.page_present(cid) else None, coalesce=coalesce)
        if not self.page_present(cid):  # gone meanwhile: its jobs may have been forgotten before this one came
            self.jobs.forget(cid)
        return why

    def _jobs_of(self, cid: int) -> Callable[[str, Callable[[], Any], bool], str | None]:
        """``jobs(what, job, coalesce)`` of page ``cid``'s panels (:meth:`submit_job`)."""
        return lambda what, job, coalesce: self.submit_job(cid, what, job, coalesce)

    def _on_disconnect(self, client: viser.ClientHandle) -> None:
        cid = client.client_id
        with self._build_lock:  # after its build, if it is being built
            with self._lock:
                self.panels.pop(cid, None)
                self.pages.pop(cid, None)
            review = self.reviews.pop(cid, None)
        self._let_go(client, review)
        log.info("page gone: client %s", cid)

    def _let_go(self, client: Any, review: PlaybackPanel | None) -> None:
        """Everything the console keeps of a page that has gone: its review, its jobs, the
        guard's rules for its inputs, its elements in the shared tabs."""
        cid = client.client_id
        self.cameras.remove(cid)
        if review is not None:
            review.stop(page_gone=True)
        self.jobs.forget(cid)
        self.guard.forget_page(cid)
        viser_compat.release_page_elements(client, self.shared_tabs)

    def request_refresh(self) -> None:
        """Refresh every page's controls at the next UI tick (any thread)."""
        self._dirty.set()

    def set_history(self, who: Any, seconds: object) -> None:
        """The plots' time window (the pilot's choice; every page shows the same plots)."""
        self.sup.require_pilot(who, "plot history")
        if isinstance(seconds, bool) or not isinstance(seconds, (int, float)) or not math.isfinite(seconds):
            raise CommandRefused(f"history: expected a number of seconds, got {seconds!r}")
        if not 5.0 <= seconds <= self.cfg.max_history:
            raise CommandRefused(f"history: {seconds!r} s is out of range; allowed: [5, {self.cfg.max_history:g}] s")
        self.history = float(seconds)
        self.request_refresh()

    # ------------------------------------------------------------------ theme
    @staticmethod
    def _theme(gui: Any, dark: bool) -> None:
        gui.configure_theme(control_width="medium", show_share_button=False, dark_mode=dark)

    def _remembered_theme(self, cid: int) -> None:
        """The theme this page's browser chose before (it asks the page; no answer within 20 s,
        which a page loading on a slow link or a busy machine may take: the default)."""
        page = self.pages.get(cid)
        if page is None:
            return
        try:
            stored = page.client.local_storage.get_item(page_script.THEME_KEY, timeout=20.0)
        except Exception:
            stored = None
        if stored in ("dark", "light"):
            page.dark = stored == "dark"
        self._theme(page.client.gui, page.dark)

    def toggle_theme(self, cid: int) -> None:
        """Dark <-> light for one page, remembered by its browser."""
        page = self.pages.get(cid)
        if page is None:
            return
        page.dark = not page.dark
        page.client.local_storage.set_item(page_script.THEME_KEY, "dark" if page.dark else "light")
        self._theme(page.client.gui, page.dark)

    # ------------------------------------------------------------------ UI thread (the live view's)
    def _probe(self) -> None:
        body, probe = self.view.body, self.probe
        if probe is not None and body is not None:
            probe.content = (f'<span id="ucat-probe" data-seq="{self.view.body_seq}" '
                             f'data-wall="{self.view.body_wall * 1e3:.1f}" data-t="{body.t:.3f}"></span>')

    def _tick(self) -> None:
        self.cameras.tick(self.guard.link_slow)
        if self._dirty.is_set():
            self._dirty.clear()
            self._refresh_panels()
        now = time.monotonic()
        if now >= self._next_follow:
            self._next_follow = now + FOLLOW_PERIOD
            self._follow()

    def _notify_pages(self) -> None:
        """Every page gets a notification of each alarm (it stays until closed), and of its end."""
        while self._alarms:
            ev = self._alarms.popleft()
            alarm = (ev.source, ev.code) in ALARMS
            with self._lock:
                pages = list(self.pages.values())
            for page in pages:
                try:
                    page.client.add_notification(
                        f"ALARM: {ev.source} {ev.code}" if alarm else f"{ev.source}: cleared", ev.message,
                        color="red" if alarm else "green", with_close_button=True,
                        auto_close_seconds=None if alarm else 10.0)
                except Exception:
                    log.debug("client %s was not notified", page.client.client_id, exc_info=True)

    def _tick_slow(self) -> None:
        self._notify_pages()
        self.metrics.refresh()
        sup = self.sup
        st = sup.state()  # one snapshot for every page of this tick
        _set(self.introspection, markdown.introspection_markdown(list(self._plans), st.late_plans,
                                                              st.plan_overruns, st.mode))
        _set(self.failsafes, self.failsafe_text(st))
        _set(self.journal, markdown.journal_markdown(sup.journal(12)))
        _set(self.effects, effects_markdown(list(st.effects), st.t))
        with self._lock:
            pages = list(self.pages.items())
            ps = dict(self.panels)
            reviews = dict(self.reviews)
        for cid, page in pages:
            panel = ps.get(cid)
            if panel is None:
                continue
            review = reviews.get(cid)
            try:
                panel.show_events()
                uuids = {f"{name}_uuid": viser_compat.handle_uuid(handle) for name, handle in
                         (("disarm", panel.disarm), ("drive", panel.drive_input), ("theme", panel.theme_button),
                          ("token", panel.token), ("take", panel.take))}
                state = bar_state(st, cid, dark=page.dark, uuids=uuids, loading=self.loading,
                                  link_slow=self.guard.link_slow(cid),
                                  review=review.reviewing if review is not None else "", console=self.run_id)
                # what the pilot must see first (ahead of the telemetry on a slow link)
                self.guard.send_first(cid, [viser_compat.run_javascript(page_script.update_source(state))])
            except Exception:
                log.debug("the status bar of client %s was not sent", cid, exc_info=True)

    @staticmethod
    def failsafe_text(st: ConsoleState) -> str:
        """The Safety tab's text: the failsafes' table, and the protective ones set only to warn."""
        text = markdown.failsafe_markdown(list(st.safety.failsafes), st.t)
        warn_only = st.safety.warn_only
        if warn_only:
            text += ("\n\n**Set to warn only** (they will not act on the robot): "
                     + ", ".join(warn_only) + ".")
        return text

    def _follow(self) -> None:
        """Move each following page's camera with the robot it shows (live or reviewed)."""
        with self._lock:
            pages = list(self.pages.items())
            ps = dict(self.panels)
        live = set(self.guard.clients)
        for cid, page in pages:
            try:
                self._follow_page(page, ps.get(cid), self.reviews.get(cid), cid in live)
            except Exception as e:  # this page's camera only: the others still follow
                page.followed = None
                more = page.follow_failed.note(time.monotonic())
                if more is not None and self.page_present(cid):
                    log.warning("the camera of page %s did not follow the robot: %s: %s%s", cid,
                                type(e).__name__, e, f" ({more} more since the last line)" if more else "")

    def _follow_page(self, page: _Page, panel: panels.ControlPanel | None, review: PlaybackPanel | None,
                     live: bool) -> None:
        if panel is None or not panel.follow.value or not live:
            page.followed = None
            return
        scene = review.view.scene if review is not None and review.player is not None else self.view.scene
        p = scene.world_position() if scene is not None else None
        if p is None:
            return
        if page.followed is not None and math.dist(p, page.followed) < FOLLOW_STEP:
            return  # the camera moves in steps: each move costs the page a re-render
        if page.followed is not None:
            cam = page.client.camera  # keep the camera's offset from the robot, look at it
            offset = tuple(float(a - b) for a, b in zip(cam.position, page.followed, strict=True))
            with page.client.atomic():  # the position first: viser moves the point looked at with it
                cam.position = tuple(a + b for a, b in zip(p, offset))
                cam.look_at = p
        page.followed = p

    def _refresh_panels(self) -> None:
        live = set(self.guard.clients)
        with self._lock:
            ps = [p for cid, p in self.panels.items() if cid in live]
        st = self.sup.state() if ps else None  # one snapshot for every page
        for p in ps:
            try:
                p.refresh(state=st)
            except Exception:
                if p.cid not in self.guard.clients:  # the page went while it was refreshed
                    log.debug("client %s left during a refresh", p.cid)
                    continue
                log.exception("refreshing the controls of client %s failed", p.cid)


def _no_share_url(*args: Any, **kwargs: Any) -> None:
    """A page may not open a public share tunnel to the console."""
    log.warning("a page asked for a public share URL: refused")
    return None


def _set(handle: Any, content: str) -> None:
    if handle.content != content:
        handle.content = content


@contextlib.contextmanager
def _sent_at_once(server: viser.ViserServer) -> Iterator[None]:
    """``server.atomic()`` (the pages apply the pass's messages together), then the batch
    sent at once: viser otherwise waits up to 1/60 s for more messages after each batch (its
    buffer's window), a pose's latency for nothing when the pass is one batch anyway."""
    with server.atomic():
        yield
    server.flush()
