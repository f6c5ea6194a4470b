"""The page served while the console prepares its compiled code (the first start on a machine).

``ucat-console run`` serves this page on the console's address at once, with a progress
bar and the same status bar as the console (disarmed, nothing to arm), while
:mod:`ucat_console.backend.prepare` compiles in a child process. When the code is ready the
console takes this page's server over (:meth:`LoadingPage.hand_over`): one server for the
whole run, so the terminal shows one address and viser's "Server stopped" only when the
console stops. The progress goes from the server and the console's page is built in its
place; a page open meanwhile gets the console without reloading (viser replays the
console's page building for every page connected). The page passes through the same
:class:`~ucat_console.ui.guard.PageGuard` the console goes on with, from the server's start,
with no inputs at all: nothing a page sends changes anything until the console allows it.
"""

from __future__ import annotations

import threading
import time
from typing import Any, Callable

import viser

from ucat_console.backend.prepare import Progress
from ucat_console.config import AppConfig
from ucat_console.ui import page_script
from ucat_console.ui.guard import PageGuard
from ucat_console.ui.viser_compat import run_javascript


class _PageEvents:
    """The guard's page callbacks, handed from the loading page to the console once: every
    page that opened before the hand-over and is still open is announced to the console
    exactly once (:meth:`hand_over`), every later one as it opens."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._open: dict[int, str] = {}  # before the hand-over: client -> its address
        self._connect: Callable[[int, str], None] | None = None
        self._disconnect: Callable[[int], None] = lambda c: None
        self._gone: Callable[[int, float], None] = lambda c, s: None

    def connected(self, client: int, address: str) -> None:
        with self._lock:
            if self._connect is None:
                self._open[client] = address
                return
            self._connect(client, address)

    def disconnected(self, client: int) -> None:
        with self._lock:
            self._open.pop(client, None)
            self._disconnect(client)

    def gone(self, client: int, silent_for: float) -> None:
        with self._lock:
            self._gone(client, silent_for)

    def hand_over(self, on_connect: Callable[[int, str], None], on_disconnect: Callable[[int], None],
                  on_gone: Callable[[int, float], None]) -> None:
        with self._lock:
            self._connect, self._disconnect, self._gone = on_connect, on_disconnect, on_gone
            opened, self._open = self._open, {}
            for client, address in opened.items():
                on_connect(client, address)


class LoadingPage:
    def __init__(self, cfg: AppConfig, host: str, port: int) -> None:
        c = cfg.console
        self._events = _PageEvents()
        self.guard = PageGuard(is_pilot=lambda cid: False, pilot_timeout=lambda: cfg.failsafe.pilot_gone.timeout,
                               page_timeout=c.page_timeout, heartbeat_period=c.heartbeat_period,
                               allowed_origins=c.allowed_origins, max_per_address=c.max_pages_per_address,
                               on_connect=self._events.connected, on_disconnect=self._events.disconnected,
                               on_gone=self._events.gone)
        self.host = host
        self.server = self.guard.serve(host=host, port=port, verbose=False, label="U-CAT console")
        self.server.gui.configure_theme(control_width="medium", show_share_button=False, dark_mode=c.dark)
        self.server.request_share_url = lambda *a, **k: None  # type: ignore[method-assign]
        gui = self.server.gui
        self.text = gui.add_markdown("**Starting the console.** Preparing the compiled planners ...")
        self.bar = gui.add_progress_bar(0.0, animated=True)
        self.note = gui.add_markdown("The first start on a machine compiles the planners (one to two minutes on "
                                     "two cores, `ucat-console bench compile` measures it); later starts take "
                                     "seconds. This page turns into the console when it is ready; arming is "
                                     "possible from then on.")
        self._t0 = time.monotonic()
        self._progress = Progress(0, 1, "the planners")
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._handed = False  # the console has the server
        self.server.on_client_connect(self._on_connect)
        self._thread = threading.Thread(target=self._run, name="loading-page", daemon=True)
        self._thread.start()

    @property
    def port(self) -> int:
        return self.server.get_port()

    def _on_connect(self, client: Any) -> None:
        if not self._handed:  # the console installs the page's script itself
            self.guard.send_first(client.client_id, [run_javascript(page_script.INSTALL)])

    def set_progress(self, p: Progress) -> None:
        with self._lock:
            self._progress = p
        if self._stop.is_set():
            return
        self._show()
        self.bar.value = 100.0 * p.done / max(p.total, 1)

    def _show(self) -> None:
        p = self._progress
        self.text.content = (f"**Starting the console.** {p.text().capitalize()} ... "
                             f"({time.monotonic() - self._t0:.0f} s)")

    def _state(self) -> dict[str, Any]:
        p = self._progress
        why = p.text()
        return {"armed": False, "mode": "-", "pilot": "none (the console is starting)", "you_pilot": False,
                "recording": "", "failsafes": [], "battery": "",
                "lights": [{"name": "Planner", "state": "warn", "why": why}],
                "link_policy": "The console is starting; this page turns into it by itself.",
                "dark": True, "disarm_uuid": "", "drive_uuid": "", "theme_uuid": ""}

    def _run(self) -> None:
        ticks = 0
        while not self._stop.wait(0.25):
            ticks += 1
            if ticks % 4 == 0:  # the time taken, every second: a compile shows no progress of its own
                self._show()
            src = page_script.update_source(self._state())
            for client in self.server.get_clients().values():
                try:
                    self.guard.send_first(client.client_id, [run_javascript(src)])
                except Exception:
                    pass

    def _end_progress(self) -> None:
        self._stop.set()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)

    def hand_over(self, *, is_pilot: Callable[[int], bool], pilot_timeout: Callable[[], float],
                  on_connect: Callable[[int, str], None], on_disconnect: Callable[[int], None],
                  on_gone: Callable[[int, float], None]) -> tuple[PageGuard, viser.ViserServer]:
        """The console takes the server over: the progress stops and its elements go; the
        guard (which has checked every page from the server's start) answers with the
        console's callbacks from now on, ``on_connect`` called at once for each page open
        now. Returns (the guard, the server); the console stops them when it stops."""
        self._end_progress()
        self._handed = True
        for handle in (self.text, self.bar, self.note):
            handle.remove()
        self.guard.is_pilot = is_pilot
        self.guard.pilot_timeout = pilot_timeout
        self._events.hand_over(on_connect, on_disconnect, on_gone)
        return self.guard, self.server

    def stop(self) -> None:
        """Stop serving (a start that ends before the console takes the server over)."""
        self._end_progress()
        self.guard.stop()
        self.server.stop()
