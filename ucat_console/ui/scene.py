"""The 3-D view: the U-CAT's ellipsoidal hull with a heading arrow, its four fins as fin-shaped
plates at their measured angles (the commanded angle ghosted), the body pose from the
estimator, a trail of the path and a depth label; and, once per view, the pool around it:
a faint water surface at depth 0 and a floor grid.

Frames. The telemetry is in NED (x north, y east, z down) and the body frame is FRD; a
robot's root node (``/ned`` for the live robot, ``/review`` for a page's reviewed one)
turns NED into viser's z-up world (half a turn about x), so every node below it takes
telemetry values unchanged; the water surface is world z = 0, so depth reads directly. A
page that reviews a session hides the live robot for itself (a page-scoped, invisible
``/ned`` shadows the shared one) and sees the reviewed robot in its place.

Fins. Each fin works in its own plane (``robot.geometry.fin_plane_axes``): the fin's
chord points along ``cos(theta) x_m + sin(theta) y_m``, turning about the plane's normal.
A fin's mount (``robot.geometry.fin_mount``) has axes (x_m, y_m, normal); its blade is the
mount turned about the mount's z axis by the fin's angle (:func:`blade_wxyzs`). The four
blades (measured angles) are one batched mesh, ``blades``, and the four ghosts (commanded
angles, translucent) another, ``ghosts``: one message moves all four, and the page draws
them in one call each. Instances are in the robot's fin order, as in the telemetry.

The hull is an icosphere scaled to the hull's half-sizes (viser scales nodes per axis); the
fin plate is a small extruded outline built here (:func:`fin_plate_mesh`: a dozen points
do not need a mesh library).
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from ucat_console.robot.fins import N_FINS
from ucat_console.robot.geometry import BLADE_LENGTH_FACTOR, BLADE_SPAN, BLADE_THICKNESS, Geometry, fin_mount
from ucat_console.robot.look import FIN_COLOURS, GHOST_COLOUR, HULL_COLOUR, NOSE_COLOUR
from ucat_console.telemetry.messages import BodyState, FinState
from ucat_console.ui.fast_props import set_pose, set_prop

WATER_COLOUR = (64, 140, 200)
FLOOR_COLOUR = (120, 130, 140)
#: side of the square pool drawn around the origin (m)
POOL_SIZE = 40.0
TRAIL_COLOUR = (220, 60, 60)
HEADING_COLOUR = (220, 60, 40)
#: NED -> viser world (z up): half a turn about x
NED_WXYZ = (0.0, 1.0, 0.0, 0.0)
LIVE_ROOT = "/ned"
REVIEW_ROOT = "/review"


def turn_about_z(theta: float) -> tuple[float, float, float, float]:
    return (math.cos(theta / 2), 0.0, 0.0, math.sin(theta / 2))


def _changed(a: float, b: float) -> bool:
    return a != b and not (math.isnan(a) and math.isnan(b))


def blade_wxyzs(mount_wxyz: Sequence[Sequence[float]], angles: Sequence[float]) -> np.ndarray:
    """The blades' orientations (n, 4) in the body frame: each fin's mount turned by its
    angle about the mount's z axis (an angle that is not a number leaves the blade neutral)."""
    rows = []
    for (w, x, y, z), a in zip(mount_wxyz, angles):
        # the product q * (cos(a/2), 0, 0, sin(a/2)) written out (40 times a second)
        h = 0.5 * a if math.isfinite(a) else 0.0
        c, s = math.cos(h), math.sin(h)
        rows.append((w * c - z * s, x * c + y * s, y * c - x * s, w * s + z * c))
    return np.array(rows, dtype=np.float32).reshape(-1, 4)


