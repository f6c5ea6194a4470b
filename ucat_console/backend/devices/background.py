"""The background thread of a device driver or emulator: spawned once, stopped and joined.

:class:`BackgroundThread` holds the stop flag and the thread; ``stop`` (also on leaving a
``with`` block) sets the flag, joins the thread and then calls ``_close`` to release the
port, socket or pty. A subclass writes ``start`` (which calls ``_spawn``), ``_run`` and
``_close``.
"""

from __future__ import annotations

import threading
from typing import Self


class BackgroundThread:
    """Stop flag, thread and ``stop``/context-manager protocol of one device object."""

    def __init__(self) -> None:
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> object:
        raise NotImplementedError

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        self._close()

    def __enter__(self) -> Self:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _spawn(self, name: str) -> None:
        """Clear the stop flag and run ``_run`` in a daemon thread called ``name``."""
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        raise NotImplementedError

    def _close(self) -> None:
        """Release the transport (after the thread ended)."""
