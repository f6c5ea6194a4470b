"""The control loop's own watchdog: a thread of its own that acts when the loop stops stepping.

The loop's thread beats (:meth:`LoopWatchdog.beat`) each time it comes back to the
supervisor: at every wait of the paced loop and at the end of every chunk, many times a
second. The watchdog's thread looks every ``period`` s; when the last beat is more than
``timeout`` s old (the loop is stuck: a blocked call, a hung driver, an endless compiled
step), it calls ``on_stuck(silent_for)`` once, from its own thread, since the loop's thread
cannot act. The next beat calls ``on_resumed()`` (from the loop's thread). A look that
comes more than half the timeout after the one before is only a fresh start: the watchdog's
thread was held back too (a busy computer holds the whole process, not the loop alone), and
the loop gets the chance to run that the watchdog just had; it acts at the next look, 20 ms
on, if the loop has still not stepped.

:meth:`check` is the decision alone, on the clock it is given (tests drive it with a fake
one); the thread calls it with ``time.monotonic``.

A loop stuck in compiled code that holds Python's interpreter lock stops this thread too:
the watchdog then acts only when the lock is released. The loop's own compiled steps are
short (the core returns to Python at every event).
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Callable

log = logging.getLogger(__name__)


class LoopWatchdog:
    """See the module docstring."""

    def __init__(self, timeout: float, on_stuck: Callable[[float], None], on_resumed: Callable[[], None],
                 period: float | None = None, clock: Callable[[], float] = time.monotonic) -> None:
        if not timeout > 0:
            raise ValueError(f"timeout: expected a positive time in s, got {timeout!r}")
        self.timeout = float(timeout)
        self.period = float(period) if period is not None else min(0.02, self.timeout / 10)
        self._clock = clock
        self._on_stuck = on_stuck
        self._on_resumed = on_resumed
        self._last = clock()
        self._looked = self._last  # the watchdog's last look
        self._lock = threading.Lock()
        self._tripped = False
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def tripped(self) -> bool:
        return self._tripped

    def beat(self) -> None:
        """The loop is stepping (its thread; cheap: called many times a second)."""
        self._last = self._clock()
        if self._tripped:
            with self._lock:
                was, self._tripped = self._tripped, False
            if was:
                self._on_resumed()

    def check(self, now: float) -> float | None:
        """At ``now``: how long the loop has been silent when that has just passed the
        timeout (``on_stuck`` was called), else None."""
        with self._lock:
            held_back, self._looked = now - self._looked > self.timeout / 2, now
            silent = now - self._last
            if self._tripped or silent <= self.timeout or held_back:
                return None
            self._tripped = True
        try:
            self._on_stuck(silent)
        except Exception:
            log.exception("the loop watchdog's action failed")
        return silent

    def start(self) -> None:
        if self._thread is not None:
            raise RuntimeError("the loop watchdog is already running")
        self._last = self._looked = self._clock()
        self._thread = threading.Thread(target=self._run, name="loop-watchdog", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        t, self._thread = self._thread, None
        if t is not None and t is not threading.current_thread():
            t.join(timeout=5.0)

    def _run(self) -> None:
        while not self._stop.wait(self.period):
            self.check(self._clock())
