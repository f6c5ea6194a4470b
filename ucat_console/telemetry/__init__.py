"""The telemetry stream: typed, timestamped messages on named channels.

``Event``, ``EventSink`` and ``TelemetryStream`` are imported on first use, so that the
device readings can import :mod:`ucat_console.telemetry.fields` (their field descriptions)
while :mod:`ucat_console.telemetry.channels` imports the readings.
"""

from __future__ import annotations

from typing import Any

__all__ = ["Event", "EventSink", "TelemetryStream"]


def __getattr__(name: str) -> Any:
    if name in ("Event", "EventSink"):
        from ucat_console.telemetry import events

        return getattr(events, name)
    if name == "TelemetryStream":
        from ucat_console.telemetry.stream import TelemetryStream

        return TelemetryStream
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
