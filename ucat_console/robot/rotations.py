"""Quaternions, rotation matrices and Euler angles: the project's one implementation.

Conventions: ``q = (w, x, y, z)``, a unit quaternion rotating body (sensor) vectors into the
world (NED): ``v_world = R(q) v_body``. Euler angles are ZYX (yaw, pitch, roll), returned and
taken as (roll, pitch, yaw) in rad.

The arithmetic lives in compiled functions (numba, ``cache=True``) on plain floats and
arrays, which the plant's and the sensor models' kernels call directly; the Python-facing
functions below call the same compiled code, so a kernel and the estimator cannot disagree.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from numba import njit

Quaternion = tuple[float, float, float, float]
Vector3 = tuple[float, float, float]


# ---------------------------------------------------------------- compiled core


@njit(cache=True)
def quat_to_rot(q: np.ndarray, r: np.ndarray) -> None:
    """Fill ``r`` (3x3) with R(q) of the unit quaternion q = (w, x, y, z)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    r[0, 0] = 1.0 - 2.0 * (y * y + z * z)
    r[0, 1] = 2.0 * (x * y - w * z)
    r[0, 2] = 2.0 * (x * z + w * y)
    r[1, 0] = 2.0 * (x * y + w * z)
    r[1, 1] = 1.0 - 2.0 * (x * x + z * z)
    r[1, 2] = 2.0 * (y * z - w * x)
    r[2, 0] = 2.0 * (x * z - w * y)
    r[2, 1] = 2.0 * (y * z + w * x)
    r[2, 2] = 1.0 - 2.0 * (x * x + y * y)


@njit(cache=True)
def quat_mul(
    aw: float, ax: float, ay: float, az: float, bw: float, bx: float, by: float, bz: float
) -> tuple[float, float, float, float]:
    """Hamilton product a (x) b."""
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


@njit(cache=True)
def quat_to_euler(w: float, x: float, y: float, z: float) -> tuple[float, float, float]:
    """ZYX Euler angles (roll, pitch, yaw) of a unit quaternion; yaw in (-pi, pi]."""
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x))))
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return roll, pitch, yaw


@njit(cache=True)
def euler_to_quat(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """ZYX Euler angles (rad) to the quaternion (w, x, y, z) (unit up to rounding)."""
    cr, sr = math.cos(0.5 * roll), math.sin(0.5 * roll)
    cp, sp = math.cos(0.5 * pitch), math.sin(0.5 * pitch)
    cy, sy = math.cos(0.5 * yaw), math.sin(0.5 * yaw)
    return (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )


# ---------------------------------------------------------------- Python-facing


def rotation_matrix(q: Sequence[float]) -> np.ndarray:
    """R(q) (3x3): body to world."""
    r = np.empty((3, 3))
    quat_to_rot(np.asarray(q, dtype=float), r)
    return r


def quaternion_multiply(a: Sequence[float], b: Sequence[float]) -> Quaternion:
    aw, ax, ay, az = (float(v) for v in a)
    bw, bx, by, bz = (float(v) for v in b)
    return quat_mul(aw, ax, ay, az, bw, bx, by, bz)


def quaternion_normalize(q: Sequence[float]) -> Quaternion:
    """``q / |q|`` with ``w >= 0`` (one sign for one rotation)."""
    n = math.sqrt(sum(v * v for v in q))
    if not n > 0.0 or not math.isfinite(n):
        raise ValueError(f"quaternion {tuple(q)!r} cannot be normalised")
    w, x, y, z = (v / n for v in q)
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    return (w, x, y, z)


def quaternion_from_rotation_vector(phi: Sequence[float]) -> Quaternion:
    """``exp`` of a rotation vector (axis times angle, rad)."""
    px, py, pz = (float(v) for v in phi)
    angle = math.sqrt(px * px + py * py + pz * pz)
    if angle < 1e-12:
        return quaternion_normalize((1.0, 0.5 * px, 0.5 * py, 0.5 * pz))
    s = math.sin(0.5 * angle) / angle
    return (math.cos(0.5 * angle), s * px, s * py, s * pz)


def quaternion_from_euler(roll: float, pitch: float, yaw: float) -> Quaternion:
    """ZYX Euler angles (rad) to the quaternion (w, x, y, z) (unit up to rounding; normalise
    with :func:`quaternion_normalize` for ``w >= 0``)."""
    return euler_to_quat(float(roll), float(pitch), float(yaw))


def euler_from_quaternion(q: Sequence[float]) -> Vector3:
    """ZYX Euler angles (roll, pitch, yaw) in rad; yaw in (-pi, pi]."""
    w, x, y, z = (float(v) for v in q)
    return quat_to_euler(w, x, y, z)


def skew(v: Sequence[float]) -> np.ndarray:
    """The cross-product matrix S(v): S(v) u = v x u."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def quaternion_from_matrix(m: np.ndarray) -> Quaternion:
    """(w, x, y, z) of a rotation matrix (Shepperd's method: the largest of the four
    candidates, so no division by a small number)."""
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        w, x, y, z = 0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2]) * 2
        w, x, y, z = (m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s
    elif m[1, 1] > m[2, 2]:
        s = math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2]) * 2
        w, x, y, z = (m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s
    else:
        s = math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1]) * 2
        w, x, y, z = (m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s
    return (float(w), float(x), float(y), float(z))
