"""The fin as a flat plate hinged on its shaft, and the inertia each stroke spins up.

The plate reaches ``R`` from the shaft and is ``span`` wide along it, sized so that its
r^2-moment of area is the fin model's ``A_f r_c^2`` (``R = sqrt(3) r_c``, ``span = A_f /
R``). Turning it about the shaft turns the water beside it too: strips across the plate carry
the 2-D added mass of a plate of width ``span`` (Newman, *Marine Hydrodynamics*, 1977,
section 4.13), an added inertia ``rho pi span^2 R^3 / 12`` about the shaft, 0.018 kg m2 for
the U-CAT's fin against the blade's own 2.8e-5. The simulated plant's fin
(``backend/sim/plate.py``) is this plate.

A stroke starts from rest and ends at rest, and the drives do not regenerate
(``robot/motor.py``): each stroke spins up the blade, the water it carries and the motor's
rotor (``J_r N^2`` at the shaft, 0.017 kg m2 with the default drive) and gets none of it
back. :data:`STROKE_INERTIA` is their sum: what the closed-stroke MPC's energy term charges a
stroke for when it is given the drive's whole load (``[loop.mpc] fin_inertia``,
``control/cost.py``). This module imports nothing of the package but the robot description.
"""

from __future__ import annotations

import math

from ucat_console.robot.geometry import FIN_AREA, FIN_R_C
from ucat_console.robot.hull import FIN_INERTIA
from ucat_console.robot.motor import FinMotor
from ucat_console.robot.units import RHO_TABLE_I


def plate_geometry(r_c: float, area: float) -> tuple[float, float]:
    """(R, span) of the plate whose r^2-moment of area is ``area r_c^2``: ``R = sqrt(3) r_c``."""
    radius = math.sqrt(3.0) * r_c
    return radius, area / radius


def added_inertia(rho: float, r_c: float, area: float, factor: float = 1.0) -> float:
    """The plate's added inertia about the shaft, ``factor rho pi span^2 R^3 / 12`` (kg m2)."""
    radius, span = plate_geometry(r_c, area)
    return factor * rho * math.pi * span * span * radius ** 3 / 12.0


def rotor_inertia_at_shaft(motor: FinMotor) -> float:
    """The motor rotor's inertia seen at the fin's shaft, ``J_r N^2`` (kg m2)."""
    return motor.rotor_inertia * motor.gear_ratio ** 2


#: what a stroke from rest spins up and the drive does not get back (kg m2): the blade, the
#: water it carries and the default drive's rotor
STROKE_INERTIA = FIN_INERTIA + added_inertia(RHO_TABLE_I, FIN_R_C, FIN_AREA) + rotor_inertia_at_shaft(FinMotor())
