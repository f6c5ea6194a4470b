"""The channel names of the telemetry stream and the message type each carries.

This is the one definition: the supervisor publishes under these names, the recorder
writes them as MCAP channels, the UI and the metrics subscribe to them. An auxiliary
sensor's channel (``sensors/<name>``, its reading's dataclass) is added to :data:`CHANNELS`
when the sensor is registered (``backend.sensors``, through :func:`add_channel`) and taken
out when it is unregistered: the stream, the recorder and the session reader read
:data:`CHANNELS` when they need it.
"""

from __future__ import annotations

import dataclasses

from ucat_console.robot.fins import N_FINS  # ch.N_FINS: how many fin channels
from ucat_console.robot.readings import DepthReading, DvlVelocity, ImuReading
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.messages import (
    BodyAllocation,
    BodyCommand,
    BodyState,
    BodyTracking,
    CameraImage,
    ElectricalPower,
    FinCycle,
    FinPlan,
    FinState,
    FinStrouhal,
    Power,
    Setpoints,
    Status,
)


BODY_STATE = "body/state"
SETPOINTS = "body/setpoints"
BODY_COMMAND = "body/command"
BODY_ALLOCATION = "body/allocation"
BODY_TRACKING = "body/tracking"
POWER = "power"
POWER_ELECTRICAL = "power/electrical"
STATUS = "status"
EVENTS = "events"
IMU = "sensors/imu"
DVL = "sensors/dvl"
DEPTH = "sensors/depth"
CAMERA_IMAGE = "camera/image"


def fin_state(fin: int) -> str:
    return f"fin/{fin}/state"


def fin_plan(fin: int) -> str:
    return f"fin/{fin}/plan"


def fin_strouhal(fin: int) -> str:
    return f"fin/{fin}/strouhal"


def fin_cycle(fin: int) -> str:
    return f"fin/{fin}/cycle"


#: every channel and its message type
CHANNELS: dict[str, type] = {
    BODY_STATE: BodyState,
    SETPOINTS: Setpoints,
    BODY_COMMAND: BodyCommand,
    BODY_ALLOCATION: BodyAllocation,
    BODY_TRACKING: BodyTracking,
    POWER: Power,
    POWER_ELECTRICAL: ElectricalPower,
    STATUS: Status,
    EVENTS: Event,
    IMU: ImuReading,
    DVL: DvlVelocity,
    DEPTH: DepthReading,
    CAMERA_IMAGE: CameraImage,
    **{fin_state(i): FinState for i in range(N_FINS)},
    **{fin_plan(i): FinPlan for i in range(N_FINS)},
    **{fin_strouhal(i): FinStrouhal for i in range(N_FINS)},
    **{fin_cycle(i): FinCycle for i in range(N_FINS)},
}


#: the channels of the fixed set above (:func:`add_channel` adds others, never one of these)
FIXED = frozenset(CHANNELS)


def add_channel(channel: str, cls: type) -> None:
    """Add ``channel`` carrying ``cls`` messages (a frozen dataclass with a time ``t`` and
    :class:`~ucat_console.robot.fields.Doc` fields); ValueError if the name is taken."""
    if not isinstance(channel, str) or not channel:
        raise ValueError(f"channel: expected a non-empty name, got {channel!r}")
    if channel in CHANNELS:
        raise ValueError(f"channel {channel!r} is already one of the telemetry channels")
    if not dataclasses.is_dataclass(cls) or not isinstance(cls, type) or "t" not in {f.name for f in dataclasses.fields(cls)}:
        raise ValueError(f"channel {channel!r}: expected a dataclass with a time field t, got {cls!r}")
    CHANNELS[channel] = cls


def remove_channel(channel: str) -> None:
    """Take out a channel :func:`add_channel` added (ValueError for one of the fixed set)."""
    if channel in FIXED:
        raise ValueError(f"channel {channel!r} is one of the fixed telemetry channels")
    CHANNELS.pop(channel, None)


def message_type(channel: str) -> type:
    try:
        return CHANNELS[channel]
    except KeyError:
        raise ValueError(f"unknown telemetry channel {channel!r}") from None
