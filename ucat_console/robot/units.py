"""Physical constants and unit conversions, each defined once.

* Gravity and water density: :data:`GRAVITY` (standard gravity, used for weight, pressure
  and the IMU's g unit alike), :data:`RHO_FRESH`, :data:`RHO_SALT`.
* Pressure transducer (Gems 3101P, 4-20 mA): gauge pressure
  ``p = p_min + (I - 4 mA) / 16 mA * span``; depth ``d = (p - p_surface) / (rho g)``; a
  saturating transmitter's loop current stays within :data:`LOOP_MIN_MA` ..
  :data:`LOOP_MAX_MA` (NAMUR NE 43).
* Fin drives (EPOS2): position in quadcounts of the motor encoder (four per encoder line
  and motor turn), speed in rpm of the motor shaft; the controller thinks in radians and
  rad/s at the fin, which turns ``gear_ratio`` times slower than the motor.
  :class:`DriveUnits` is the encoder and gearhead of the fin drives; the driver, the EPOS2
  emulator and the plant's encoder model all convert through it.

``DriveUnits`` defaults to the U-CAT's drives as this project models them: a 512-line
encoder and a 35:1 gearhead. The gear ratio is not in the sources (plant.md assumes it);
it is the default because the plant has always modelled it, both shipped configuration
files set it, and a direct drive (1:1, the drivers' former default) is not what the U-CAT
has. A rig whose drives differ sets ``[devices.epos2.units]``.
"""

from __future__ import annotations

import math
from dataclasses import Field, dataclass, field, fields
from typing import Any

from numba.extending import register_jitable

#: standard gravity (m/s2)
GRAVITY = 9.80665
#: fresh and salt water density (kg/m3)
RHO_FRESH = 997.0
RHO_SALT = 1029.0
#: the water density of the paper's fin model (kg/m3, Table I)
RHO_TABLE_I = 1000.0

#: 4-20 mA loop: current at zero gauge pressure and from 4 to 20 mA
LOOP_ZERO_MA = 4.0
LOOP_SPAN_MA = 16.0
#: loop current limits of a saturating transmitter (NAMUR NE 43): below, a broken loop;
#: above, a shorted one
LOOP_MIN_MA = 3.8
LOOP_MAX_MA = 20.5

#: the U-CAT fin drives' encoder lines per motor turn and motor turns per fin turn
ENCODER_LINES = 512
GEAR_RATIO = 35.0

_TWO_PI = 2.0 * math.pi
_SECONDS_PER_MINUTE = 60.0


# ---------------------------------------------------------------- pressure and depth


@register_jitable
def current_to_pressure(current_ma: float, p_min_pa: float, span_pa: float) -> float:
    """Gauge pressure (Pa) from loop current (mA)."""
    return p_min_pa + (current_ma - LOOP_ZERO_MA) / LOOP_SPAN_MA * span_pa


@register_jitable
def pressure_to_current(pressure_pa: float, p_min_pa: float, span_pa: float) -> float:
    """Loop current (mA) for a gauge pressure (Pa); inverse of :func:`current_to_pressure`."""
    return LOOP_ZERO_MA + (pressure_pa - p_min_pa) / span_pa * LOOP_SPAN_MA


@register_jitable
def pressure_to_depth(pressure_pa: float, surface_pressure_pa: float, rho: float) -> float:
    """Depth (m, positive down) below the zeroed surface."""
    return (pressure_pa - surface_pressure_pa) / (rho * GRAVITY)


@register_jitable
def depth_to_pressure(depth_m: float, surface_pressure_pa: float, rho: float) -> float:
    """Gauge pressure (Pa) at a depth; inverse of :func:`pressure_to_depth`."""
    return surface_pressure_pa + depth_m * rho * GRAVITY


# ---------------------------------------------------------------- fin drives


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


def bounded(default: Any, lo: float, hi: float, *, lo_open: bool = False, unit: str = "",
            doc: str = "") -> Any:
    """A dataclass field with its range, unit and description in the field's metadata,
    under the keys the configuration machinery reads (``typedconf.param``'s): the blocks of
    this package are configuration blocks too (their range shows in the configuration's
    schema and is checked on load), and this package imports nothing of that machinery."""
    return field(default=default, metadata={"lo": lo, "hi": hi, "lo_open": lo_open, "hi_open": False,
                                            "choices": None, "unit": unit, "doc": doc, "secret": False})


def check_bounded(obj: Any) -> None:
    """Check every :func:`bounded` field of a frozen dataclass instance (an ``int`` field
    takes integers only; a ``float`` field takes any number, made a float); ValueError
    naming the field and its range."""
    for f in fields(obj):
        v = getattr(obj, f.name)
        integer = f.type in ("int", int)
        kind_ok = not isinstance(v, bool) and isinstance(v, int if integer else (int, float))
        if not (kind_ok and math.isfinite(v) and _inside(f, v)):
            m = f.metadata
            unit = f" {m['unit']}" if m["unit"] else ""
            what = "an integer in " if integer else ""
            raise ValueError(f"{f.name}: {v!r} is out of range; allowed: {what}{'(' if m['lo_open'] else '['}"
                             f"{m['lo']}, {m['hi']}]{unit}")
        if not integer:
            object.__setattr__(obj, f.name, float(v))


def _inside(f: Field, v: float) -> bool:
    m = f.metadata
    return (m["lo"] < v if m["lo_open"] else m["lo"] <= v) and v <= m["hi"]


@dataclass(frozen=True)
class DriveUnits:
    """Encoder and gearhead of one fin drive (the same on all four fins).

    A configuration block (``[devices.epos2.units]``, ``[plant.servo.units]``): the
    configuration loader reads it like any other block; its two checks are here because
    this package imports nothing of the configuration machinery.
    """

    encoder_lines: int = bounded(
        ENCODER_LINES, 1, 1_000_000, unit="lines/turn",
        doc="encoder lines per motor turn (quadcounts = 4 x lines); set to the installed encoder")
    gear_ratio: float = bounded(
        GEAR_RATIO, 0.0, 10_000.0, lo_open=True, doc="motor turns per fin turn; set to the installed gearhead")

    def __post_init__(self) -> None:
        check_bounded(self)

    @property
    def quadcounts_per_rad(self) -> float:
        return quadcounts_per_rad(self.encoder_lines, self.gear_ratio)

    @property
    def resolution_rad(self) -> float:
        """One quadcount as a fin angle (the encoder quantisation step)."""
        return 1.0 / self.quadcounts_per_rad

    @property
    def rate_quantum(self) -> float:
        """Fin rate (rad/s) of one motor rpm, the resolution of the reported velocity."""
        return rpm_to_rad_s(1.0, self.gear_ratio)

    def to_quadcounts(self, angle_rad: float) -> int:
        """Fin angle to the nearest whole quadcount (what 0x607A takes)."""
        return int(round(rad_to_quadcounts(angle_rad, self.encoder_lines, self.gear_ratio)))

    def to_rad(self, quadcounts: float) -> float:
        return quadcounts_to_rad(quadcounts, self.encoder_lines, self.gear_ratio)

    def to_rpm(self, rate_rad_s: float) -> float:
        return rad_s_to_rpm(rate_rad_s, self.gear_ratio)

    def to_rad_s(self, rpm: float) -> float:
        return rpm_to_rad_s(rpm, self.gear_ratio)
