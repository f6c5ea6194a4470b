"""The robot as a URDF: the hull, the four fins and their joints, for Foxglove's URDF layer,
ROS tools and any URDF loader.

Links are named as the transform frames of the session files and the live Foxglove server
(``backend/sessions/foxglove.py``), so a URDF loaded beside a recording lines up with its
transforms::

    base_link_frd   root: the vehicle, FRD (x forward, y starboard, z down); the hull, an
                    ellipsoid of the hull's length, width and height (``hull.stl``, a unit
                    sphere scaled per axis), and its red nose cap
    base_link       fixed joint: the vehicle in REP 103's FLU axes (half a turn about x)
    fin<i>          continuous joint ``fin<i>_joint`` at the fin's mount
                    (``geometry.fin_mount``), turning about its z axis; the blade as drawn
                    by the console (``BLADE_LENGTH_FACTOR`` x L_f along x, ``BLADE_SPAN``
                    along z)

Joint limits are the servo model's (``robot.servo``): the fin turns freely (a continuous
joint: the model has no end stop) at up to ``FIN_MAX_RATE`` rad/s. The model has no torque
limit, so ``effort`` (which URDF requires) is written as 0, meaning "not modelled".

The shipped files (``ucat_console/robot/urdf/ucat.urdf`` and ``hull.stl``, package data) are
made by :func:`write` from the default geometry; a test checks that they are what this
module makes now. Meshes are referenced as ``package://ucat_console/robot/urdf/...``: a tool
resolves them with the folder that holds ``ucat_console`` on its package path (ROS's
``ROS_PACKAGE_PATH``, Foxglove's "ROS package path" setting), and the live Foxglove server
serves them itself.
"""

from __future__ import annotations

import math
import struct
from pathlib import Path

from ucat_console.robot.fins import N_FINS
from ucat_console.robot.geometry import (
    BLADE_LENGTH_FACTOR,
    BLADE_SPAN,
    BLADE_THICKNESS,
    Geometry,
    fin_mount,
    nose_cap,
)
from ucat_console.robot.look import FIN_COLOURS, HULL_COLOUR, NOSE_COLOUR
from ucat_console.robot.rotations import euler_from_quaternion
from ucat_console.robot.servo import FIN_MAX_RATE

PACKAGE = "ucat_console"
URDF_DIR = Path(__file__).with_name("urdf")
URDF_PATH = URDF_DIR / "ucat.urdf"
MESH_PATH = URDF_DIR / "hull.stl"
#: the files as package URIs (``package://<package>/<path in the package>``)
URDF_URI = f"package://{PACKAGE}/robot/urdf/{URDF_PATH.name}"
MESH_URI = f"package://{PACKAGE}/robot/urdf/{MESH_PATH.name}"
ROOT_LINK = "base_link_frd"
FLU_LINK = "base_link"
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


# ------------------------------------------------------------------ the URDF
def _f(x: float) -> str:
    return f"{x:.12g}" if abs(x) > 1e-12 else "0"  # (no -0 or rounding dust)


def _v(values: tuple[float, ...] | list[float]) -> str:
    return " ".join(_f(float(x)) for x in values)


def _rgba(rgb: tuple[int, int, int]) -> str:
    return _v([c / 255 for c in rgb] + [1.0])


def urdf_text(geometry: Geometry | None = None) -> str:
    """The URDF of a robot of ``geometry`` (default: the U-CAT's)."""
    g = geometry or Geometry()
    half = tuple(0.5 * float(s) for s in g.hull_size)
    nose, nose_semi_axes = nose_cap(g.hull_size)
    blade = BLADE_LENGTH_FACTOR * g.fin_length
    lines = [
        '<?xml version="1.0"?>',
        "<!-- The U-CAT, made by ucat_console.robot.urdf (urdf_text) from its default geometry;",
        "     links are named as the transform frames of the session files. -->",
        '<robot name="ucat">',
        f'  <material name="hull"><color rgba="{_rgba(HULL_COLOUR)}"/></material>',
        f'  <material name="nose"><color rgba="{_rgba(NOSE_COLOUR)}"/></material>',
        *(f'  <material name="fin{i}"><color rgba="{_rgba(c)}"/></material>' for i, c in enumerate(FIN_COLOURS)),
        f'  <link name="{ROOT_LINK}">',
        '    <visual name="hull">',
        f'      <geometry><mesh filename="{MESH_URI}" scale="{_v(half)}"/></geometry>',
        '      <material name="hull"/>',
        "    </visual>",
        '    <visual name="nose">',
        f'      <origin xyz="{_v(nose)}" rpy="0 0 0"/>',
        f'      <geometry><mesh filename="{MESH_URI}" scale="{_v(nose_semi_axes)}"/></geometry>',
        '      <material name="nose"/>',
        "    </visual>",
        "  </link>",
        f'  <link name="{FLU_LINK}"/>',
        f'  <joint name="{FLU_LINK}_joint" type="fixed">',
        f'    <parent link="{ROOT_LINK}"/>',
        f'    <child link="{FLU_LINK}"/>',
        f'    <origin xyz="0 0 0" rpy="{_v((math.pi, 0.0, 0.0))}"/>',
        "  </joint>",
    ]
    for i in range(N_FINS):
        position, q = fin_mount(g, i)
        rpy = euler_from_quaternion(q)
        lines += [
            f'  <link name="{fin_link(i)}">',
            "    <visual>",
            f'      <origin xyz="{_v((blade / 2, 0.0, 0.0))}" rpy="0 0 0"/>',
            f'      <geometry><box size="{_v((blade, BLADE_THICKNESS, BLADE_SPAN))}"/></geometry>',
            f'      <material name="fin{i}"/>',
            "    </visual>",
            "  </link>",
            f'  <joint name="{fin_link(i)}_joint" type="continuous">',
            f'    <parent link="{ROOT_LINK}"/>',
            f'    <child link="{fin_link(i)}"/>',
            f'    <origin xyz="{_v(position)}" rpy="{_v(rpy)}"/>',
            '    <axis xyz="0 0 1"/>',
            f'    <limit effort="0" velocity="{_f(FIN_MAX_RATE)}"/>',
            "  </joint>",
        ]
    lines.append("</robot>")
    return "\n".join(lines) + "\n"


def write(directory: Path = URDF_DIR) -> list[Path]:
    """Write ``ucat.urdf`` and ``hull.stl`` of the default geometry into ``directory``."""
    directory.mkdir(parents=True, exist_ok=True)
    urdf, mesh = directory / URDF_PATH.name, directory / MESH_PATH.name
    urdf.write_text(urdf_text())
    mesh.write_bytes(sphere_stl())
    return [urdf, mesh]


def package_file(uri: str) -> Path | None:
    """The shipped file a ``package://`` URI names, if it is one of the robot's (None
    otherwise: nothing else is served)."""
    return {URDF_URI: URDF_PATH, MESH_URI: MESH_PATH}.get(uri)
