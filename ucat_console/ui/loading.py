"""The page served while the console prepares its compiled code (the first start on a machine).

``ucat-console run`` serves this page on the console's address at once, with a progress
bar and the same status bar as the console (disarmed, nothing to arm), while
:mod:`ucat_console.backend.prepare` compiles in a child process. When the code is ready the
page's server stops and the console starts on the same port; open pages reconnect by
themselves (viser's page retries every second) and get the console. The page passes
through the same :class:`~ucat_console.ui.guard.PageGuard` as the console's, with no
inputs at all: nothing a page sends changes anything.
"""

from __future__ import annotations

import socket
import threading
import time
from typing import Any

from ucat_console.backend.prepare import Progress
from ucat_console.config import AppConfig
from ucat_console.ui import page_script
from ucat_console.ui.guard import PageGuard
from ucat_console.ui.viser_compat import run_javascript


class LoadingPage:
    def __init__(self, cfg: AppConfig, host: str, port: int) -> None:
        c = cfg.console
        self.guard = PageGuard(is_pilot=lambda cid: False, pilot_timeout=lambda: cfg.failsafe.pilot_gone.timeout,
                               page_timeout=c.page_timeout, heartbeat_period=c.heartbeat_period,
                               allowed_origins=c.allowed_origins)
        self.host = host
        self.server = self.guard.serve(host=host, port=port, verbose=False, label="U-CAT console")
        self.server.gui.configure_theme(control_width="medium", show_share_button=False, dark_mode=c.dark)
        self.server.request_share_url = lambda *a, **k: None  # type: ignore[method-assign]
        gui = self.server.gui
        self.text = gui.add_markdown("**Starting the console.** Preparing the compiled planners ...")
        self.bar = gui.add_progress_bar(0.0, animated=True)
        gui.add_markdown("The first start on a machine compiles the planners (one to two minutes on "
                         "two cores, `ucat-console bench compile` measures it); later starts take "
                         "seconds. This page turns into the console when it is ready; arming is "
                         "possible from then on.")
        self._t0 = time.monotonic()
        self._progress = Progress(0, 1, "the planners")
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self.server.on_client_connect(self._on_connect)
        self._thread = threading.Thread(target=self._run, name="loading-page", daemon=True)
        self._thread.start()

    @property
    def port(self) -> int:
        return self.server.get_port()

    def _on_connect(self, client: Any) -> None:
        self.guard.send_first(client.client_id, [run_javascript(page_script.INSTALL)])

    def set_progress(self, p: Progress) -> None:
        with self._lock:
            self._progress = p
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
                "link_policy": "The console is starting; this page reconnects by itself.",
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

    def stop(self) -> None:
        """Stop serving; returns when the port is free for the console (which refuses any other)."""
        port = self.port
        self._stop.set()
        self._thread.join(timeout=2.0)
        self.guard.stop()
        self.server.stop()
        _wait_port_free(self.host, port)


def _wait_port_free(host: str, port: int, timeout: float = 10.0) -> None:
    """Until ``port`` on ``host`` can be bound again (as the page's server binds it: address
    reuse on), or ``timeout`` s (then the console reports the port taken)."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    deadline = time.monotonic() + timeout
    while True:
        with socket.socket(family, socket.SOCK_STREAM) as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                s.bind((host, port))
                return
            except OSError:
                if time.monotonic() > deadline:
                    return
        time.sleep(0.05)
