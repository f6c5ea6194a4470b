"""The readings as rows of numbers: what compiled code passes between the robot and the loop.

A reading (``robot.readings``) is one row of a float array, ``ROW`` wide: its kind, its
time, then its values (NaN where a value is missing). The simulated robot writes rows in
compiled code and the closed loop's compiled core reads them, so that a simulated sample
reaches the controller with no Python object in between; a robot that delivers reading
objects (the drivers) has them turned into rows by :func:`to_row`, and a row becomes the
reading it stands for with :func:`from_row` (for the telemetry, and for robots that hand
readings to the loop as objects).

Columns by kind (after ``KIND`` and ``T``)::

    IMU    accel_g (3), gyro (3), quaternion (4, NaN: not streamed), euler (3, NaN: none)
    DEPTH  depth_m, pressure_pa
    DVL    vx, vy, vz, valid (1.0 / 0.0), altitude, fom
    FINS   every fin's angle (N_FINS), then every fin's rate (N_FINS), robot order
    FIN    fin, angle, rate (one fin's drive)
"""

from __future__ import annotations

import math

import numpy as np

from ucat_console.robot.fins import N_FINS
from ucat_console.robot.readings import DepthReading, DvlVelocity, FinFeedback, FinFeedbacks, ImuReading, Reading

KIND = 0
T = 1
V = 2  # first value column
ROW = 16
# kinds
IMU, DEPTH, DVL, FINS, FIN = 1.0, 2.0, 3.0, 4.0, 5.0
# IMU columns
IMU_ACCEL = V
IMU_GYRO = V + 3
IMU_Q = V + 6
IMU_EULER = V + 10
# DEPTH
DEPTH_M = V
DEPTH_PA = V + 1
# DVL
DVL_V = V
DVL_VALID = V + 3
DVL_ALTITUDE = V + 4
DVL_FOM = V + 5
# FINS
FINS_ANGLE = V
FINS_RATE = V + N_FINS
# FIN
FIN_INDEX = V
FIN_ANGLE = V + 1
FIN_RATE = V + 2

_NAN3 = (math.nan,) * 3
_NAN4 = (math.nan,) * 4


def to_row(r: Reading, row: np.ndarray) -> None:
    """Write reading ``r`` into ``row`` (ValueError for a reading the loop does not take)."""
    tp = type(r)
    row[:] = math.nan
    row[T] = r.t
    if tp is FinFeedbacks:
        row[KIND] = FINS
        row[FINS_ANGLE:FINS_ANGLE + N_FINS] = r.position_rad
        row[FINS_RATE:FINS_RATE + N_FINS] = r.velocity_rad_s
    elif tp is FinFeedback:
        row[KIND] = FIN
        row[FIN_INDEX] = r.fin
        row[FIN_ANGLE] = r.position_rad
        row[FIN_RATE] = r.velocity_rad_s
    elif tp is ImuReading:
        row[KIND] = IMU
        row[IMU_ACCEL:IMU_ACCEL + 3] = r.accel_g
        row[IMU_GYRO:IMU_GYRO + 3] = r.gyro
        if r.quaternion is not None:
            row[IMU_Q:IMU_Q + 4] = r.quaternion
        if r.euler is not None:
            row[IMU_EULER:IMU_EULER + 3] = r.euler
    elif tp is DepthReading:
        row[KIND] = DEPTH
        row[DEPTH_M] = r.depth_m
        row[DEPTH_PA] = r.pressure_pa
    elif tp is DvlVelocity:
        row[KIND] = DVL
        row[DVL_V], row[DVL_V + 1], row[DVL_V + 2] = r.vx, r.vy, r.vz
        row[DVL_VALID] = 1.0 if r.valid else 0.0
        row[DVL_ALTITUDE] = r.altitude
        row[DVL_FOM] = r.fom
    else:
        raise ValueError(f"reading: unexpected type {tp.__name__} from the robot")


def _optional(values: list[float]) -> tuple[float, ...] | None:
    return None if math.isnan(values[0]) else tuple(values)


def from_row(row: np.ndarray) -> Reading:
    """The reading that ``row`` stands for."""
    return reading_of(row.tolist())


def reading_of(v: list[float]) -> Reading:
    """The reading that the numbers of a row (``row.tolist()``) stand for."""
    kind, t = v[KIND], v[T]
    if kind == IMU:
        return ImuReading(t, (v[IMU_ACCEL], v[IMU_ACCEL + 1], v[IMU_ACCEL + 2]),
                          (v[IMU_GYRO], v[IMU_GYRO + 1], v[IMU_GYRO + 2]),
                          _optional(v[IMU_Q:IMU_Q + 4]),  # type: ignore[arg-type]
                          _optional(v[IMU_EULER:IMU_EULER + 3]))  # type: ignore[arg-type]
    if kind == DEPTH:
        return DepthReading(t=t, depth_m=v[DEPTH_M], pressure_pa=v[DEPTH_PA])
    if kind == DVL:
        return DvlVelocity(t=t, vx=v[DVL_V], vy=v[DVL_V + 1], vz=v[DVL_V + 2], valid=v[DVL_VALID] != 0.0,
                           altitude=v[DVL_ALTITUDE], fom=v[DVL_FOM])
    if kind == FINS:
        fb = np.array(v[FINS_ANGLE:FINS_RATE + N_FINS])
        fb.flags.writeable = False
        return FinFeedbacks(t, fb[:N_FINS], fb[N_FINS:])
    if kind == FIN:
        return FinFeedback(t, int(v[FIN_INDEX]), v[FIN_ANGLE], v[FIN_RATE])
    raise ValueError(f"row: unknown reading kind {kind!r}")
