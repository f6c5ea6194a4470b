"""Typed events: faults, failsafes, mode switches, tuning changes, markers.

Every source (drivers, emulators, the supervisor, the operator) reports through this one
message type, so the UI, the recorder and the failsafes read faults the same way.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated, Any, Callable

from ucat_console.robot.fields import Doc

#: severities, lowest first
LEVELS = ("debug", "info", "warning", "error", "fatal")


@dataclass(frozen=True)
class Event:
    """One timestamped event.

    ``t`` is seconds on the clock of whoever raised it (the supervisor's clock on the
    stream); ``source`` names the device or component (``"epos2.1"``, ``"imu"``, ``"dvl"``,
    ``"pressure"``, ``"failsafe"``, ``"operator"``); ``code`` is machine-readable
    (``"heartbeat_lost"``, ``"emcy"``, ``"checksum"``, ``"silence"``, ``"invalid_data"``,
    ``"reconnected"``, ``"mode"``, ``"tuning"``, ``"marker"`` ...); ``message`` is for people;
    ``data`` holds the details (JSON-compatible values only).
    """

    t: Annotated[float, Doc("time on the clock of whoever raised it", "s")]
    source: Annotated[str, Doc("the device or component")]
    code: Annotated[str, Doc("machine-readable code")]
    message: Annotated[str, Doc("for people")]
    level: Annotated[str, Doc("debug, info, warning, error or fatal")] = "warning"
    data: Annotated[dict[str, Any], Doc("details (JSON values)")] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.level not in LEVELS:
            raise ValueError(f"level: {self.level!r} is not one of {', '.join(LEVELS)}")


EventSink = Callable[[Event], None]


def ignore_events(event: Event) -> None:
    """An event sink that drops events (for one-off tools that print nothing)."""
