"""A stroke's timing on the fin drive, and the force a fin can deliver."""

from __future__ import annotations

import math

import pytest

from ucat_console.control.params import MpcConfig
from ucat_console.control.stroke_timing import deliverable_force, mean_rate_limit, profile_velocity
from ucat_console.robot.servo import servo_step

ACC, VMAX = 64.0, 10.0


def stroke_time(d: float, v: float, dt: float = 1e-4) -> float:
    """How long the drive model (robot.servo) takes for a stroke of d from rest at profile
    velocity v."""
    theta, omega, t = 0.0, 0.0, 0.0
    while True:
        theta, omega, _ = servo_step(theta, omega, d, v, ACC, VMAX, dt)
        t += dt
        if theta == d and omega == 0.0:
            return t
        assert t < 60.0


def test_the_mean_rate_limit_is_the_triangle_or_the_trapezoid_at_the_top_rate():
    assert mean_rate_limit(1.0, ACC, VMAX) == pytest.approx(4.0)  # sqrt(64) / 2
    assert mean_rate_limit(-1.0, ACC, VMAX) == pytest.approx(4.0)
    # 3 rad: the triangle would peak at sqrt(192) = 13.9 > 10: cruise at 10, 3 / (0.3 + 0.15625)
    assert mean_rate_limit(3.0, ACC, VMAX) == pytest.approx(3.0 / (3.0 / 10.0 + 10.0 / 64.0))
    assert mean_rate_limit(0.0, ACC, VMAX) == 0.0


@pytest.mark.parametrize("d, w", [(1.0, 2.0), (0.6, 1.5), (1.2, 4.0), (-0.8, 3.0), (0.2, 0.5)])
def test_the_profile_velocity_makes_the_stroke_take_its_planned_time(d, w):
    v = profile_velocity(d, w, ACC, VMAX)
    assert v >= w  # the profile runs faster than the mean to make up for its ramps
    assert stroke_time(d, v) == pytest.approx(abs(d) / w, abs=2e-3)
    # sending the mean rate itself makes the stroke late by the ramps, w / a
    assert stroke_time(d, w) == pytest.approx(abs(d) / w + w / ACC, abs=2e-3)


def test_a_stroke_faster_than_the_drive_gets_its_fastest():
    v = profile_velocity(1.0, 6.0, ACC, VMAX)
    assert v == pytest.approx(8.0)  # the triangle's peak, sqrt(64 * 1)
    assert stroke_time(1.0, v) == pytest.approx(1.0 / 4.0, abs=2e-3)


def test_the_deliverable_force_by_hand():
    cfg = MpcConfig()
    # the largest stroke, 1.2 rad, at its fastest mean rate sqrt(64 * 1.2) / 2 = 4.382 rad/s:
    # q |C| w^2 cos(0.6) with q = 0.5 * 1000 * 0.02 * 0.01 = 0.1, |C| = hypot(0.25, 0.7)
    w = math.sqrt(64.0 * 1.2) / 2.0
    by_hand = 0.1 * math.hypot(0.25, 0.7) * w * w * math.cos(0.6)
    assert deliverable_force(cfg, ACC, VMAX) == pytest.approx(by_hand, rel=1e-9)
    assert by_hand == pytest.approx(1.177, abs=1e-3)
    # a drive twice as quick lets the fin make twice the force (w^2 = a d / 4)
    assert deliverable_force(cfg, 2 * ACC, 20.0) == pytest.approx(2 * by_hand, rel=1e-9)
