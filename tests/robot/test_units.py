"""Fin angle/rate <-> EPOS2 quadcounts/rpm: hand-computed values and round trips."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from ucat_console.robot import units
from ucat_console.robot.units import DriveUnits


def test_quadcounts_are_four_per_line():
    assert units.quadcounts_per_turn(500) == 2000
    assert units.quadcounts_per_turn(512) == 2048


def test_half_fin_turn_without_gear_is_half_the_quadcounts():
    # 500 lines -> 2000 qc per motor turn; gear 1: pi rad at the fin is half a turn
    assert units.rad_to_quadcounts(math.pi, 500, 1.0) == pytest.approx(1000.0)
    assert DriveUnits(encoder_lines=500, gear_ratio=1.0).to_quadcounts(math.pi) == 1000


def test_gear_multiplies_quadcounts_per_fin_radian():
    # 512 lines, gear 10: one fin turn = 10 motor turns = 20480 qc
    u = DriveUnits(encoder_lines=512, gear_ratio=10.0)
    assert u.to_quadcounts(2.0 * math.pi) == 20480
    assert u.to_rad(20480) == pytest.approx(2.0 * math.pi)
    # 1 rad = 20480 / (2 pi) = 3259.493 qc -> 3259
    assert u.to_quadcounts(1.0) == 3259
    assert u.resolution_rad == pytest.approx(2.0 * math.pi / 20480)


def test_fin_rate_to_motor_rpm():
    # one fin turn per second = 60 rpm at the fin; gear 5 -> 300 rpm at the motor
    assert units.rad_s_to_rpm(2.0 * math.pi, 1.0) == pytest.approx(60.0)
    assert units.rad_s_to_rpm(2.0 * math.pi, 5.0) == pytest.approx(300.0)
    assert units.rpm_to_rad_s(300.0, 5.0) == pytest.approx(2.0 * math.pi)
    # 64 rad/s2 at the fin with gear 4: 64 * 4 * 60 / (2 pi) = 2444.62 rpm/s
    u = DriveUnits(encoder_lines=500, gear_ratio=4.0)
    assert u.to_rpm(64.0) == pytest.approx(2444.619, abs=1e-3)


@given(
    qc=st.integers(min_value=-(2**31), max_value=2**31 - 1),
    lines=st.integers(min_value=1, max_value=100_000),
    gear=st.floats(min_value=0.01, max_value=1000.0),
)
def test_quadcounts_round_trip_exactly(qc, lines, gear):
    u = DriveUnits(encoder_lines=lines, gear_ratio=gear)
    assert u.to_quadcounts(u.to_rad(qc)) == qc


@given(
    angle=st.floats(min_value=-100.0, max_value=100.0),
    lines=st.integers(min_value=1, max_value=100_000),
    gear=st.floats(min_value=0.01, max_value=1000.0),
)
def test_angle_round_trip_within_half_a_quadcount(angle, lines, gear):
    u = DriveUnits(encoder_lines=lines, gear_ratio=gear)
    back = u.to_rad(u.to_quadcounts(angle))
    assert abs(back - angle) <= 0.5 * u.resolution_rad * (1 + 1e-9)


@given(
    rate=st.floats(min_value=-1000.0, max_value=1000.0),
    gear=st.floats(min_value=0.01, max_value=1000.0),
)
def test_rate_round_trip(rate, gear):
    u = DriveUnits(gear_ratio=gear)
    assert u.to_rad_s(u.to_rpm(rate)) == pytest.approx(rate, rel=1e-12, abs=1e-12)


def test_bad_units_name_the_key():
    with pytest.raises(ValueError, match="gear_ratio"):
        DriveUnits(gear_ratio=0.0)
    with pytest.raises(ValueError, match="encoder_lines"):
        DriveUnits(encoder_lines=0)
