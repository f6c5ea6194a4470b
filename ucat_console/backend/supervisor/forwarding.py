"""The closed loop's stream: what the loop publishes reaches the public stream through
:class:`LoopOutlet`, as the loop made it, except that a burst of plan overruns or stalls is
folded into one event (:class:`~.bursts.BurstFolder`). The loop builds only what the
public stream's subscribers take (``wants``, ``wanted``).
"""

from __future__ import annotations

from typing import Any

from ucat_console.backend.supervisor.bursts import BurstFolder
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.stream import TelemetryStream


class LoopOutlet:
    """The stream the closed loop publishes on (``publish``, ``publish_many``, ``wants``,
    ``wanted``): onto ``public``, as the module docstring says."""

    def __init__(self, public: TelemetryStream, bursts: BurstFolder) -> None:
        self._public = public
        self._bursts = bursts

    def wants(self, channel: str) -> bool:
        return self._public.wants(channel)

    @property
    def wanted(self) -> frozenset[str]:
        return self._public.wanted

    def publish(self, channel: str, msg: Any) -> None:
        if not self._folded(channel, msg):
            self._public.publish(channel, msg)

    def publish_many(self, items: Any) -> None:
        for _, msg in items:
            if type(msg) is Event:
                break
        else:  # no event (the core's rows): every message as the loop made it
            self._public.publish_many(items)
            return
        self._public.publish_many([(c, m) for c, m in items if not self._folded(c, m)])

    def _folded(self, channel: str, msg: Any) -> bool:
        return type(msg) is Event and channel == ch.EVENTS and self._bursts.take(msg)
