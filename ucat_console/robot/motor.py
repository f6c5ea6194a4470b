"""The fin drive from the fin's shaft to the battery: gearhead, DC motor, bridge, the drive itself.

A fin's shaft needs torque ``tau`` (N m) at rate ``w`` (rad/s) and acceleration ``a``
(rad/s2). Through the gearhead (ratio ``N`` motor turns per fin turn, efficiency ``eta_g``)
the motor turns at ``w_m = N w`` and gives

    tau_m = tau / (N eta_g)        while it drives the fin (tau w >= 0),
    tau_m = tau eta_g / N          while the fin drives it back (the gearhead's losses help),
    tau_m += J_r N a               its rotor's inertia,
    tau_m += k_t I_0 sign(w_m)     its friction (the no-load current),

so its current is ``I = tau_m / k_t`` and its terminal voltage ``V_t = R I + k_t w_m``
(SI units: the back-EMF constant equals the torque constant). The motor takes ``V_t I``:
the shaft's power plus the copper loss ``R I^2`` plus the friction and the gearhead's loss.
The bridge passes it at efficiency ``eta_b`` and returns nothing to the battery (the drives
do not regenerate: a negative ``V_t I`` costs the battery nothing and gives nothing back),
and the drive draws ``P_q`` of its own:

    P_battery = max(0, V_t I) / eta_b + P_q.

The same formula gives a real drive's battery power from the current it measures and the
encoder's rate (:func:`battery_power`), so the simulated robot and the real one report
electrical power the same way. The values are the fin drive's configuration
(``[devices.epos2.motor]`` on the robot, ``[plant.motor]`` in the simulator). The U-CAT's
sources name "Maxon motors on EPOS2 controllers" and nothing more, so which motor is an
assumption: the defaults are the catalogue values of a maxon EC 45 flat, 50 W, 24 V (torque
constant 36 mNm/A, terminal resistance 0.942 ohm, no-load current 238 mA, rotor inertia 135
g cm^2; maxon catalogue, "EC 45 flat 43.5 mm, brushless, 50 watt"), a motor of the size the
fins' torque and speed call for, with the project's 35:1 gearhead at 0.7 (maxon's three-stage
planetary gearheads are rated 0.7-0.75), a bridge at 0.95 and 0.5 W for the drive itself
(both guesses; docs/power.md). This module imports nothing of the package.
"""

from __future__ import annotations

from dataclasses import dataclass

from numba.extending import register_jitable

from ucat_console.robot.units import GEAR_RATIO, bounded, check_bounded

#: the default motor's nominal current, its largest continuous one (A; maxon catalogue, EC 45
#: flat 50 W 24 V: 2.52 A at its nominal torque of 91.1 mN m): what the URDF's fin joints
#: give as their effort limit, through :meth:`FinMotor.shaft_torque`
NOMINAL_CURRENT = 2.52


@dataclass(frozen=True)
class FinMotor:
    """One fin drive's motor, gearhead and bridge (the same on all four fins).

    A configuration block; its checks are here because this package imports nothing of the
    configuration machinery. Every default is an assumption (module docstring)."""

    torque_constant: float = bounded(
        0.036, 0.0, 10.0, lo_open=True, unit="N m/A",
        doc="motor torque constant k_t; the back-EMF constant in V s/rad is the same number")
    resistance: float = bounded(0.942, 0.0, 1000.0, lo_open=True, unit="ohm", doc="terminal resistance R")
    no_load_current: float = bounded(
        0.238, 0.0, 100.0, unit="A", doc="no-load current I_0: the motor's friction and iron losses, k_t I_0")
    rotor_inertia: float = bounded(1.35e-5, 0.0, 1.0, unit="kg m2", doc="rotor inertia J_r")
    gear_ratio: float = bounded(GEAR_RATIO, 0.0, 10_000.0, lo_open=True, doc="motor turns per fin turn N")
    gear_efficiency: float = bounded(0.7, 0.0, 1.0, lo_open=True, doc="gearhead efficiency eta_g")
    bridge_efficiency: float = bounded(0.95, 0.0, 1.0, lo_open=True, doc="bridge efficiency eta_b")
    quiescent_power: float = bounded(0.5, 0.0, 1000.0, unit="W", doc="the drive's own consumption, P_q")
    supply_voltage: float = bounded(
        24.0, 0.0, 100.0, lo_open=True, unit="V", doc="the supply (battery) voltage at the drives")

    def __post_init__(self) -> None:
        check_bounded(self)

    def constants(self) -> tuple[float, float, float, float, float, float, float, float]:
        """The values the compiled functions take, in this order (not the supply voltage)."""
        return (self.torque_constant, self.resistance, self.no_load_current, self.rotor_inertia,
                self.gear_ratio, self.gear_efficiency, self.bridge_efficiency, self.quiescent_power)

    def shaft_torque(self, current: float) -> float:
        """The torque (N m) a motor current gives the fin's shaft at a steady rate: the
        inverse of :func:`motor_current` driving the fin with no acceleration,
        ``(k_t I - k_t I_0) N eta_g``."""
        return (self.torque_constant * (current - self.no_load_current) * self.gear_ratio
                * self.gear_efficiency)

    def battery_power(self, current: float, rate: float) -> float:
        """:func:`battery_power` with this drive's values (W)."""
        return battery_power(current, rate, self.torque_constant, self.resistance, self.gear_ratio,
                             self.bridge_efficiency, self.quiescent_power)


@register_jitable
def motor_current(tau: float, w: float, a: float, k_t: float, i_0: float, j_r: float, n: float,
                  eta_g: float) -> float:
    """The motor current (A) for shaft torque ``tau`` at fin rate ``w`` and acceleration ``a``
    (module docstring)."""
    if tau * w >= 0.0:
        tau_m = tau / (n * eta_g)
    else:
        tau_m = tau * eta_g / n
    tau_m += j_r * n * a
    w_m = n * w
    if w_m > 0.0:
        tau_m += k_t * i_0
    elif w_m < 0.0:
        tau_m -= k_t * i_0
    return tau_m / k_t


@register_jitable
def battery_power(current: float, w: float, k_t: float, r: float, n: float, eta_b: float, p_q: float) -> float:
    """The battery's power (W) for a drive whose motor carries ``current`` (A) at fin rate ``w``
    (rad/s): ``max(0, V_t I) / eta_b + P_q`` with ``V_t = R I + k_t N w``."""
    v_t = r * current + k_t * n * w
    return max(0.0, v_t * current) / eta_b + p_q
