"""Fin servo: trapezoidal profile-position moves and encoder quantisation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ucat_console.robot.servo import encoder_reading, servo_step
from ucat_console.robot.units import DriveUnits

DT = 0.001
ACC = 64.0


def _run(theta: float, omega: float, target: float, vel: float, max_rate: float = 10.0, t_max: float = 2.0):
    th, om = [theta], [omega]
    for _ in range(int(t_max / DT)):
        a, w, _ = servo_step(th[-1], om[-1], target, vel, ACC, max_rate, DT)
        th.append(a)
        om.append(w)
    return np.array(th), np.array(om)


def _arrival(th: np.ndarray, om: np.ndarray, target: float) -> float:
    done = np.nonzero((th == target) & (om == 0.0))[0]
    return done[0] * DT


def test_trapezoid_time_and_peak_rate() -> None:
    # 1.0 rad at 4 rad/s, 64 rad/s2: ramps of 4/64 s and 0.125 rad each, cruise 0.75 rad / 4
    th, om = _run(0.0, 0.0, 1.0, 4.0)
    assert _arrival(th, om, 1.0) == pytest.approx(0.25 + 4.0 / 64.0, abs=2 * DT)
    assert om.max() == pytest.approx(4.0)
    assert th.max() <= 1.0 + 1e-12  # no overshoot
    assert np.all(np.abs(np.diff(om)) <= ACC * DT + 1e-12)  # acceleration limit


def test_triangle_profile_when_cruise_rate_is_never_reached() -> None:
    # 0.2 rad at 8 rad/s: peak sqrt(64 * 0.2) = 3.578 rad/s, duration 2 sqrt(0.2 / 64) = 0.1118 s
    th, om = _run(0.0, 0.0, -0.2, 8.0)
    assert _arrival(th, om, -0.2) == pytest.approx(2 * math.sqrt(0.2 / 64.0), abs=2 * DT)
    assert -om.min() == pytest.approx(math.sqrt(64.0 * 0.2), abs=ACC * DT)
    assert th.min() >= -0.2 - 1e-12


def test_profile_velocity_is_clipped_to_the_maximum_rate() -> None:
    th, om = _run(0.0, 0.0, 3.0, 50.0, max_rate=10.0)
    assert om.max() == pytest.approx(10.0)
    # 3 rad at 10 rad/s: 3/10 + 10/64 s
    assert _arrival(th, om, 3.0) == pytest.approx(0.3 + 10.0 / 64.0, abs=2 * DT)


def test_new_target_behind_the_motion_brakes_then_returns() -> None:
    # moving at +4 rad/s, new target 0.1 rad behind: brake at 64 rad/s2, then come back
    th, om = _run(0.5, 4.0, 0.4, 4.0)
    assert np.all(np.abs(np.diff(om)) <= ACC * DT + 1e-12)
    turn = np.argmax(om <= 0.0)
    assert turn * DT == pytest.approx(4.0 / 64.0, abs=2 * DT)
    assert th.max() == pytest.approx(0.5 + 4.0**2 / (2 * 64.0), abs=1e-3)
    assert th[-1] == 0.4 and om[-1] == 0.0


def test_holds_at_target() -> None:
    a, w, acc = servo_step(0.3, 0.0, 0.3, 2.0, ACC, 10.0, DT)
    assert (a, w, acc) == (0.3, 0.0, 0.0)


def test_encoder_quantisation() -> None:
    cfg = DriveUnits(encoder_lines=500, gear_ratio=35.0)  # 2000 quadcounts per motor turn
    count = 2 * math.pi / (2000 * 35.0)
    rpm_step = 2 * math.pi / 60.0 / 35.0
    for theta, omega in [(0.123456, 1.234567), (-0.7, -3.3), (1e-6, 1e-4)]:
        a, w = encoder_reading(theta, omega, cfg)
        assert abs(a - theta) <= count / 2 + 1e-15
        assert abs(w - omega) <= rpm_step / 2 + 1e-15
        assert round(a / count) == pytest.approx(a / count, abs=1e-6)
        assert round(w / rpm_step) == pytest.approx(w / rpm_step, abs=1e-6)
