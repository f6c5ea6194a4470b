"""What an executed cycle delivered by the fin model, against what was asked."""

from __future__ import annotations

import math

import pytest

from ucat_console.control.fin_cycle import CycleForce, direction_error, executed_force, planned_duration
from ucat_console.control.params import MpcConfig

CFG = MpcConfig()
Q = 0.5 * 1000.0 * 0.02 * 0.01  # 0.5 rho A_f r_c^2


def test_a_symmetric_pair_delivers_the_baselines_force():
    # strokes c - A -> c + A -> c - A at 2 rad/s: mean force cos(A) q w^2 R(c) (-C_L, -C_D)
    c, a, w = -1.2278, 0.3, 2.0
    t1 = 2 * a / w
    fx, fy = executed_force([c - a, c + a, c - a], [0.0, t1, 2 * t1], CFG)
    k = math.cos(a) * Q * w * w
    want = (k * (-0.25 * math.cos(c) + 0.7 * math.sin(c)), k * (-0.25 * math.sin(c) - 0.7 * math.cos(c)))
    assert (fx, fy) == pytest.approx(want, abs=1e-12)
    # c = -1.2278 is the forward-thrust centre of the paper's coefficients: (-|f|, 0)
    assert fy == pytest.approx(0.0, abs=1e-4) and fx < 0.0


def test_strokes_weigh_by_their_duration():
    # one stroke of 0.4 rad in 0.2 s, then the fin rests 0.2 s (a stroke of 0)
    fx, fy = executed_force([0.0, 0.4, 0.4], [0.0, 0.2, 0.4], CFG)
    alone = executed_force([0.0, 0.4], [0.0, 0.2], CFG)
    assert (fx, fy) == pytest.approx((alone[0] / 2, alone[1] / 2))


def test_direction_and_magnitude_errors():
    assert direction_error((-1.0, 0.0), (-2.0, 0.0)) == pytest.approx(0.0)
    assert direction_error((-1.0, 0.0), (0.0, 0.5)) == pytest.approx(math.pi / 2)
    assert direction_error((-1.0, 0.0), (1.0, 0.0)) == pytest.approx(math.pi)
    assert math.isnan(direction_error((0.0, 0.0), (1.0, 0.0)))
    c = CycleForce(target=(0.3, 0.4), delivered=(0.0, 0.2), duration=1.1, planned_duration=1.0)
    assert c.magnitude_error == pytest.approx(-0.3)
    assert planned_duration((0.5, -0.5, 2.0, 1.0)) == pytest.approx(0.75)


def test_bad_input_is_refused():
    with pytest.raises(ValueError, match="angles, times"):
        executed_force([0.0], [0.0], CFG)
