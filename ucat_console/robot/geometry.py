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
