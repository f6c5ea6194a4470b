"""A headless Chromium of our own (its process group known), driven by Playwright over CDP.

Playwright's own ``launch`` hides the browser's process; to freeze a page the way a hung
browser or a laptop lid does (SIGSTOP on every process of the browser), the browser is
started here in a process group of its own and Playwright connects to its DevTools port.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import tempfile
import threading
import time
from pathlib import Path

from ucat_console.bench.ui import CHROMIUM, CHROMIUM_ARGS, UNTHROTTLED

_DEVTOOLS = re.compile(r"DevTools listening on (ws://\S+)")


class Chromium:
    """``with Chromium() as c:`` a headless browser; ``c.ws_url`` for ``connect_over_cdp``."""

    def __init__(self, executable: str = CHROMIUM, timeout: float = 60.0) -> None:
        exe = executable if Path(executable).exists() else shutil.which("chromium")
        if exe is None:
            raise FileNotFoundError(f"no Chromium at {executable}")
        self.profile = tempfile.mkdtemp(prefix="ucat-chromium-")
        self.proc = subprocess.Popen(
            [exe, "--headless", *CHROMIUM_ARGS, *UNTHROTTLED, "--remote-debugging-port=0",
             "--remote-debugging-address=127.0.0.1", f"--user-data-dir={self.profile}", "about:blank"],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, start_new_session=True,
        )
        found: list[str] = []
        ready = threading.Event()

        def read() -> None:
            assert self.proc.stderr is not None
            for line in self.proc.stderr:
                m = _DEVTOOLS.search(line)
                if m and not found:
                    found.append(m.group(1))
                    ready.set()
            ready.set()

        threading.Thread(target=read, daemon=True).start()
        if not ready.wait(timeout) or not found:
            self.close()
            raise RuntimeError("Chromium did not open its DevTools port")
        self.ws_url = found[0]
        self.stopped = False

    def freeze(self) -> None:
        """SIGSTOP every process of the browser."""
        os.killpg(self.proc.pid, signal.SIGSTOP)
        self.stopped = True

    def thaw(self) -> None:
        os.killpg(self.proc.pid, signal.SIGCONT)
        self.stopped = False

    def close(self) -> None:
        try:
            os.killpg(self.proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        try:
            self.proc.wait(timeout=10.0)
        except subprocess.TimeoutExpired:
            pass
        deadline = time.monotonic() + 5.0
        while time.monotonic() < deadline:
            try:
                shutil.rmtree(self.profile)
                break
            except OSError:
                time.sleep(0.1)

    def __enter__(self) -> Chromium:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
