"""The telemetry stream: publish typed messages on named channels, subscribe to them.

Publishing calls each subscriber in the publisher's thread, in subscription order, so
subscribers must return quickly (the UI copies into ring buffers, the recorder enqueues
for its writer thread). A subscriber that raises is logged and kept; it never breaks
the publisher. The same stream object is fed by the supervisor (live) or by the session
player (from a file): subscribers cannot tell which.

A publisher with several messages at once (the closed loop, after each step of its
compiled core: the readings, the body state, the fin states, the power) hands them over
with :meth:`TelemetryStream.publish_many`: each subscriber, in subscription order, gets
the ones of its channels in their order. One that subscribed with
:meth:`TelemetryStream.subscribe_batches` gets them as one list, in one call: the
recorder, the live view and the failsafes take some 450 messages a second from the loop
in some 50 calls instead.
"""

from __future__ import annotations

import logging
import threading
from typing import Any, Callable, Iterable, Sequence

from ucat_console.telemetry.channels import CHANNELS, message_type

log = logging.getLogger(__name__)

Subscriber = Callable[[str, Any], None]
#: takes a list of (channel, message), in publishing order
BatchSubscriber = Callable[[Sequence[tuple[str, Any]]], None]


class TelemetryStream:
    def __init__(self, validate: bool = True) -> None:
        self._lock = threading.Lock()
        # (callback, its channels or None for all, whether it takes lists)
        self._subs: tuple[tuple[Callable[..., None], frozenset[str] | None, bool], ...] = ()
        self._validate = validate
        self._wanted: frozenset[str] = frozenset()
        # each channel's subscribers in subscription order (a new dict after each change); a
        # channel that is not one of CHANNELS (published unvalidated) goes to those of all
        self._by_channel: dict[str, tuple[tuple[Callable[..., None], bool], ...]] = {}
        self._of_all: tuple[tuple[Callable[..., None], bool], ...] = ()

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
        self._wanted = frozenset().union(*(every if c is None else c for _, c, _ in subs))
        self._by_channel = {name: tuple((cb, b) for cb, c, b in subs if c is None or name in c) for name in CHANNELS}
        self._of_all = tuple((cb, b) for cb, c, b in subs if c is None)

    def subscribe(self, callback: Subscriber, channels: Iterable[str] | None = None) -> Callable[[], None]:
        """Call ``callback(channel, message)`` for each message (of ``channels`` only,
        when given). Returns a function that unsubscribes."""
        return self._add(callback, channels, False)

    def subscribe_batches(self, callback: BatchSubscriber, channels: Iterable[str] | None = None) -> Callable[[], None]:
        """Call ``callback(items)`` with the (channel, message) items of ``channels`` (all,
        when not given) of each publication: all of a :meth:`publish_many` at once (only when
        there are some), a one-item list for a :meth:`publish`. Returns a function that
        unsubscribes."""
        return self._add(callback, channels, True)

    def _add(self, callback: Callable[..., None], channels: Iterable[str] | None, batch: bool) -> Callable[[], None]:
        chans = None
        if channels is not None:
            chans = frozenset(channels)
            for c in chans:
                message_type(c)
        entry = (callback, chans, batch)
        with self._lock:
            self._subs = self._subs + (entry,)
            self._update_wanted()

        def unsubscribe() -> None:
            with self._lock:
                self._subs = tuple(s for s in self._subs if s is not entry)
                self._update_wanted()

        return unsubscribe

    def _check(self, channel: str, message: Any) -> None:
        expected = CHANNELS.get(channel) or message_type(channel)
        if type(message) is not expected:
            raise TypeError(f"channel {channel!r} carries {expected.__name__}, got {type(message).__name__}")

    def publish(self, channel: str, message: Any) -> None:
        if self._validate:
            self._check(channel, message)
        # a snapshot: the dict is replaced, never changed
        for callback, batch in self._by_channel.get(channel, self._of_all):
            try:
                if batch:
                    callback([(channel, message)])
                else:
                    callback(channel, message)
            except Exception:  # a broken subscriber must not stop the publisher
                log.exception("telemetry subscriber %r failed on %s", callback, channel)

    def publish_many(self, items: Sequence[tuple[str, Any]]) -> None:
        """Publish ``(channel, message)`` items in order (module docstring). Every item is
        checked first: one that does not fit its channel publishes none of them."""
        if self._validate:
            expected = CHANNELS.get
            for channel, message in items:
                if type(message) is not expected(channel):
                    self._check(channel, message)  # raises, naming what is wrong
        for callback, chans, batch in self._subs:  # a snapshot: the tuple is replaced, never changed
            mine = items if chans is None else [item for item in items if item[0] in chans]
            if not mine:
                continue
            if batch:
                try:
                    callback(mine)
                except Exception:
                    log.exception("telemetry subscriber %r failed on %d messages", callback, len(mine))
                continue
            for channel, message in mine:
                try:
                    callback(channel, message)
                except Exception:
                    log.exception("telemetry subscriber %r failed on %s", callback, channel)
