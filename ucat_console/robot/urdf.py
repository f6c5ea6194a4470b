"""The robot as a URDF: the hull, the four fins and their joints, with inertials, collisions and
joint limits, for ROS (robot_state_publisher, Gazebo, ros2_control), Foxglove's URDF layer and
any URDF loader.

Links are named as the transform frames of the session files and the live Foxglove server
(``backend/sessions/foxglove.py``), so a URDF loaded beside a recording lines up with its
transforms::

    base_link       root: the vehicle in REP 103's FLU axes (x forward, y left, z up), as
                    mavros and PX4 name it; no inertial of its own (KDL takes none on a root)
    base_link_frd   fixed joint, half a turn about x: the vehicle in FRD axes (x forward, y
                    starboard, z down), the axes of the telemetry, the plant and the fin
                    mounts. The hull: visual an ellipsoid of the hull's length, width and
                    height (``hull.stl``, a unit sphere scaled per axis) with its red nose
                    cap; collision the box of the hull's size; inertial the robot's (below)
    fin<i>          continuous joint ``fin<i>_joint`` at the fin's mount
                    (``geometry.fin_mount``), turning about its z axis; visual the blade as
                    the console draws it (``BLADE_LENGTH_FACTOR`` x L_f along x,
                    ``BLADE_SPAN`` along z); collision and inertial a thin box of that chord
                    whose planform is the fin's area A_f (span A_f / chord)

Where the numbers come from (:func:`inertials`):

* the whole robot at the fins' neutral angle has the plant's rigid body: mass
  ``hull.MASS`` (22 kg, the paper's Table II), centre of gravity ``hull.CG``, inertias
  ``hull.IXX``, ``IYY``, ``IZZ`` about it (eeUVsim's U-CAT). The hull link holds that
  minus the four fins.
* a fin's inertia about its shaft is the plant's, ``hull.FIN_INERTIA`` (2.8e-5 kg m2,
  eeUVsim). The U-CAT's sources give no fin mass: it is the mass of a uniform box of the
  collision's size with that inertia about the shaft, ``12 J / (4 c^2 + t^2)`` (3.7 g; a
  derived value, not a measurement).
* joint limits are the drive's: velocity the servo model's largest rate
  (``servo.FIN_MAX_RATE``); effort the torque the motor's nominal (largest continuous)
  current gives the shaft through the gearhead (``motor.NOMINAL_CURRENT`` through
  :meth:`FinMotor.shaft_torque`: 2.01 N m). The fins turn freely (continuous joints: the
  servo model has no end stop).

The shipped ROS package ``ucat_description`` (``ucat_console/robot/ucat_description``:
``package.xml``, ``CMakeLists.txt``, ``urdf/ucat.urdf``, ``meshes/hull.stl``) holds the files
:func:`write` makes from the default geometry; a test checks that they are what this module
makes now. Meshes are referenced as ``package://ucat_description/meshes/...``: ROS resolves
them once the package is built in a workspace (or with ``ucat_console/robot`` on
``ROS_PACKAGE_PATH``), Foxglove with that folder as its "ROS package path", and the live
Foxglove server serves them itself.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ucat_console.robot import hull
from ucat_console.robot.fins import N_FINS
from ucat_console.robot.geometry import (
    BLADE_LENGTH_FACTOR,
    BLADE_SPAN,
    BLADE_THICKNESS,
    FIN_AREA,
    Geometry,
    fin_mount,
    nose_cap,
)
from ucat_console.robot.look import FIN_COLOURS, HULL_COLOUR, NOSE_COLOUR
from ucat_console.robot.motor import NOMINAL_CURRENT, FinMotor
from ucat_console.robot.rotations import euler_from_quaternion, rotation_matrix
from ucat_console.robot.servo import FIN_MAX_RATE

PACKAGE = "ucat_description"
PACKAGE_DIR = Path(__file__).with_name(PACKAGE)
URDF_PATH = PACKAGE_DIR / "urdf" / "ucat.urdf"
MESH_PATH = PACKAGE_DIR / "meshes" / "hull.stl"
PACKAGE_XML = PACKAGE_DIR / "package.xml"
#: the files as package URIs (``package://<package>/<path in the package>``)
URDF_URI = f"package://{PACKAGE}/urdf/{URDF_PATH.name}"
MESH_URI = f"package://{PACKAGE}/meshes/{MESH_PATH.name}"
#: the URDF's URI in layouts saved before it moved into the ROS package (still served)
OLD_URDF_URI = "package://ucat_console/robot/urdf/ucat.urdf"
ROOT_LINK = "base_link"
FRD_LINK = "base_link_frd"
#: the fin joints' effort limit (N m): the nominal current's torque at the shaft
FIN_EFFORT = FinMotor().shaft_torque(NOMINAL_CURRENT)
_SUBDIVISIONS = 2  # of the icosahedron: 320 faces


def fin_link(fin: int) -> str:
    return f"fin{fin}"


# ------------------------------------------------------------------ the hull mesh
def unit_sphere(subdivisions: int = _SUBDIVISIONS) -> list[tuple[tuple[float, float, float], ...]]:
    """Triangles of an icosphere of radius 1, counter-clockwise seen from outside."""
    t = (1.0 + math.sqrt(5.0)) / 2.0
    raw = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t),
           (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]

    def unit(p: tuple[float, ...]) -> tuple[float, float, float]:
        n = math.sqrt(sum(c * c for c in p))
        return (p[0] / n, p[1] / n, p[2] / n)

    v = [unit(p) for p in raw]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
             (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
             (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    tris = [(v[a], v[b], v[c]) for a, b, c in faces]
    for _ in range(subdivisions):
        finer = []
        for a, b, c in tris:
            ab, bc, ca = (unit(tuple((p + q) / 2 for p, q in zip(x, y))) for x, y in ((a, b), (b, c), (c, a)))
            finer += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        tris = finer
    return tris


def sphere_stl(subdivisions: int = _SUBDIVISIONS) -> bytes:
    """A unit icosphere as a binary STL (what ``hull.stl`` holds)."""
    tris = unit_sphere(subdivisions)
    out = [b"ucat_console unit sphere (the hull: scaled per axis in the URDF)".ljust(80, b" "),
           struct.pack("<I", len(tris))]
    for a, b, c in tris:
        n = tuple((a[i] + b[i] + c[i]) / 3.0 for i in range(3))  # outward: the centroid's direction
        length = math.sqrt(sum(x * x for x in n))
        out.append(struct.pack("<12fH", *(x / length for x in n), *a, *b, *c, 0))
    return b"".join(out)


# ------------------------------------------------------------------ inertials
@dataclass(frozen=True)
class Inertial:
    """A link's mass (kg), centre of mass (m, link frame) and inertia about it (kg m2, link axes)."""

    mass: float
    com: tuple[float, float, float]
    inertia: np.ndarray


