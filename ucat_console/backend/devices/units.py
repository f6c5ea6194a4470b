"""Fin angle and rate <-> EPOS2 units: the one place for these conversions.

The EPOS2 counts position in quadcounts of the motor encoder (four per encoder line and
turn) and speed in rpm of the motor shaft; the controller thinks in radians and rad/s at
the fin, which turns ``gear_ratio`` times slower than the motor. Every conversion between
the two goes through the functions below (the driver, the emulator and the tests alike).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ucat_console.typedconf import Config, param

_TWO_PI = 2.0 * math.pi
_SECONDS_PER_MINUTE = 60.0


def quadcounts_per_turn(encoder_lines: int) -> int:
    """Quadcounts per motor turn: four edges per encoder line."""
    return 4 * encoder_lines


def quadcounts_per_rad(encoder_lines: int, gear_ratio: float) -> float:
    """Quadcounts per radian at the fin."""
    return quadcounts_per_turn(encoder_lines) * gear_ratio / _TWO_PI


def rad_to_quadcounts(angle_rad: float, encoder_lines: int, gear_ratio: float) -> float:
    """Fin angle (rad) to motor position (quadcounts, not rounded)."""
    return angle_rad * quadcounts_per_rad(encoder_lines, gear_ratio)


def quadcounts_to_rad(quadcounts: float, encoder_lines: int, gear_ratio: float) -> float:
    """Motor position (quadcounts) to fin angle (rad)."""
    return quadcounts / quadcounts_per_rad(encoder_lines, gear_ratio)


def rad_s_to_rpm(rate_rad_s: float, gear_ratio: float) -> float:
    """Fin rate (rad/s) to motor speed (rpm, not rounded); also rad/s2 -> rpm/s."""
    return rate_rad_s * gear_ratio * _SECONDS_PER_MINUTE / _TWO_PI


def rpm_to_rad_s(rpm: float, gear_ratio: float) -> float:
    """Motor speed (rpm) to fin rate (rad/s); also rpm/s -> rad/s2."""
    return rpm * _TWO_PI / (gear_ratio * _SECONDS_PER_MINUTE)


@dataclass(frozen=True)
class DriveUnits(Config):
    """Encoder and gearhead of one fin drive (the same on all four fins)."""

    encoder_lines: int = param(
        512, lo=1, hi=1_000_000, unit="lines/turn",
        doc="encoder lines per motor turn (quadcounts = 4 x lines); set to the installed encoder",
    )
    gear_ratio: float = param(
        1.0, lo=0.0, hi=10_000.0, lo_open=True,
        doc="motor turns per fin turn; set to the installed gearhead",
    )

    @property
    def quadcounts_per_rad(self) -> float:
        return quadcounts_per_rad(self.encoder_lines, self.gear_ratio)

    @property
    def resolution_rad(self) -> float:
        """One quadcount as a fin angle (the encoder quantisation step)."""
        return 1.0 / self.quadcounts_per_rad

    def to_quadcounts(self, angle_rad: float) -> int:
        """Fin angle to the nearest whole quadcount (what 0x607A takes)."""
        return int(round(rad_to_quadcounts(angle_rad, self.encoder_lines, self.gear_ratio)))

    def to_rad(self, quadcounts: float) -> float:
        return quadcounts_to_rad(quadcounts, self.encoder_lines, self.gear_ratio)

    def to_rpm(self, rate_rad_s: float) -> float:
        return rad_s_to_rpm(rate_rad_s, self.gear_ratio)

    def to_rad_s(self, rpm: float) -> float:
        return rpm_to_rad_s(rpm, self.gear_ratio)
