"""What the sensors deliver: one frozen dataclass per kind of reading.

The drivers (``backend/devices``) and the simulated sensors (``backend/sim``) produce these
types, so the estimator and the body-frame layer never know whether a reading came through
a real device, an emulator or the headless simulator. Units are SI unless the field name
says otherwise; ``t`` is the receiving clock's time in seconds. Each field's meaning, unit
and frame is its :class:`~ucat_console.robot.fields.Doc`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

import numpy as np

from ucat_console.robot.fields import RPY, WXYZ, XYZ, Doc

Time = Annotated[float, Doc("time on the receiving clock", unit="s")]


@dataclass(frozen=True)
class ImuReading:
    """MIP sensor data set 0x80: the specific force (acceleration less gravity) in m/s^2
    (the sensor reports it in standard gravities; its driver converts), gyro in rad/s,
    orientation when streamed."""

    t: Time
    accel: Annotated[tuple[float, float, float], Doc("specific force (acceleration less gravity)", "m/s^2", "IMU", XYZ)]
    gyro: Annotated[tuple[float, float, float], Doc("angular rate", "rad/s", "IMU", XYZ)]
    quaternion: Annotated[tuple[float, float, float, float] | None,
                          Doc("orientation when streamed (held w first)", "1", "IMU to NED",
                              WXYZ)] = None
    euler: Annotated[tuple[float, float, float] | None,
                     Doc("orientation when streamed", "rad", "IMU to NED", RPY)] = None


@dataclass(frozen=True)
class DvlVelocity:
    """DVL A50 ``velocity`` report in the DVL's frame; ``valid`` False means missing data."""

    t: Time
    vx: Annotated[float, Doc("velocity along the DVL's x", "m/s", "DVL")]
    vy: Annotated[float, Doc("velocity along the DVL's y", "m/s", "DVL")]
    vz: Annotated[float, Doc("velocity along the DVL's z", "m/s", "DVL")]
    valid: Annotated[bool, Doc("the DVL has bottom lock (False: the velocity is missing)")]
    altitude: Annotated[float, Doc("distance to the bottom", "m")]
    fom: Annotated[float, Doc("figure of merit (velocity uncertainty)", "m/s")]


@dataclass(frozen=True)
class DvlPosition:
    """DVL A50 ``position_local`` (dead reckoning)."""

    t: float
    x: float
    y: float
    z: float
    roll: float
    pitch: float
    yaw: float
    std: float


@dataclass(frozen=True)
class DepthReading:
    """Pressure transducer reading converted to depth below the zeroed surface."""

    t: Time
    depth_m: Annotated[float, Doc("depth below the zeroed surface", "m")]
    pressure_pa: Annotated[float, Doc("gauge pressure (the transducer reads above the atmosphere)", "Pa")]


@dataclass(frozen=True)
class FinFeedback:
    """EPOS2 encoder feedback at the fin (after gear ratio): angle and rate."""

    t: float
    fin: int
    position_rad: float
    velocity_rad_s: float
    state: str = "operation_enabled"


@dataclass(frozen=True)
class DriveElectrical:
    """One fin drive's electrical input as its EPOS2 measures it: the motor current averaged
    by the drive (0x2027) and the supply voltage at its power stage (0x2200 sub 1)."""

    t: Time
    fin: int
    current_a: Annotated[float, Doc("motor current averaged by the drive", "A")]
    voltage_v: Annotated[float, Doc("supply voltage at the power stage", "V")]


@dataclass(frozen=True, eq=False)
class FinFeedbacks:
    """Encoder feedback of every fin sampled at the same time ``t`` (the simulated robot's
    drives report together): angles and rates at the fin, in the robot's fin order. The
    arrays are read-only; the loop takes them as they are, with no per-fin object."""

    t: float
    position_rad: np.ndarray
    velocity_rad_s: np.ndarray


#: any reading a robot delivers
Reading = ImuReading | DvlVelocity | DepthReading | FinFeedback | FinFeedbacks
