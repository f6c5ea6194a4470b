"""The one way into the closed loop from other threads: :class:`CommandChannel`.

It holds what the loop is commanded to do (:class:`~.commands.Commanded`, what the
supervisor and the page read back) and the queue of commands for the loop's thread.
:meth:`CommandChannel.submit` resolves a command against what is commanded (a refused one
raises and changes nothing), records it as commanded, queues it, and returns a
:class:`concurrent.futures.Future`; the loop's thread applies the queue, in submission
order, at its next event (:meth:`CommandChannel.drain`, its one drain point) through the
loop's :class:`~.commands.CommandTarget`. The Future answers what the command returns (an
exception it raises goes through the Future too); a command whose Future was cancelled
before the drain (its caller gave up waiting) never runs.
"""

from __future__ import annotations

import logging
import queue
import threading
from concurrent.futures import Future

from ucat_console.backend.loop.commands import CommandRefused, Commanded, CommandTarget, LoopCommand
from ucat_console.backend.loop.config import LoopConfig
from ucat_console.control.allocation import BodySetpoints

log = logging.getLogger(__name__)


class CommandChannel:
    """The loop's commanded state and its queue of commands (module docstring)."""

    def __init__(self, cfg: LoopConfig, setpoints: BodySetpoints, target: CommandTarget) -> None:
        self._cfg = cfg
        self._target = target
        self._lock = threading.Lock()
        self._commanded = Commanded.of(cfg, setpoints)
        self._queue: queue.SimpleQueue[tuple[Future, LoopCommand]] = queue.SimpleQueue()

    @property
    def commanded(self) -> Commanded:
        return self._commanded

    def submit(self, command: LoopCommand) -> Future:
        """Queue ``command`` for the loop's thread (any thread); CommandRefused, with nothing
        changed, when it does not fit what is commanded or the configuration."""
        if not isinstance(command, LoopCommand):
            raise CommandRefused(f"command: expected a loop command, got {type(command).__name__}")
        fut: Future = Future()
        with self._lock:
            resolved = command.resolve(self._commanded, self._cfg)
            self._commanded = resolved.commanded(self._commanded)
            self._queue.put((fut, resolved))
        return fut

    @property
    def waiting(self) -> bool:
        return not self._queue.empty()

    def drain(self, t: float) -> None:
        """Apply every queued command, in order, at loop time ``t`` (the loop's thread);
        one submitted while this runs is applied here too."""
        while True:
            try:
                fut, command = self._queue.get_nowait()
            except queue.Empty:
                return
            if not fut.set_running_or_notify_cancel():
                continue  # its caller gave up: never run it
            try:
                fut.set_result(command.apply(self._target, t))
            except Exception as e:
                if not isinstance(e, CommandRefused):
                    log.exception("the loop's command %r failed", command)
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
