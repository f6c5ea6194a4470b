"""The channel names of the telemetry stream and the message type each carries.

This is the one definition: the supervisor publishes under these names, the recorder
writes them as MCAP channels, the UI and the metrics subscribe to them.
"""

from __future__ import annotations

from ucat_console.robot.fins import N_FINS  # ch.N_FINS: how many fin channels
from ucat_console.robot.readings import DepthReading, DvlVelocity, ImuReading
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.messages import (
    BodyAllocation,
    BodyCommand,
    BodyState,
    BodyTracking,
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
    **{fin_state(i): FinState for i in range(N_FINS)},
    **{fin_plan(i): FinPlan for i in range(N_FINS)},
    **{fin_strouhal(i): FinStrouhal for i in range(N_FINS)},
    **{fin_cycle(i): FinCycle for i in range(N_FINS)},
}


def message_type(channel: str) -> type:
    try:
        return CHANNELS[channel]
    except KeyError:
        raise ValueError(f"unknown telemetry channel {channel!r}") from None
