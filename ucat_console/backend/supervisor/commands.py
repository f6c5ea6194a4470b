"""Commands: refusals, value checks, and the queue of work for the loop's thread.

Commands come from any thread (UI callbacks, the CLI). Those that must act between two
chunks of the closed loop (arming, drive resets) go through :class:`LoopCommands`, on
:class:`concurrent.futures.Future`: the caller waits for the loop's thread to run the work;
when the loop does not take it in time the future is cancelled, so the work either ran and
was answered, or never runs ("nothing was done").
"""

from __future__ import annotations

import math
import queue
import threading
from concurrent.futures import Future
from typing import Any, Callable

#: seconds a command waits for the loop's thread
WAIT_LOOP = 5.0


class CommandRefused(ValueError):
    """A command refused because of its value or the present state (the message says why)."""


def number(key: str, value: Any, integer: bool) -> float | int:
    """``value`` as a finite number of the right kind, or CommandRefused naming ``key``."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        kind = "an integer" if integer else "a number"
        raise CommandRefused(f"{key}: expected {kind}, got {value!r}")
    if not math.isfinite(value):
        raise CommandRefused(f"{key}: {value!r} is not a finite number")
    if integer:
        if float(value) != int(value):
            raise CommandRefused(f"{key}: expected an integer, got {value!r}")
        return int(value)
    return float(value)


class LoopCommands:
    """Work handed to the loop's thread and run there between chunks (:meth:`run_pending`)."""

    def __init__(self, wait: float = WAIT_LOOP) -> None:
        self.wait = wait
        self._queue: queue.SimpleQueue[tuple[Future, Callable[[], Any]]] = queue.SimpleQueue()
        self.thread: threading.Thread | None = None  # the loop's thread, once it runs
        self.why_not_running: Callable[[], str] = lambda: ""

    def run(self, fn: Callable[[], Any]) -> Any:
        """``fn()`` in the loop's thread (at once when no loop thread runs, or from it)."""
        t = self.thread
        if t is None or threading.current_thread() is t:
            return fn()
        if not t.is_alive():
            why = self.why_not_running()
            raise CommandRefused(f"the loop is not running{': ' + why if why else ''}")
        fut: Future = Future()
        self._queue.put((fut, fn))
        try:
            return fut.result(timeout=self.wait)
        except TimeoutError:
            if fut.cancel():  # not started: it never will be
                raise CommandRefused("the loop did not answer in time; nothing was done") from None
            return fut.result()  # started: wait for its answer

    def post(self, fn: Callable[[], Any]) -> None:
        """``fn()`` in the loop's thread at its next chunk; the caller does not wait for it."""
        self._queue.put((Future(), fn))

    def run_pending(self) -> None:
        """Run every queued command (in the loop's thread)."""
        while True:
            try:
                fut, fn = self._queue.get_nowait()
            except queue.Empty:
                return
            if not fut.set_running_or_notify_cancel():
                continue  # its caller gave up: never run it
            try:
                fut.set_result(fn())
            except BaseException as e:
                fut.set_exception(e)

    def fail_all(self, why: str) -> None:
        """Refuse every queued command (the loop has stopped)."""
        while True:
            try:
                fut, _ = self._queue.get_nowait()
            except queue.Empty:
                return
            if fut.set_running_or_notify_cancel():
                fut.set_exception(CommandRefused(why))
