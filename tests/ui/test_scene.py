"""3-D view geometry: the fins' mount frames match the plant's fin planes; the fin plate is a
closed mesh; the hull is drawn from the configured geometry."""

from __future__ import annotations

import math
import types

import numpy as np
import pytest

from ucat_console.backend.sim.params import PlantConfig
from ucat_console.robot.geometry import Geometry, fin_mount, fin_plane_axes
from ucat_console.ui.scene import RobotScene, blade_wxyzs, fin_plate_mesh, turn_about_z


def rotate(q: tuple[float, float, float, float], v: np.ndarray) -> np.ndarray:
    w, x, y, z = q
    r = np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])
    return r @ v


@pytest.mark.parametrize("fin", range(4))
def test_a_fins_chord_at_angle_theta_follows_the_fin_plane(fin: int) -> None:
    cfg = PlantConfig()
    pos, q = fin_mount(cfg.geometry, fin)
    xm, ym = (np.array(v) for v in fin_plane_axes(cfg.fins, fin))
    for theta in (0.0, 0.7, -1.2):
        # chord = mount rotation applied to the blade's x axis turned by theta
        chord = rotate(q, rotate(turn_about_z(theta), np.array([1.0, 0.0, 0.0])))
        np.testing.assert_allclose(chord, math.cos(theta) * xm + math.sin(theta) * ym, atol=1e-12)
        # the batched blades' orientation (float32, as sent) points the same way
        angles = [0.0] * 4
        angles[fin] = theta
        wxyz = blade_wxyzs([fin_mount(cfg.geometry, i)[1] for i in range(4)], angles)[fin]
        np.testing.assert_allclose(rotate(tuple(wxyz), np.array([1.0, 0.0, 0.0])),
                                   math.cos(theta) * xm + math.sin(theta) * ym, atol=1e-6)
    # the blade sits outside the hull, on the fin's side
    half_width = cfg.vehicle.hull_size[1] / 2
    assert abs(pos[1]) > half_width
    assert math.copysign(1.0, pos[1]) == (1.0 if fin in (0, 1) else -1.0)  # 0, 1: starboard
    assert math.copysign(1.0, pos[0]) == (1.0 if fin in (0, 3) else -1.0)  # 0, 3: front


def test_the_fin_plate_is_a_closed_mesh_of_the_blade_size() -> None:
    verts, faces = fin_plate_mesh(0.15, 0.08, 0.006)
    assert verts[:, 0].min() == 0.0 and verts[:, 0].max() == pytest.approx(0.15)
    assert np.ptp(verts[:, 2]) == pytest.approx(0.08) and np.ptp(verts[:, 1]) == pytest.approx(0.006)
    # closed: every edge is shared by exactly two faces
    edges: dict[tuple[int, int], int] = {}
    for f in faces:
        for a, b in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0])):
            key = (min(a, b), max(a, b))
            edges[key] = edges.get(key, 0) + 1
    assert set(edges.values()) == {2}


class SceneCalls:
    """A stand-in for viser's scene API that records what is added (name -> keyword arguments)."""

    def __init__(self) -> None:
        self.added: dict[str, dict] = {}

    def __getattr__(self, method: str):
        def add(name: str, *args, **kwargs):
            self.added[name] = {"method": method, **kwargs}
            return types.SimpleNamespace()

        return add


def test_the_hull_is_an_ellipsoid_of_the_configured_size_with_the_fins_outside_it() -> None:
    geometry = Geometry(hull_size=(0.8, 0.4, 0.2))
    calls = SceneCalls()
    RobotScene(calls, geometry, trail_points=10, trail_spacing=0.05)
    hull = calls.added["/ned/ucat/hull"]
    assert hull["method"] == "add_icosphere" and hull["radius"] == 1.0
    assert hull["scale"] == pytest.approx((0.4, 0.2, 0.1))  # the half-sizes: an ellipsoid
    positions = calls.added["/ned/ucat/blades"]["batched_positions"]
    np.testing.assert_allclose(calls.added["/ned/ucat/ghosts"]["batched_positions"], positions)
    for i in range(4):
        pos, _ = fin_mount(geometry, i)
        np.testing.assert_allclose(positions[i], pos, atol=1e-6)
        # each fin's shaft lies outside the ellipsoid
        assert sum((p / h) ** 2 for p, h in zip(pos, (0.4, 0.2, 0.1))) > 1.0
    nose = calls.added["/ned/ucat/nose"]["position"]
    assert nose[0] == pytest.approx(0.4 - 0.01)  # at the bow of this hull


def test_the_blades_orientations_are_each_mount_turned_by_its_angle() -> None:
    from ucat_console.robot.rotations import quaternion_multiply

    cfg = PlantConfig()
    mounts = [fin_mount(cfg.geometry, i)[1] for i in range(4)]
    rng = np.random.default_rng(7)
    for _ in range(50):
        angles = list(rng.uniform(-3.5, 3.5, size=4))
        angles[rng.integers(4)] = rng.choice([math.nan, math.inf, -math.inf, angles[0]])
        got = blade_wxyzs(mounts, angles)
        assert got.dtype == np.float32 and got.shape == (4, 4)
        for q, a, row in zip(mounts, angles, got):
            want = quaternion_multiply(q, turn_about_z(a if math.isfinite(a) else 0.0))
            np.testing.assert_allclose(row, want, atol=1e-6)


def test_the_trail_keeps_points_a_spacing_apart_and_the_newest_when_full() -> None:
    scene = RobotScene(SceneCalls(), Geometry(), trail_points=4, trail_spacing=0.05)
    for x in (0.0, 0.01, 0.04, 0.06, 0.1, 0.12, 0.2, 0.3, 0.31, 0.4):
        scene._add_trail_point((x, 0.0, 1.0))
    # 0.01 and 0.04 are within 0.05 of 0.0, 0.1 of 0.06, 0.12 kept (0.06 from 0.06), 0.31 of 0.3
    np.testing.assert_allclose(scene.trail_points()[:, 0], [0.12, 0.2, 0.3, 0.4])
    np.testing.assert_allclose(scene.trail_points()[:, 2], 1.0)