def fin_box(geometry: Geometry) -> tuple[float, float, float]:
    """A fin's collision box in its link (chord along x, thickness along y, span along z):
    the drawn blade's chord, the span that makes its planform the fin's area A_f."""
    chord = BLADE_LENGTH_FACTOR * geometry.fin_length
    return chord, BLADE_THICKNESS, FIN_AREA / chord


def _box_inertia(mass: float, size: tuple[float, float, float]) -> np.ndarray:
    a, b, c = size
    return np.diag([mass * (b * b + c * c), mass * (a * a + c * c), mass * (a * a + b * b)]) / 12.0


def _shift(mass: float, d: np.ndarray) -> np.ndarray:
    """The parallel-axis term: what a point mass at ``d`` adds to an inertia about the origin."""
    return mass * (float(d @ d) * np.eye(3) - np.outer(d, d))


def inertials(geometry: Geometry | None = None) -> tuple[Inertial, Inertial]:
    """(the hull's, one fin's) inertial (module docstring): the fin's, in its link, has the
    plant's fin inertia about the shaft; the hull's, in ``base_link_frd``, is what makes the
    robot with its fins at the neutral angle the plant's rigid body."""
    g = geometry or Geometry()
    chord, thickness, span = fin_box(g)
    m_f = 12.0 * hull.FIN_INERTIA / (4.0 * chord * chord + thickness * thickness)
    fin = Inertial(m_f, (chord / 2, 0.0, 0.0), _box_inertia(m_f, (chord, thickness, span)))
    cg = np.array(hull.CG)
    m_h = hull.MASS - N_FINS * m_f
    remaining = np.diag([hull.IXX, hull.IYY, hull.IZZ]).astype(float)  # about the CG
    moment = hull.MASS * cg
    for i in range(N_FINS):
        position, q = fin_mount(g, i)
        r = rotation_matrix(q)
        p = np.array(position) + r @ np.array(fin.com)
        remaining -= r @ fin.inertia @ r.T + _shift(m_f, p - cg)
        moment -= m_f * p
    com = moment / m_h
    remaining -= _shift(m_h, com - cg)
    return Inertial(m_h, tuple(float(x) for x in com), remaining), fin  # type: ignore[arg-type]


# ------------------------------------------------------------------ the URDF
def _f(x: float) -> str:
    return f"{x:.12g}" if abs(x) > 1e-12 else "0"  # (no -0 or rounding dust)


def _v(values: tuple[float, ...] | list[float]) -> str:
    return " ".join(_f(float(x)) for x in values)


def _rgba(rgb: tuple[int, int, int]) -> str:
    return _v([c / 255 for c in rgb] + [1.0])


