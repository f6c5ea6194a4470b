"""State estimation: the attitude EKF (static tilt from gravity, yaw from a constant rate, gyro
bias) and dead reckoning."""

from __future__ import annotations

import math

import pytest

from ucat_console.control import estimation as att
from ucat_console.robot import rotations as rot
from ucat_console.robot.readings import ImuReading
from ucat_console.robot.units import GRAVITY as G0

ROLL, PITCH = 0.3, -0.2


def specific_force(roll: float, pitch: float) -> tuple[float, float, float]:
    """Sensor-frame specific force at rest, z down, in m/s^2: R^T (0, 0, -g0) for R = Rz Ry Rx.

    The third row of Rz(yaw) Ry(pitch) Rx(roll) is (-sin p, sin r cos p, cos r cos p).
    """
    return (G0 * math.sin(pitch), -G0 * math.sin(roll) * math.cos(pitch), -G0 * math.cos(roll) * math.cos(pitch))


def test_tilt_from_accel_inverts_the_gravity_model() -> None:
    assert att.tilt_from_accel(specific_force(ROLL, PITCH)) == pytest.approx((ROLL, PITCH), abs=1e-12)
    assert att.tilt_from_accel((0.0, 0.0, -G0)) == pytest.approx((0.0, 0.0), abs=1e-12)


def test_converges_to_a_static_tilt_from_level_start() -> None:
    cfg = att.AttitudeConfig()
    state = att.initial_state(0.0, cfg)  # level: 0.36 rad away from the truth
    f = specific_force(ROLL, PITCH)
    for k in range(1, 501):  # 5 s at 100 Hz
        state = att.step(state, k * 0.01, f, (0.0, 0.0, 0.0), cfg)
    roll, pitch, _ = state.euler
    assert roll == pytest.approx(ROLL, abs=2e-3)
    assert pitch == pytest.approx(PITCH, abs=2e-3)
    assert max(state.attitude_std[:2]) < 0.05  # the filter is also confident about it


def test_tracks_a_constant_yaw_rate_while_tilted() -> None:
    # turning at r about the world vertical: body rate = r * R^T e_z, constant for a fixed
    # tilt; the specific force does not depend on yaw, so it is constant too
    r = 0.2
    down = (-math.sin(PITCH), math.sin(ROLL) * math.cos(PITCH), math.cos(ROLL) * math.cos(PITCH))
    gyro = tuple(r * d for d in down)
    f = specific_force(ROLL, PITCH)
    state = att.initial_state(0.0, accel=f)
    for k in range(1, 1001):  # 10 s
        state = att.step(state, k * 0.01, f, gyro)
        if k % 250 == 0:
            roll, pitch, yaw = state.euler
            expected = math.remainder(r * k * 0.01, 2 * math.pi)
            assert math.remainder(yaw - expected, 2 * math.pi) == pytest.approx(0.0, abs=1e-3)
            assert (roll, pitch) == pytest.approx((ROLL, PITCH), abs=1e-3)


def test_estimates_a_gyro_bias_at_rest() -> None:
    bias = (0.01, -0.02, 0.0)
    state = att.initial_state(0.0, accel=(0.0, 0.0, -G0))
    for k in range(1, 3001):
        state = att.step(state, k * 0.01, (0.0, 0.0, -G0), bias)
    assert state.bias[:2] == pytest.approx(bias[:2], abs=1e-3)
    roll, pitch, _ = state.euler
    assert abs(roll) < 1e-3 and abs(pitch) < 1e-3


def test_acceleration_beyond_the_gate_is_not_used_as_gravity() -> None:
    state = att.initial_state(0.0, accel=(0.0, 0.0, -G0))
    after = att.correct(state, (0.8 * G0, 0.0, -G0))  # |a| = 1.281 g0, beyond the 0.15 g0 gate
    assert after.q == state.q


def test_time_is_an_argument_and_steps_back_are_ignored() -> None:
    state = att.initial_state(1.0)
    assert att.predict(state, 0.5, (1.0, 0.0, 0.0)) is state
    gap = att.predict(state, 2.0, (1.0, 0.0, 0.0))  # 1 s gap > max_dt: not integrated
    assert gap.q == state.q and gap.t == 2.0
    assert gap.attitude_std[0] > state.attitude_std[0]


def test_non_finite_inputs_are_refused() -> None:
    state = att.initial_state(0.0)
    with pytest.raises(ValueError, match="gyro"):
        att.predict(state, 0.01, (math.nan, 0.0, 0.0))
    with pytest.raises(ValueError, match="accel"):
        att.correct(state, (0.0, math.inf, -G0))


def test_estimator_object_initialises_from_the_first_reading() -> None:
    est = att.AttitudeEstimator()
    f = specific_force(ROLL, PITCH)
    first = est.update(ImuReading(t=0.0, accel=f, gyro=(0.0, 0.0, 0.0)))
    assert first.euler[:2] == pytest.approx((ROLL, PITCH), abs=1e-9)
    second = est.update(ImuReading(t=0.01, accel=f, gyro=(0.0, 0.0, 0.0)))
    assert second.t == 0.01


def test_dead_reckoning_rotates_the_body_velocity_into_ned() -> None:
    # heading east (yaw +90 deg): 0.5 m/s forward and 0.2 m/s to starboard for 0.8 s
    q = rot.quaternion_from_euler(0.0, 0.0, math.pi / 2)
    x, y = att.dead_reckon((1.0, 2.0), q, (0.5, 0.2, 0.0), 0.8)
    assert (x, y) == pytest.approx((1.0 - 0.16, 2.0 + 0.4), abs=1e-12)
    # a gap longer than the longest integrated one counts as that long; none backwards
    x, y = att.dead_reckon((0.0, 0.0), (1.0, 0.0, 0.0, 0.0), (1.0, 0.0, 0.0), 10.0)
    assert x == pytest.approx(att.MAX_DEAD_RECKONING_GAP)
    assert att.dead_reckon((0.0, 0.0), (1.0, 0.0, 0.0, 0.0), (1.0, 0.0, 0.0), -1.0) == (0.0, 0.0)
