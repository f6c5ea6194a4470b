"""What the sensors deliver: one frozen dataclass per kind of reading.

The drivers (``backend/devices``) and the simulated sensors (``backend/sim``) produce these
types, so the estimator and the body-frame layer never know whether a reading came through
a real device, an emulator or the headless simulator. Units are SI unless the field name says otherwise; ``t`` is the
receiving clock's time in seconds.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class ImuReading:
    """MIP sensor data set 0x80: accel in g, gyro in rad/s, orientation when streamed."""

    t: float
    accel_g: tuple[float, float, float]
    gyro: tuple[float, float, float]
    quaternion: tuple[float, float, float, float] | None = None  # (w, x, y, z)
    euler: tuple[float, float, float] | None = None  # roll, pitch, yaw (rad)


@dataclass(frozen=True)
class DvlVelocity:
    """DVL A50 ``velocity`` report in the DVL's frame; ``valid`` False means missing data."""

    t: float
    vx: float
    vy: float
    vz: float
    valid: bool
    altitude: float
    fom: float


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

    t: float
    depth_m: float
    pressure_pa: float


@dataclass(frozen=True)
class FinFeedback:
    """EPOS2 encoder feedback at the fin (after gear ratio): angle and rate."""

    t: float
    fin: int
    position_rad: float
    velocity_rad_s: float
    state: str = "operation_enabled"


#: any reading a robot delivers
Reading = ImuReading | DvlVelocity | DepthReading | FinFeedback