def _inertial_lines(inertial: Inertial) -> list[str]:
    i = inertial.inertia
    return [
        "    <inertial>",
        f'      <origin xyz="{_v(inertial.com)}" rpy="0 0 0"/>',
        f'      <mass value="{_f(inertial.mass)}"/>',
        f'      <inertia ixx="{_f(i[0, 0])}" ixy="{_f(i[0, 1])}" ixz="{_f(i[0, 2])}" iyy="{_f(i[1, 1])}"'
        f' iyz="{_f(i[1, 2])}" izz="{_f(i[2, 2])}"/>',
        "    </inertial>",
    ]


def urdf_text(geometry: Geometry | None = None) -> str:
    """The URDF of a robot of ``geometry`` (default: the U-CAT's)."""
    g = geometry or Geometry()
    half = tuple(0.5 * float(s) for s in g.hull_size)
    nose, nose_semi_axes = nose_cap(g.hull_size)
    blade = BLADE_LENGTH_FACTOR * g.fin_length
    hull_inertial, fin_inertial = inertials(g)
    box = fin_box(g)
    lines = [
        '<?xml version="1.0"?>',
        "<!-- The U-CAT, made by ucat_console.robot.urdf (urdf_text) from its default geometry;",
        "     links are named as the transform frames of the session files. Where the",
        "     inertials, collisions and limits come from: that module's docstring. -->",
        '<robot name="ucat">',
        f'  <material name="hull"><color rgba="{_rgba(HULL_COLOUR)}"/></material>',
        f'  <material name="nose"><color rgba="{_rgba(NOSE_COLOUR)}"/></material>',
        *(f'  <material name="fin{i}"><color rgba="{_rgba(c)}"/></material>' for i, c in enumerate(FIN_COLOURS)),
        f'  <link name="{ROOT_LINK}"/>',
        f'  <link name="{FRD_LINK}">',
        *_inertial_lines(hull_inertial),
        '    <visual name="hull">',
        f'      <geometry><mesh filename="{MESH_URI}" scale="{_v(half)}"/></geometry>',
        '      <material name="hull"/>',
        "    </visual>",
        '    <visual name="nose">',
        f'      <origin xyz="{_v(nose)}" rpy="0 0 0"/>',
        f'      <geometry><mesh filename="{MESH_URI}" scale="{_v(nose_semi_axes)}"/></geometry>',
        '      <material name="nose"/>',
        "    </visual>",
        '    <collision name="hull">',
        f'      <geometry><box size="{_v(g.hull_size)}"/></geometry>',
        "    </collision>",
        "  </link>",
        f'  <joint name="{FRD_LINK}_joint" type="fixed">',
        f'    <parent link="{ROOT_LINK}"/>',
        f'    <child link="{FRD_LINK}"/>',
        f'    <origin xyz="0 0 0" rpy="{_v((math.pi, 0.0, 0.0))}"/>',
        "  </joint>",
    ]
    for i in range(N_FINS):
        position, q = fin_mount(g, i)
        rpy = euler_from_quaternion(q)
        lines += [
            f'  <link name="{fin_link(i)}">',
            *_inertial_lines(fin_inertial),
            "    <visual>",
            f'      <origin xyz="{_v((blade / 2, 0.0, 0.0))}" rpy="0 0 0"/>',
            f'      <geometry><box size="{_v((blade, BLADE_THICKNESS, BLADE_SPAN))}"/></geometry>',
            f'      <material name="fin{i}"/>',
            "    </visual>",
            "    <collision>",
            f'      <origin xyz="{_v((box[0] / 2, 0.0, 0.0))}" rpy="0 0 0"/>',
            f'      <geometry><box size="{_v(box)}"/></geometry>',
            "    </collision>",
            "  </link>",
            f'  <joint name="{fin_link(i)}_joint" type="continuous">',
            f'    <parent link="{FRD_LINK}"/>',
            f'    <child link="{fin_link(i)}"/>',
            f'    <origin xyz="{_v(position)}" rpy="{_v(rpy)}"/>',
            '    <axis xyz="0 0 1"/>',
            f'    <limit effort="{_f(FIN_EFFORT)}" velocity="{_f(FIN_MAX_RATE)}"/>',
            "  </joint>",
        ]
    lines.append("</robot>")
    return "\n".join(lines) + "\n"


def write(directory: Path = PACKAGE_DIR) -> list[Path]:
    """Write ``urdf/ucat.urdf`` and ``meshes/hull.stl`` of the default geometry into the
    package folder ``directory``."""
    urdf = directory / URDF_PATH.relative_to(PACKAGE_DIR)
    mesh = directory / MESH_PATH.relative_to(PACKAGE_DIR)
    for path in (urdf, mesh):
        path.parent.mkdir(parents=True, exist_ok=True)
    urdf.write_text(urdf_text())
    mesh.write_bytes(sphere_stl())
    return [urdf, mesh]


def package_file(uri: str) -> Path | None:
    """The shipped file a ``package://`` URI names, if it is the robot's URDF or mesh (None
    otherwise: nothing else is served)."""
    return {URDF_URI: URDF_PATH, OLD_URDF_URI: URDF_PATH, MESH_URI: MESH_PATH}.get(uri)
