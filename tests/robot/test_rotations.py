"""Quaternions, rotation matrices and Euler angles: round trips and known rotations."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from ucat_console.robot import rotations as rot

angles = st.floats(-math.pi + 1e-3, math.pi - 1e-3)
pitches = st.floats(-math.pi / 2 + 1e-3, math.pi / 2 - 1e-3)


def test_euler_quaternion_round_trip() -> None:
    for rpy in [(0.1, -0.2, 0.3), (-1.0, 0.5, -2.5), (0.0, 0.0, math.pi - 1e-6)]:
        back = rot.euler_from_quaternion(rot.quaternion_from_euler(*rpy))
        assert back == pytest.approx(rpy, abs=1e-9)


def test_rotation_matrix_of_a_yaw_quarter_turn() -> None:
    R = rot.rotation_matrix(rot.quaternion_from_euler(0.0, 0.0, math.pi / 2))
    # sensor x (forward) points east after a +90 deg yaw in NED
    assert R @ np.array([1.0, 0.0, 0.0]) == pytest.approx([0.0, 1.0, 0.0], abs=1e-12)


@given(angles, pitches, angles)
def test_euler_matrix_quaternion_round_trips(roll: float, pitch: float, yaw: float) -> None:
    q = rot.quaternion_normalize(rot.quaternion_from_euler(roll, pitch, yaw))
    assert rot.euler_from_quaternion(q) == pytest.approx((roll, pitch, yaw), abs=1e-9)
    r = rot.rotation_matrix(q)
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
    back = rot.quaternion_normalize(rot.quaternion_from_matrix(r))
    assert back == pytest.approx(q, abs=1e-9)


@given(angles, pitches, angles, angles, pitches, angles)
def test_quaternion_product_is_the_matrix_product(r1, p1, y1, r2, p2, y2) -> None:
    a = rot.quaternion_from_euler(r1, p1, y1)
    b = rot.quaternion_from_euler(r2, p2, y2)
    np.testing.assert_allclose(
        rot.rotation_matrix(rot.quaternion_multiply(a, b)),
        rot.rotation_matrix(a) @ rot.rotation_matrix(b), atol=1e-12,
    )


def test_rotation_vector_turns_about_its_axis() -> None:
    q = rot.quaternion_from_rotation_vector((0.0, 0.0, math.pi / 2))
    assert rot.euler_from_quaternion(q) == pytest.approx((0.0, 0.0, math.pi / 2), abs=1e-12)
    assert rot.skew((1.0, 2.0, 3.0)) @ np.array([4.0, 5.0, 6.0]) == pytest.approx(np.cross([1, 2, 3], [4, 5, 6]))


def test_normalising_picks_one_sign_and_refuses_zero() -> None:
    assert rot.quaternion_normalize((-2.0, 0.0, 0.0, 0.0)) == (1.0, -0.0, -0.0, -0.0)
    with pytest.raises(ValueError, match="normalised"):
        rot.quaternion_normalize((0.0, 0.0, 0.0, 0.0))
