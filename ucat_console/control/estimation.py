"""State estimation: attitude from gyro and accelerometer, position by dead reckoning.

Pure functions of the core (no clock, no thread, no I/O: time is an argument); the closed
loop calls them on the readings it receives, whichever robot delivers them. Median and
low-pass filters are in :mod:`ucat_console.control.filters`.

Attitude: a small multiplicative quaternion EKF, used when the IMU (the IMU-only 3DM-CX5)
does not stream its own orientation. Pure functions on a frozen :class:`AttitudeState`;
:class:`AttitudeEstimator` only holds the state between samples.

Conventions (those of the 3DM-CX5): sensor frame x forward, y right, z down; world frame
NED; ``q = (w, x, y, z)`` rotates sensor vectors into the world (``v_w = R(q) v_b``);
Euler angles are ZYX (yaw, pitch, roll). The accelerometer measures specific force in
m/s^2, so a level sensor at rest reads ``(0, 0, -g0)`` (g0: standard gravity); the filter's
accelerometer settings are in standard gravities (``g_n``), as data sheets give them.

Filter: nominal quaternion and gyro bias, error state ``[dtheta (sensor frame), dbias]``
with a 6x6 covariance. Prediction integrates ``gyro - bias`` exactly for a constant rate
over the step; the correction compares the measured specific-force direction with
``R(q)^T (0, 0, -1)``. The correction is skipped while the vehicle accelerates (the norm
of the specific force differs from g0 by more than ``accel_gate`` g0). Yaw is not
observable from gravity: it follows the gyro alone, as in the paper's EKF without a
magnetometer.

Dead reckoning: :func:`dead_reckon` integrates a DVL's body-frame velocity, rotated into
NED by the attitude, over the time since the previous report.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from numba.extending import register_jitable

from ucat_console.robot.readings import ImuReading
from ucat_console.robot.rotations import (
    quat_to_rot,
    Quaternion,
    Vector3,
    euler_from_quaternion,
    quaternion_from_euler,
    quaternion_from_rotation_vector,
    quaternion_multiply,
    quaternion_normalize,
    rotation_matrix,
    skew,
)
from ucat_console.robot.units import GRAVITY
from ucat_console.typedconf import Config, param

_GRAVITY_DIRECTION_NED = np.array([0.0, 0.0, -1.0])  # specific force at rest, in g


@dataclass(frozen=True)
class AttitudeConfig(Config):
    """Noise model and gates of the attitude EKF."""

    gyro_noise: float = param(
        0.003, lo=0.0, hi=1.0, lo_open=True, unit="rad/s/sqrt(Hz)", doc="gyro white-noise density"
    )
    gyro_bias_walk: float = param(
        1e-4, lo=0.0, hi=0.1, unit="rad/s/sqrt(s)", doc="gyro bias random walk"
    )
    accel_noise: float = param(
        0.03, lo=0.0, hi=1.0, lo_open=True, unit="g_n", doc="accelerometer noise per sample"
    )
    accel_gate: float = param(
        0.15, lo=0.0, hi=2.0, lo_open=True, unit="g_n",
        doc="skip the accel correction when | |a| / g0 - 1 | exceeds this",
    )
    initial_attitude_std: float = param(
        0.5, lo=0.0, hi=3.2, lo_open=True, unit="rad", doc="initial attitude uncertainty"
    )
    initial_bias_std: float = param(
        0.02, lo=0.0, hi=1.0, unit="rad/s", doc="initial gyro bias uncertainty"
    )
    max_dt: float = param(
        0.25, lo=0.0, hi=10.0, lo_open=True, unit="s",
        doc="longer gaps between samples are not integrated (only the uncertainty grows)",
    )


@dataclass(frozen=True)
class AttitudeState:
    """Estimate at time ``t``: attitude, gyro bias and error covariance (6x6, read-only)."""

    t: float
    q: Quaternion
    bias: Vector3
    cov: np.ndarray = field(repr=False, compare=False)

    @property
    def euler(self) -> Vector3:
        return euler_from_quaternion(self.q)

    @property
    def attitude_std(self) -> Vector3:
        d = np.sqrt(np.clip(np.diag(self.cov)[:3], 0.0, None))
        return (float(d[0]), float(d[1]), float(d[2]))


# ---------------------------------------------------------------- attitude


def tilt_from_accel(accel: Sequence[float]) -> tuple[float, float]:
    """Roll and pitch (rad) of a sensor at rest from its specific force (any unit)."""
    fx, fy, fz = (float(v) for v in accel)
    roll = math.atan2(-fy, -fz)
    pitch = math.atan2(fx, math.hypot(fy, fz))
    return roll, pitch


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a



def initial_state(
    t: float,
    config: AttitudeConfig = AttitudeConfig(),
    accel: Sequence[float] | None = None,
    yaw: float = 0.0,
) -> AttitudeState:
    """Start at ``yaw``; level, or tilted as the accelerometer (``accel``, m/s^2) says when
    it is given."""
    roll = pitch = 0.0
    if accel is not None and all(math.isfinite(float(v)) for v in accel):
        roll, pitch = tilt_from_accel(accel)
    cov = np.diag(
        [config.initial_attitude_std**2] * 3 + [config.initial_bias_std**2] * 3
    )
    q = quaternion_normalize(quaternion_from_euler(roll, pitch, yaw))
    return AttitudeState(float(t), q, (0.0, 0.0, 0.0), _frozen(cov))


def predict(
    state: AttitudeState, t: float, gyro: Sequence[float], config: AttitudeConfig = AttitudeConfig()
) -> AttitudeState:
    """Propagate to time ``t`` with the rate ``gyro`` (rad/s) held over the step.

    A step back in time is ignored; a gap longer than ``max_dt`` grows the uncertainty
    without moving the estimate (the rate over the gap is unknown).
    """
    dt = float(t) - state.t
    if not dt > 0.0:
        return state
    g = np.array([float(v) for v in gyro])
    if not np.all(np.isfinite(g)):
        raise ValueError(f"gyro: {tuple(gyro)!r} is not finite")
    q_noise = config.gyro_noise**2 * dt
    b_noise = config.gyro_bias_walk**2 * dt
    Q = np.diag([q_noise] * 3 + [b_noise] * 3)
    P = np.array(state.cov)
    if dt > config.max_dt:
        gap = np.diag([config.gyro_noise**2 * dt + (0.1 * dt) ** 2] * 3 + [b_noise] * 3)
        return AttitudeState(float(t), state.q, state.bias, _frozen(P + gap))
    w = g - np.array(state.bias)
    phi = w * dt
    q = quaternion_normalize(quaternion_multiply(state.q, quaternion_from_rotation_vector(phi)))
    # error dynamics: d(dtheta)/dt = -[w x] dtheta - dbias
    F = np.eye(6)
    F[:3, :3] = rotation_matrix(quaternion_from_rotation_vector(phi)).T
    F[:3, 3:] = -np.eye(3) * dt
    P = F @ P @ F.T + Q
    return AttitudeState(float(t), q, state.bias, _frozen(0.5 * (P + P.T)))


def correct(
    state: AttitudeState, accel: Sequence[float], config: AttitudeConfig = AttitudeConfig()
) -> AttitudeState:
    """Correct roll and pitch (and the gyro bias) with the direction of the specific force
    ``accel`` (m/s^2)."""
    a = np.array([float(v) for v in accel])
    if not np.all(np.isfinite(a)):
        raise ValueError(f"accel: {tuple(accel)!r} is not finite")
    norm = float(np.linalg.norm(a))
    if abs(norm / GRAVITY - 1.0) > config.accel_gate:
        return state
    z = a / norm
    R = rotation_matrix(state.q)
    h = R.T @ _GRAVITY_DIRECTION_NED
    H = np.zeros((3, 6))
    H[:, :3] = skew(h)
    P = np.array(state.cov)
    Rn = np.eye(3) * config.accel_noise**2
    S = H @ P @ H.T + Rn
    K = np.linalg.solve(S, H @ P).T  # P H^T S^-1 (S and P symmetric)
    dx = K @ (z - h)
    q = quaternion_normalize(quaternion_multiply(state.q, quaternion_from_rotation_vector(dx[:3])))
    bias = np.array(state.bias) + dx[3:]
    I_KH = np.eye(6) - K @ H
    P = I_KH @ P @ I_KH.T + K @ Rn @ K.T
    return AttitudeState(
        state.t, q, (float(bias[0]), float(bias[1]), float(bias[2])), _frozen(0.5 * (P + P.T))
    )


def step(
    state: AttitudeState,
    t: float,
    accel: Sequence[float],
    gyro: Sequence[float],
    config: AttitudeConfig = AttitudeConfig(),
) -> AttitudeState:
    """One IMU sample: predict to ``t`` with ``gyro``, then correct with ``accel`` (m/s^2)."""
    return correct(predict(state, t, gyro, config), accel, config)


def gravity_innovation(q: Sequence[float], accel: Sequence[float], gate: float) -> float:
    """The attitude ``q`` (w, x, y, z; sensor to NED) against the accelerometer: the angle
    (rad) between the measured specific force ``accel`` and the direction ``q`` predicts for
    it at rest, ``R(q)^T (0, 0, -1)`` (what :func:`correct` compares). NaN when the specific
    force's norm differs from g0 by more than ``gate`` g0 (the sensor accelerates: its
    specific force is not gravity's direction, and the filter skips it too) or a value is not
    finite."""
    w, x, y, z = (float(v) for v in q)
    ax, ay, az = (float(v) for v in accel)
    qn = math.sqrt(w * w + x * x + y * y + z * z)
    norm = math.sqrt(ax * ax + ay * ay + az * az)
    if not (math.isfinite(qn) and math.isfinite(norm) and qn > 0.0 and norm > 0.0):
        return math.nan
    if abs(norm / GRAVITY - 1.0) > gate:
        return math.nan
    w, x, y, z = w / qn, x / qn, y / qn, z / qn
    # minus the third row of R(q): the world's up in the sensor frame
    hx, hy, hz = -2.0 * (x * z - w * y), -2.0 * (y * z + w * x), -(1.0 - 2.0 * (x * x + y * y))
    c = (ax * hx + ay * hy + az * hz) / norm
    return math.acos(max(-1.0, min(1.0, c)))


class AttitudeEstimator:
    """Holds the state between samples; the first sample initialises the tilt."""

    def __init__(self, config: AttitudeConfig = AttitudeConfig(), initial_yaw: float = 0.0) -> None:
        self.config = config
        self._yaw0 = initial_yaw
        self.state: AttitudeState | None = None

    def update(self, reading: ImuReading) -> AttitudeState:
        if self.state is None:
            self.state = initial_state(reading.t, self.config, reading.accel, self._yaw0)
            return self.state
        self.state = step(self.state, reading.t, reading.accel, reading.gyro, self.config)
        return self.state

    def reset(self, initial_yaw: float = 0.0) -> None:
        self._yaw0 = initial_yaw
        self.state = None


# ---------------------------------------------------------------- dead reckoning

#: longest gap between DVL reports that is integrated (s); a longer one counts as this long
MAX_DEAD_RECKONING_GAP = 1.0


@register_jitable
def dead_reckon_into(xy: np.ndarray, q: np.ndarray, velocity: np.ndarray, dt: float, r: np.ndarray) -> None:
    """Move ``xy`` (north, east; in place) at the body-frame ``velocity`` (m/s) for ``dt``
    seconds (clipped to 0 .. :data:`MAX_DEAD_RECKONING_GAP`) with attitude ``q`` (``r``: a
    3x3 scratch array). The one definition: :func:`dead_reckon` runs it as Python, the
    closed loop's compiled core compiled."""
    dt = min(max(dt, 0.0), MAX_DEAD_RECKONING_GAP)
    quat_to_rot(q, r)
    vx, vy, vz = velocity[0], velocity[1], velocity[2]
    x = xy[0] + dt * (r[0, 0] * vx + r[0, 1] * vy + r[0, 2] * vz)
    y = xy[1] + dt * (r[1, 0] * vx + r[1, 1] * vy + r[1, 2] * vz)
    xy[0] = x
    xy[1] = y


def dead_reckon(
    xy: tuple[float, float], q: Sequence[float], velocity: Sequence[float], dt: float
) -> tuple[float, float]:
    """North and east position after moving at the body-frame ``velocity`` (m/s) for ``dt``
    seconds (clipped to 0 .. :data:`MAX_DEAD_RECKONING_GAP`) with attitude ``q``."""
    out = np.array(xy, dtype=float)
    dead_reckon_into(out, np.asarray(q, dtype=float), np.asarray(velocity, dtype=float), float(dt),
                     np.empty((3, 3)))
    return float(out[0]), float(out[1])
