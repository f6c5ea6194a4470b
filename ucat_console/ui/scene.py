"""The 3-D view: the U-CAT hull, its four fins (measured, and the commanded angle ghosted),
the body pose from the estimator, a trail of the path, the water surface and a depth label.

Frames. The telemetry is in NED (x north, y east, z down) and the body frame is FRD; the
scene node ``/ned`` turns NED into viser's z-up world (half a turn about x), so every
node below it takes telemetry values unchanged. The view follows the vehicle
horizontally (``/ned`` is shifted so the vehicle stays above the origin) and the water
surface stays at world z = 0, so depth reads directly.

Fins. Each fin works in its own plane (``robot.geometry.fin_plane_axes``): the fin's
chord points along ``cos(theta) x_m + sin(theta) y_m``, turning about the plane's normal.
Node ``fin<i>`` is the fin's mount with axes (x_m, y_m, normal); its children ``blade``
(measured angle) and ``ghost`` (commanded angle, translucent) turn about the mount's z axis.
Fins are numbered in the robot's order, as in the telemetry.
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from ucat_console.robot.fins import N_FINS, fin_signs
from ucat_console.robot.geometry import Geometry, fin_plane_axes
from ucat_console.robot.rotations import quaternion_from_matrix
from ucat_console.telemetry.messages import BodyState, FinState

HULL_COLOUR = (245, 196, 0)
NOSE_COLOUR = (200, 60, 40)
FIN_COLOUR = (40, 40, 40)
GHOST_COLOUR = (30, 144, 255)
WATER_COLOUR = (64, 140, 200)
TRAIL_COLOUR = (220, 60, 60)
#: NED -> viser world (z up): half a turn about x
NED_WXYZ = (0.0, 1.0, 0.0, 0.0)
SURFACE_SIZE = 10.0  # m, side of the square of surface lines around the vehicle
SURFACE_STEP = 0.5  # m between surface lines
FIN_SPAN = 0.08  # m, along the fin's axis (for the view)
FIN_THICKNESS = 0.006  # m


Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]


def fin_mount(g: Geometry, fin: int, hull_width: float) -> tuple[Vec3, Quat]:
    """Body-frame position and orientation (wxyz) of a fin's mount frame (x_m, y_m, normal)."""
    s_lat, s_long, _ = fin_signs(fin)
    xm, ym = fin_plane_axes(g, fin)
    xm_a, ym_a = np.array(xm), np.array(ym)
    n = np.cross(xm_a, ym_a)
    outward = 1.0 if n[1] * s_lat > 0 else -1.0
    # the blade spans along the axis, outside the hull
    base = np.array([s_long * g.arm_pitch, s_lat * max(g.arm_roll, hull_width / 2), 0.0])
    pos = base + outward * n * (FIN_SPAN / 2 + 0.01)
    p = (float(pos[0]), float(pos[1]), float(pos[2]))
    return p, quaternion_from_matrix(np.column_stack([xm_a, ym_a, n]))


def surface_lines(size: float, step: float) -> np.ndarray:
    """Segments (N, 2, 3) of a square grid of side ``size`` at z = 0, centred on the origin."""
    h = size / 2
    ticks = np.arange(-h, h + 1e-9, step)
    segs = [((x, -h, 0.0), (x, h, 0.0)) for x in ticks] + [((-h, y, 0.0), (h, y, 0.0)) for y in ticks]
    return np.array(segs, dtype=float)


def turn_about_z(theta: float) -> tuple[float, float, float, float]:
    return (math.cos(theta / 2), 0.0, 0.0, math.sin(theta / 2))


