"""The closed loop's stream: what the loop publishes reaches the public stream through
:class:`LoopOutlet`, which shows what the robot really does while it is disarmed.

While disarmed, a fin state's commanded angle and rate are the ones the arming gate last
sent (none: the fins are held), and the loop's stroke timeouts are held back (no stroke
was sent). A burst of plan overruns or stalls is folded into one event
(:class:`~.bursts.BurstFolder`). The loop builds only what the public stream's subscribers
take (``wants``, ``wanted``).
"""

from __future__ import annotations

from typing import Any, Callable

from ucat_console.backend.supervisor.bursts import BurstFolder
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.messages import FinState
from ucat_console.telemetry.stream import TelemetryStream


class LoopOutlet:
    """The stream the closed loop publishes on (``publish``, ``publish_many``, ``wants``,
    ``wanted``): onto ``public``, as the module docstring says. ``armed()``: whether the
    motors are armed; ``sent(fin)``: the (angle, rate) the arming gate last sent to ``fin``."""

    def __init__(self, public: TelemetryStream, bursts: BurstFolder, armed: Callable[[], bool],
                 sent: Callable[[int], tuple[float, float]]) -> None:
        self._public = public
        self._bursts = bursts
        self._armed = armed
        self._sent = sent

    def wants(self, channel: str) -> bool:
        return self._public.wants(channel)

    @property
    def wanted(self) -> frozenset[str]:
        return self._public.wanted

    def publish(self, channel: str, msg: Any) -> None:
        msg = self._forwarded(channel, msg, self._armed())
        if msg is not None:
            self._public.publish(channel, msg)

    def publish_many(self, items: Any) -> None:
        armed = self._armed()
        if armed:
            for _, msg in items:
                if type(msg) is Event:
                    break
            else:  # armed and no event: every message as the loop made it
                self._public.publish_many(items)
                return
        out = []
        for channel, msg in items:
            msg = self._forwarded(channel, msg, armed)
            if msg is not None:
                out.append((channel, msg))
        self._public.publish_many(out)

    def _forwarded(self, channel: str, msg: Any, armed: bool) -> Any:
        """The loop's message as the public stream carries it; None when it is held back."""
        tp = type(msg)
        if not armed:
            if tp is FinState:
                a, r = self._sent(msg.fin)
                return FinState(msg.t, msg.fin, msg.angle, msg.rate, a, r)
            if tp is Event and msg.code == "stroke_timeout" and msg.source == "loop":
                return None
        if tp is Event and channel == ch.EVENTS and self._bursts.take(msg):
            return None
        return msg
