"""3-D view geometry: the fins' mount frames match the plant's fin planes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ucat_console.backend.sim.params import PlantConfig
from ucat_console.robot.geometry import fin_plane_axes
from ucat_console.ui.scene import fin_mount, turn_about_z


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
    pos, q = fin_mount(cfg.geometry, fin, cfg.vehicle.hull_size[1])
    xm, ym = (np.array(v) for v in fin_plane_axes(cfg.fins, fin))
    for theta in (0.0, 0.7, -1.2):
        # chord = mount rotation applied to the blade's x axis turned by theta
        chord = rotate(q, rotate(turn_about_z(theta), np.array([1.0, 0.0, 0.0])))
        np.testing.assert_allclose(chord, math.cos(theta) * xm + math.sin(theta) * ym, atol=1e-12)
    # the blade sits outside the hull, on the fin's side
    half_width = cfg.vehicle.hull_size[1] / 2
    assert abs(pos[1]) > half_width
    assert math.copysign(1.0, pos[1]) == (1.0 if fin in (0, 1) else -1.0)  # 0, 1: starboard
    assert math.copysign(1.0, pos[0]) == (1.0 if fin in (0, 3) else -1.0)  # 0, 3: front