def fin_plate_mesh(length: float, span: float, thickness: float) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, faces) of a fin blade: a rounded, tapering outline in the x-z plane (chord
    along +x from the shaft at x = 0, span along z), ``thickness`` thick along y."""
    # half-spans along the chord: full at the shaft, tapering, rounded at the tip
    xs = np.array([0.0, 0.35, 0.7, 0.88, 0.97, 1.0]) * length
    hs = np.array([0.5, 0.48, 0.4, 0.3, 0.18, 0.0]) * span
    outline = [(x, h) for x, h in zip(xs, hs)] + [(x, -h) for x, h in zip(xs[::-1][1:], hs[::-1][1:])]
    n = len(outline)
    y = thickness / 2
    verts = [(x, y, z) for x, z in outline] + [(x, -y, z) for x, z in outline]
    cx = float(np.mean([p[0] for p in outline]))
    verts += [(cx, y, 0.0), (cx, -y, 0.0)]
    top_c, bot_c = 2 * n, 2 * n + 1
    faces = []
    for i in range(n):
        j = (i + 1) % n
        faces.append((top_c, i, j))  # top
        faces.append((bot_c, n + j, n + i))  # bottom
        faces.append((i, n + i, n + j))  # side
        faces.append((i, n + j, j))
    return np.array(verts, dtype=np.float32), np.array(faces, dtype=np.uint32)


def add_pool(scene: Any, *, floor_depth: float, shadows: bool = False, environment_map: bool = False) -> None:
    """The pool around every robot (once per view): lights, a faint water surface at depth
    0 (grid lines, so it never hides the robot) and a floor grid at ``floor_depth``."""
    scene.set_up_direction("+z")
    scene.configure_default_lights(cast_shadow=shadows)
    if not environment_map:
        scene.configure_environment_map(None)
        # daylight from above, water-blue from below
        scene.add_light_hemisphere("/light", sky_color=(255, 255, 255), ground_color=(90, 130, 170),
                                   intensity=1.6)
    # the grids as lines: a grid plane is a shader over every pixel it covers, which a
    # browser drawing in software pays on every frame (half its frame rate, measured)
    scene.add_line_segments("/surface", grid_lines(POOL_SIZE, 2.0, 0.0), WATER_COLOUR, thickness=1.0,
                            thickness_units="screen")
    scene.add_line_segments("/floor", grid_lines(POOL_SIZE, 1.0, -float(floor_depth)), FLOOR_COLOUR,
                            thickness=1.0, thickness_units="screen")


def grid_lines(size: float, step: float, z: float) -> np.ndarray:
    """The segments (n, 2, 3) of a square grid of side ``size`` (m) centred on the origin, a
    line every ``step`` m, at height ``z``."""
    half = 0.5 * size
    ticks = np.arange(-half, half + 1e-9, step)
    along_x = [((-half, y, z), (half, y, z)) for y in ticks]
    along_y = [((x, -half, z), (x, half, z)) for x in ticks]
    return np.array(along_x + along_y, dtype=float)


class RobotScene:
    """One robot's nodes under ``root`` (``/ned`` live, ``/review`` reviewed) and their updates."""

    def __init__(self, scene: Any, geometry: Geometry, *, trail_points: int, trail_spacing: float,
                 root: str = LIVE_ROOT) -> None:
        self.scene = scene
        self.root = root.rstrip("/")
        size = geometry.hull_size
        self.fin_length = BLADE_LENGTH_FACTOR * geometry.fin_length
        self.trail_spacing = float(trail_spacing)
        self._trail = np.zeros((int(trail_points), 3))
        self._trail_n = 0
        self._trail_next = 0
        self._trail_last: tuple[float, float, float] = (0.0, 0.0, 0.0)  # the newest point
        self._trail_dirty = False
        self.updates = 0
        self._shown: list[tuple[float, float]] = [(math.nan, math.nan)] * 4  # (angle, commanded) per fin
        self.position: tuple[float, float, float] | None = None  # the robot's last NED position

        r = self.root
        self.ned = scene.add_frame(r, show_axes=False, wxyz=NED_WXYZ)
        self.body = scene.add_frame(f"{r}/ucat", show_axes=False)
        half = tuple(0.5 * s for s in size)
        self.hull = scene.add_icosphere(f"{r}/ucat/hull", radius=1.0, color=HULL_COLOUR, subdivisions=3,
                                        scale=half)
        # the heading: a red nose cap and an arrow ahead of it, along the body's x axis
        scene.add_icosphere(f"{r}/ucat/nose", radius=1.0, color=NOSE_COLOUR, subdivisions=2,
                            scale=(0.035, half[1] * 0.35, half[2] * 0.35), position=(half[0] - 0.01, 0.0, 0.0))
        scene.add_arrows(f"{r}/ucat/heading", np.array([[[half[0] + 0.02, 0.0, 0.0], [half[0] + 0.25, 0.0, 0.0]]]),
                         HEADING_COLOUR, shaft_radius=0.008, head_radius=0.022, head_length=0.05)
        verts, faces = fin_plate_mesh(self.fin_length, BLADE_SPAN, BLADE_THICKNESS)
        mounts = [fin_mount(geometry, i) for i in range(N_FINS)]
        self.mount_wxyz = [q for _, q in mounts]
        positions = np.array([p for p, _ in mounts], dtype=np.float32)
        neutral = blade_wxyzs(self.mount_wxyz, [0.0] * N_FINS)
        self.blades = scene.add_batched_meshes_simple(
            f"{r}/ucat/blades", verts, faces, batched_wxyzs=neutral, batched_positions=positions,
            batched_colors=np.array(FIN_COLOURS, dtype=np.uint8), lod="off", side="double")
        self.ghosts = scene.add_batched_meshes_simple(
            f"{r}/ucat/ghosts", verts, faces, batched_wxyzs=neutral, batched_positions=positions,
            batched_colors=GHOST_COLOUR, lod="off", opacity=0.35, side="double", cast_shadow=False)
        self._label_text = "depth -"
        self.label = scene.add_label(f"{r}/ucat/depth", self._label_text, position=(0.0, 0.0, -0.35),
                                     anchor="bottom-center")
        self.trail = scene.add_line_segments(f"{r}/trail", np.zeros((1, 2, 3)), TRAIL_COLOUR,
                                             thickness=2.0, thickness_units="screen")

    def world_position(self) -> tuple[float, float, float] | None:
        """The robot's position in viser's world (z up), for a camera to follow."""
        p = self.position
        return None if p is None else (p[0], -p[1], -p[2])

    # ------------------------------------------------------------------ updates
    def update_pose(self, body: BodyState | None, fins: Sequence[FinState | None]) -> None:
        """Pose and fins (call inside ``atomic()``)."""
        if body is not None:
            set_pose(self.body, body.position, body.orientation)
            self.position = body.position
            self._add_trail_point(body.position)
        # only what changed (the commanded angles change a few times a second); set without
        # viser's casts and comparisons (ui.fast_props)
        shown = self._shown
        now = [(f.angle, f.angle_cmd) if f is not None else s for f, s in zip(fins, shown)]
        if any(_changed(a[0], b[0]) for a, b in zip(now, shown)):
            set_prop(self.blades, "batched_wxyzs", blade_wxyzs(self.mount_wxyz, [a for a, _ in now]))
        if any(_changed(a[1], b[1]) for a, b in zip(now, shown)):
            set_prop(self.ghosts, "batched_wxyzs", blade_wxyzs(self.mount_wxyz, [c for _, c in now]))
        self._shown = now
        self.updates += 1

    def update_label(self, body: BodyState | None) -> None:
        if body is not None:
            # a reviewed robot says so, beside its depth: it is a recording, not the robot now
            text = f"{'REVIEW · ' if self.root == REVIEW_ROOT else ''}depth {body.depth:.2f} m"
            if text != self._label_text:  # (viser's assignment costs more than the comparison)
                self.label.text = self._label_text = text

    def _add_trail_point(self, p: tuple[float, float, float]) -> None:
        cap = self._trail.shape[0]
        if self._trail_n and math.dist(self._trail_last, p) < self.trail_spacing:
            return
        self._trail_last = p
        self._trail[self._trail_next] = p
        self._trail_next = (self._trail_next + 1) % cap
        self._trail_n = min(self._trail_n + 1, cap)
        self._trail_dirty = True

    def trail_points(self) -> np.ndarray:
        """The trail's points, oldest first."""
        cap = self._trail.shape[0]
        idx = (self._trail_next - self._trail_n + np.arange(self._trail_n)) % cap
        return self._trail[idx]

    def update_trail(self) -> None:
        if not self._trail_dirty or self._trail_n < 2:
            return
        pts = self.trail_points()
        self.trail.points = np.stack([pts[:-1], pts[1:]], axis=1)
        self._trail_dirty = False

    def remove(self) -> None:
        """Take this robot's nodes out of the scene."""
        self.ned.remove()
