"""The telemetry stream: typed, timestamped messages on named channels."""

from ucat_console.telemetry.events import Event, EventSink
from ucat_console.telemetry.stream import TelemetryStream

__all__ = ["Event", "EventSink", "TelemetryStream"]
