"""The readings as rows of numbers: what compiled code passes between the robot and the loop.

A reading (``robot.readings``) is one row of a float array, ``ROW`` wide: its kind, its
time, then its values (NaN where a value is missing). The simulated robot writes rows in
compiled code and the closed loop's compiled core reads them, so that a simulated sample
reaches the controller with no Python object in between; a robot that delivers reading
objects (the drivers) has them turned into rows by :func:`to_row`, and a row becomes the
reading it stands for with :func:`from_row` (for the telemetry, and for robots that hand
readings to the loop as objects).

Each kind's columns are its declared layout (``robot.layout``): :data:`IMU_ROW`,
:data:`DEPTH_ROW`, :data:`DVL_ROW`, :data:`FINS_ROW` (every fin's angle, then every fin's
rate, robot order), :data:`FIN_ROW` (one fin's drive); the column constants (``IMU_GYRO``
...) are taken from them.
"""

from __future__ import annotations

import math

import numpy as np

from ucat_console.robot.fins import N_FINS
from ucat_console.robot.layout import Layout
from ucat_console.robot.readings import DepthReading, DvlVelocity, FinFeedback, FinFeedbacks, ImuReading, Reading

# the declared layout of each kind's row: its kind, its time, then its values
_HEAD = [("kind", 1, "the reading's kind (IMU ... FIN)"), ("t", 1, "time, s")]
IMU_ROW = Layout("an IMU reading's row", _HEAD + [
    ("accel", 3, "specific force, m/s^2"), ("gyro", 3, "rates, rad/s"), ("q", 4, "attitude (NaN: not streamed)"),
    ("euler", 3, "roll, pitch, yaw (NaN: none)")])
DEPTH_ROW = Layout("a depth reading's row", _HEAD + [("depth_m", 1, "depth, m"), ("pressure_pa", 1, "pressure, Pa")])
DVL_ROW = Layout("a DVL report's row", _HEAD + [
    ("v", 3, "velocity, m/s"), ("valid", 1, "1.0: bottom lock, 0.0: none"), ("altitude", 1, "altitude, m"),
    ("fom", 1, "figure of merit")])
FINS_ROW = Layout("every fin's feedback row", _HEAD + [
    ("angle", N_FINS, "every fin's angle, robot order, rad"), ("rate", N_FINS, "and rate, rad/s")])
FIN_ROW = Layout("one fin's feedback row", _HEAD + [
    ("fin", 1, "the fin (robot order)"), ("angle", 1, "its angle, rad"), ("rate", 1, "its rate, rad/s")])
LAYOUTS = (IMU_ROW, DEPTH_ROW, DVL_ROW, FINS_ROW, FIN_ROW)
KIND, T = IMU_ROW.at("kind"), IMU_ROW.at("t")
ROW = 16
assert max(lay.size for lay in LAYOUTS) <= ROW

# kinds
IMU, DEPTH, DVL, FINS, FIN = 1.0, 2.0, 3.0, 4.0, 5.0
IMU_ACCEL, IMU_GYRO, IMU_Q, IMU_EULER = (IMU_ROW.at(f) for f in ("accel", "gyro", "q", "euler"))
DEPTH_M, DEPTH_PA = DEPTH_ROW.at("depth_m"), DEPTH_ROW.at("pressure_pa")
DVL_V, DVL_VALID, DVL_ALTITUDE, DVL_FOM = (DVL_ROW.at(f) for f in ("v", "valid", "altitude", "fom"))
FINS_ANGLE, FINS_RATE = FINS_ROW.at("angle"), FINS_ROW.at("rate")
FIN_INDEX, FIN_ANGLE, FIN_RATE = (FIN_ROW.at(f) for f in ("fin", "angle", "rate"))

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
        row[IMU_ACCEL:IMU_ACCEL + 3] = r.accel
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
