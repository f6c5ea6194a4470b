"""A fin drive in profile-position mode, as an EPOS2 runs it, and its encoder: the one model.

The simulated plant (``backend/sim``) steps its fins with :func:`servo_step`, and the EPOS2
emulator (``backend/devices/epos2_emulator.py``) moves its default servo with the same
function, so the emulated drive and the simulated fin cannot move differently.

Each new set-point replaces the running profile at once (the driver's "new set-point,
change set immediately"): from the present angle and rate the servo follows a trapezoidal
velocity profile to the target, cruising at the commanded profile velocity (clipped to the
maximum rate), speeding up at the profile acceleration and slowing down at the profile
deceleration (the acceleration unless given). It starts braking at the last step from which
it can still stop on the target, so it stops there without overshoot; a target behind the
motion is reached by braking, reversing and cruising back.

One step changes the rate by at most ``acceleration * dt`` (``deceleration * dt`` when
slowing down) and moves the angle by the trapezoidal rule (mean of the old and new rate),
which makes the braking distance from a rate that is a multiple of ``deceleration * dt``
exactly ``w^2 / (2 d)``: the discrete profile is the continuous trapezoid sampled at the
steps.

The encoder reports the angle in whole quadcounts of the motor and the rate in whole motor
rpm (the EPOS2's position actual 0x6064 and velocity actual 0x606C), through the drive's
:class:`~ucat_console.robot.units.DriveUnits`.
"""

from __future__ import annotations

import math

from numba import njit

from ucat_console.robot.units import DriveUnits

#: the fin drives' profile acceleration and deceleration at the fin (rad/s2) and their
#: largest rate (rad/s): the defaults of the plant's servos, the EPOS2s' configuration and
#: the controller's timing of a stroke
FIN_ACCELERATION = 64.0
FIN_MAX_RATE = 10.0


@njit(cache=True)
def servo_step(
    theta: float,
    omega: float,
    target: float,
    profile_velocity: float,
    acceleration: float,
    max_rate: float,
    dt: float,
    deceleration: float = 0.0,
) -> tuple[float, float, float]:
    """One step of the profile: (theta, omega) -> (theta', omega', mean acceleration).

    ``deceleration`` <= 0 means the same as ``acceleration``.
    """
    dec = acceleration if deceleration <= 0.0 else deceleration
    v_cruise = min(abs(profile_velocity), max_rate)
    dv_acc = acceleration * dt
    dv_dec = dec * dt
    e = target - theta
    if abs(e) <= 0.5 * dv_dec * dt and abs(omega) <= dv_dec:
        return target, 0.0, -omega / dt
    s = 1.0 if e > 0.0 else -1.0
    # remaining distance after this step if the rate were w' (trapezoidal rule):
    # e - (omega + w') dt / 2 >= w'^2 / (2 d)  ->  largest w' that can still stop on target
    rem = s * e - 0.5 * s * omega * dt
    if rem <= 0.0:
        v_stop = 0.0
    else:
        v_stop = 0.5 * (-dv_dec + math.sqrt(dv_dec * dv_dec + 8.0 * dec * rem))
    v_des = s * min(v_cruise, v_stop)
    dv = v_des - omega
    # speeding up is limited by the acceleration, slowing down by the deceleration
    if dv > 0.0:
        lim = dv_acc if omega >= 0.0 else dv_dec
        if dv > lim:
            dv = lim
    elif dv < 0.0:
        lim = dv_acc if omega <= 0.0 else dv_dec
        if dv < -lim:
            dv = -lim
    omega_new = omega + dv
    theta_new = theta + 0.5 * (omega + omega_new) * dt
    return theta_new, omega_new, dv / dt


def quantise(theta: float, omega: float, counts_per_rad: float, rate_step: float) -> tuple[float, float]:
    """(angle, rate) rounded to whole encoder counts and whole rate steps."""
    return round(theta * counts_per_rad) / counts_per_rad, round(omega / rate_step) * rate_step


def encoder_reading(theta: float, omega: float, units: DriveUnits) -> tuple[float, float]:
    """(angle, rate) as the EPOS2 reports them: whole quadcounts and whole motor rpm."""
    return quantise(theta, omega, units.quadcounts_per_rad, units.rate_quantum)