class RobotScene:
    """The scene nodes and their updates (server-wide)."""

    def __init__(self, scene: Any, geometry: Geometry, *, trail_points: int, trail_spacing: float,
                 shadows: bool = False, environment_map: bool = False) -> None:
        self.scene = scene
        size = geometry.hull_size
        self.fin_length = 1.5 * geometry.fin_length
        self.trail_spacing = float(trail_spacing)
        self._trail = np.zeros((int(trail_points), 3))
        self._trail_n = 0
        self._trail_next = 0
        self._trail_dirty = False
        self.updates = 0

        scene.set_up_direction("+z")
        scene.configure_default_lights(cast_shadow=shadows)
        if not environment_map:
            scene.configure_environment_map(None)
            # daylight from above, water-blue from below
            scene.add_light_hemisphere("/light", sky_color=(255, 255, 255), ground_color=(90, 130, 170),
                                       intensity=1.6)
        # the surface as lines: a filled translucent plane over the whole view costs too much
        # where the browser renders in software
        self.surface = scene.add_line_segments("/surface", surface_lines(SURFACE_SIZE, SURFACE_STEP),
                                               WATER_COLOUR, thickness=1.5, thickness_units="screen")
        self.ned = scene.add_frame("/ned", show_axes=False, wxyz=NED_WXYZ)
        self.body = scene.add_frame("/ned/ucat", show_axes=False)
        self.hull = scene.add_box("/ned/ucat/hull", color=HULL_COLOUR, dimensions=tuple(size))
        scene.add_box("/ned/ucat/nose", color=NOSE_COLOUR, dimensions=(0.03, size[1] * 0.6, size[2] * 0.6),
                      position=(size[0] / 2 + 0.015, 0.0, 0.0))
        self.blades = []
        self.ghosts = []
        L = self.fin_length
        for i in range(N_FINS):
            pos, q = fin_mount(geometry, i, size[1])
            scene.add_frame(f"/ned/ucat/fin{i}", show_axes=False, position=pos, wxyz=q)
            blade = scene.add_frame(f"/ned/ucat/fin{i}/blade", show_axes=False)
            scene.add_box(f"/ned/ucat/fin{i}/blade/plate", color=FIN_COLOUR,
                          dimensions=(L, FIN_THICKNESS, FIN_SPAN), position=(L / 2, 0.0, 0.0))
            ghost = scene.add_frame(f"/ned/ucat/fin{i}/ghost", show_axes=False)
            scene.add_box(f"/ned/ucat/fin{i}/ghost/plate", color=GHOST_COLOUR,
                          dimensions=(L, FIN_THICKNESS, FIN_SPAN), position=(L / 2, 0.0, 0.0), opacity=0.35,
                          cast_shadow=False)
            self.blades.append(blade)
            self.ghosts.append(ghost)
        self.label = scene.add_label("/ned/ucat/depth", "depth -", position=(0.0, 0.0, -0.35),
                                     anchor="bottom-center")
        self.trail = scene.add_line_segments("/ned/trail", np.zeros((1, 2, 3)), TRAIL_COLOUR,
                                             thickness=2.0, thickness_units="screen")

    # ------------------------------------------------------------------ updates
    def update_pose(self, body: BodyState | None, fins: Sequence[FinState | None]) -> None:
        """Pose, fins and view offset (call inside ``server.atomic()``)."""
        if body is not None:
            x, y, _ = body.position
            self.ned.position = (-x, y, 0.0)
            self.body.position = body.position
            self.body.wxyz = body.orientation
            self._add_trail_point(body.position)
        for i, f in enumerate(fins):
            if f is None:
                continue
            self.blades[i].wxyz = turn_about_z(f.angle)
            self.ghosts[i].wxyz = turn_about_z(f.angle_cmd)
        self.updates += 1

    def update_label(self, body: BodyState | None) -> None:
        if body is not None:
            self.label.text = f"depth {body.depth:.2f} m"

    def _add_trail_point(self, p: tuple[float, float, float]) -> None:
        cap = self._trail.shape[0]
        if self._trail_n:
            last = self._trail[(self._trail_next - 1) % cap]
            if math.dist(last, p) < self.trail_spacing:
                return
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
