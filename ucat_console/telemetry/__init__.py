"""The telemetry stream: typed, timestamped messages on named channels."""

from ucat_console.telemetry.events import Event, EventSink

__all__ = ["Event", "EventSink"]
