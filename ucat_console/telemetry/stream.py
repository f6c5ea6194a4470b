"""The telemetry stream: publish typed messages on named channels, subscribe to them.

Publishing calls each subscriber in the publisher's thread, in subscription order, so
subscribers must return quickly (the UI copies into ring buffers, the recorder enqueues
for its writer thread). A subscriber that raises is logged and kept; it never breaks
the publisher. The same stream object is fed by the supervisor (live) or by the session
player (from a file): subscribers cannot tell which.
"""

from __future__ import annotations

import logging
import threading
from typing import Any, Callable, Iterable

from ucat_console.telemetry.channels import CHANNELS, message_type

log = logging.getLogger(__name__)

Subscriber = Callable[[str, Any], None]


class TelemetryStream:
    def __init__(self, validate: bool = True) -> None:
        self._lock = threading.Lock()
        self._subs: tuple[tuple[Subscriber, frozenset[str] | None], ...] = ()
        self._validate = validate
        self._wanted: frozenset[str] = frozenset()
        # each channel's subscribers in subscription order (a new dict after each change); a
        # channel that is not one of CHANNELS (published unvalidated) goes to those of all
        self._by_channel: dict[str, tuple[Subscriber, ...]] = {}
        self._of_all: tuple[Subscriber, ...] = ()

    def wants(self, channel: str) -> bool:
        """Whether a subscriber takes ``channel`` now: a publisher may leave a message that
        nobody takes unbuilt (the headless runs of the experiments subscribe to few)."""
        return channel in self._wanted

    @property
    def wanted(self) -> frozenset[str]:
        """The channels a subscriber takes now (a new set object after each change)."""
        return self._wanted

    def _update_wanted(self) -> None:
        every = frozenset(CHANNELS)
        subs = self._subs
        self._wanted = frozenset().union(*(every if c is None else c for _, c in subs))
        self._by_channel = {name: tuple(cb for cb, c in subs if c is None or name in c) for name in CHANNELS}
        self._of_all = tuple(cb for cb, c in subs if c is None)

    def subscribe(self, callback: Subscriber, channels: Iterable[str] | None = None) -> Callable[[], None]:
        """Call ``callback(channel, message)`` for each message (of ``channels`` only,
        when given). Returns a function that unsubscribes."""
        chans = None
        if channels is not None:
            chans = frozenset(channels)
            for c in chans:
                message_type(c)
        entry = (callback, chans)
        with self._lock:
            self._subs = self._subs + (entry,)
            self._update_wanted()

        def unsubscribe() -> None:
            with self._lock:
                self._subs = tuple(s for s in self._subs if s is not entry)
                self._update_wanted()

        return unsubscribe

    def publish(self, channel: str, message: Any) -> None:
        if self._validate:
            expected = CHANNELS.get(channel) or message_type(channel)
            if type(message) is not expected:
                raise TypeError(
                    f"channel {channel!r} carries {expected.__name__}, got {type(message).__name__}"
                )
        # a snapshot: the dict is replaced, never changed
        for callback in self._by_channel.get(channel, self._of_all):
            try:
                callback(channel, message)
            except Exception:  # a broken subscriber must not stop the publisher
                log.exception("telemetry subscriber %r failed on %s", callback, channel)
