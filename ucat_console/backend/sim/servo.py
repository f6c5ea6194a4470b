"""Fin servo in profile-position mode, as an EPOS2 runs it, and its encoder.

Each new set-point replaces the running profile at once (the driver's "new set-point,
change set immediately"): from the present angle and rate the servo follows a trapezoidal
velocity profile to the target, cruising at the commanded profile velocity (clipped to the
maximum rate) and accelerating and braking at the profile acceleration. It starts braking
at the last step from which it can still stop on the target, so it stops there without
overshoot; a target behind the motion is reached by braking, reversing and cruising back.

One step of :func:`servo_step` changes the rate by at most ``acceleration * dt`` and moves
the angle by the trapezoidal rule (mean of the old and new rate), which makes the braking
distance from a rate that is a multiple of ``acceleration * dt`` exactly ``w^2 / (2 a)``:
the discrete profile is the continuous trapezoid sampled at the steps.

The encoder reports the angle in quadcounts of the motor (four per encoder line and motor
turn, ``gear_ratio`` motor turns per fin turn; conversions from ``devices.units``) and the rate in whole motor rpm, as the
EPOS2's position actual (0x6064) and velocity actual (0x606C).
"""

from __future__ import annotations

import math

from numba import njit

from ucat_console.backend.devices.units import quadcounts_per_rad, rpm_to_rad_s
from ucat_console.backend.sim.params import ServoConfig


@njit(cache=True)
def servo_step(
    theta: float,
    omega: float,
    target: float,
    profile_velocity: float,
    acceleration: float,
    max_rate: float,
    dt: float,
) -> tuple[float, float, float]:
    """One step of the profile: (theta, omega) -> (theta', omega', mean acceleration)."""
    v_cruise = min(abs(profile_velocity), max_rate)
    dv_max = acceleration * dt
    e = target - theta
    if abs(e) <= 0.5 * dv_max * dt and abs(omega) <= dv_max:
        return target, 0.0, -omega / dt
    s = 1.0 if e > 0.0 else -1.0
    # remaining distance after this step if the rate were w' (trapezoidal rule):
    # e - (omega + w') dt / 2 >= w'^2 / (2 a)  ->  largest w' that can still stop on target
    rem = s * e - 0.5 * s * omega * dt
    if rem <= 0.0:
        v_stop = 0.0
    else:
        v_stop = 0.5 * (-dv_max + math.sqrt(dv_max * dv_max + 8.0 * acceleration * rem))
    v_des = s * min(v_cruise, v_stop)
    dv = v_des - omega
    if dv > dv_max:
        dv = dv_max
    elif dv < -dv_max:
        dv = -dv_max
    omega_new = omega + dv
    theta_new = theta + 0.5 * (omega + omega_new) * dt
    return theta_new, omega_new, dv / dt


def counts_per_fin_radian(cfg: ServoConfig) -> float:
    """Encoder quadcounts per radian of fin angle."""
    return quadcounts_per_rad(cfg.encoder_lines, cfg.gear_ratio)


def rate_quantum(cfg: ServoConfig) -> float:
    """Fin rate (rad/s) of one motor rpm, the resolution of the reported velocity."""
    return rpm_to_rad_s(1.0, cfg.gear_ratio)


def quantise(theta: float, omega: float, counts_per_rad: float, rate_step: float) -> tuple[float, float]:
    """(angle, rate) rounded to whole encoder counts and whole rate steps."""
    return round(theta * counts_per_rad) / counts_per_rad, round(omega / rate_step) * rate_step


def encoder_reading(theta: float, omega: float, cfg: ServoConfig) -> tuple[float, float]:
    """(angle, rate) as the EPOS2 reports them: whole quadcounts and whole motor rpm."""
    return quantise(theta, omega, counts_per_fin_radian(cfg), rate_quantum(cfg))

