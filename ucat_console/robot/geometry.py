"""The U-CAT's hull and fin geometry: what the 3-D view, the allocation and the plant share.

Frames: body FRD (x forward, y starboard, z down). Each fin works in its own 2-D plane
(the controller's fin model, control.md section 1): ``x_m`` is horizontal, pointing to the
body's rear at the mounting angle alpha from the body's -x axis (towards the inside for the
front fins, the outside for the rear fins, as in eeUVsim's surge/sway maps); ``y_m`` is
vertical, pointing up (towards the surface). A model force (f_x, f_y) acts on the body as
(-f_x cos(alpha), s_y f_x sin(alpha), -f_y) with s_y from :func:`.fins.fin_signs`;
alpha = 0 gives exactly (-f_x, 0, -f_y). Fin angle theta = 0 is the fin's neutral
(horizontal) position; theta > 0 turns the fin from ``x_m`` towards ``y_m`` (tip up).

The defaults below are the TalTech eeUVsim U-CAT's (``finDynamics``); the plant's
configuration (``backend/sim/params.py``) takes them as its defaults and may change them,
and :attr:`PlantConfig.geometry` gives the geometry in force as a :class:`Geometry`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

from ucat_console.robot.fins import fin_signs

Vec3 = tuple[float, float, float]

#: hull box length, width, height (m)
HULL_SIZE: Vec3 = (0.57, 0.30, 0.25)
#: fin plane's horizontal axis from the body x axis (deg)
MOUNTING_ANGLE_DEG = 30.0
#: roll moment arm of a fin's vertical force (m)
ARM_ROLL = 0.1502
#: pitch moment arm of a fin's vertical force (m)
ARM_PITCH = 0.25753
#: yaw moment arm of a fin's horizontal in-plane force (m)
ARM_YAW = 0.2981
#: effective fin length L_f (m, paper Table I)
FIN_LENGTH = 0.10
#: fin planform area A_f (m2, paper Table I)
FIN_AREA = 0.020
#: the fin's radius of gyration r_c (m, paper Table I)
FIN_R_C = 0.10


@dataclass(frozen=True)
class Geometry:
    """Hull size and fin mounting of one robot (defaults: the U-CAT's)."""

    hull_size: Vec3 = HULL_SIZE
    fin_length: float = FIN_LENGTH
    mounting_angle_deg: float = MOUNTING_ANGLE_DEG
    arm_roll: float = ARM_ROLL
    arm_pitch: float = ARM_PITCH
    arm_yaw: float = ARM_YAW


class HasMountingAngle(Protocol):
    mounting_angle_deg: float


def fin_plane_axes(geometry: HasMountingAngle, fin: int) -> tuple[Vec3, Vec3]:
    """Body-frame unit vectors (x_m, y_m) of a robot fin's working plane.

    The fin's chord direction at angle theta is cos(theta) x_m + sin(theta) y_m.
    """
    _, _, s_y = fin_signs(fin)
    a = math.radians(geometry.mounting_angle_deg)
    return (-math.cos(a), s_y * math.sin(a), 0.0), (0.0, 0.0, -1.0)


# ---------------------------------------------------------------------- as drawn
#: how long a fin blade is drawn, as a multiple of the effective fin length L_f (the
#: model's length is a hydrodynamic effective length; the blade itself is longer)
BLADE_LENGTH_FACTOR = 1.5
#: span of a fin blade along its shaft (m) and its thickness (m), as drawn
BLADE_SPAN = 0.08
BLADE_THICKNESS = 0.006


def nose_cap(hull_size: Vec3) -> tuple[Vec3, Vec3]:
    """Centre and semi-axes (m, body frame) of the red cap drawn at the hull's nose: an
    ellipsoid just inside the hull's front end."""
    half = tuple(0.5 * s for s in hull_size)
    return (half[0] - 0.01, 0.0, 0.0), (0.035, 0.35 * half[1], 0.35 * half[2])

Quat = tuple[float, float, float, float]


def _cross(a: Vec3, b: Vec3) -> Vec3:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def fin_mount(geometry: Geometry, fin: int) -> tuple[Vec3, Quat]:
    """Body-frame position and orientation (w, x, y, z) of a fin's mount frame, whose axes
    are the fin plane's (x_m, y_m) and its normal; the blade turns about the normal and
    spans along it, just outside the hull."""
    import numpy as np

    from ucat_console.robot.rotations import quaternion_from_matrix

    s_lat, s_long, _ = fin_signs(fin)
    xm, ym = fin_plane_axes(geometry, fin)
    n = _cross(xm, ym)
    outward = 1.0 if n[1] * s_lat > 0 else -1.0
    base = (s_long * geometry.arm_pitch, s_lat * max(geometry.arm_roll, geometry.hull_size[1] / 2), 0.0)
    off = outward * (BLADE_SPAN / 2 + 0.01)
    pos = (base[0] + off * n[0], base[1] + off * n[1], base[2] + off * n[2])
    matrix = ((xm[0], ym[0], n[0]), (xm[1], ym[1], n[1]), (xm[2], ym[2], n[2]))
    return pos, tuple(float(v) for v in quaternion_from_matrix(np.array(matrix)))  # type: ignore[return-value]
