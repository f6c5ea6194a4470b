"""The fin drives' electrical input as one message, the same on every robot.

Each drive reports its motor current and its supply voltage (the EPOS2's 0x2027 and 0x2200,
or the simulated drive's); with the fin's rate from its encoder, the battery power it draws
is ``robot.motor.battery_power`` of its drive (gearhead, motor, bridge, its own
consumption). :func:`electrical_power` makes the :class:`ElectricalPower` message the
console publishes on ``power/electrical`` from them, for the simulated robot and the real
one alike, so both report the battery's view the same way (docs/power.md).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from ucat_console.robot.motor import FinMotor
from ucat_console.telemetry.messages import ElectricalPower


def electrical_power(t: float, current: Sequence[float], voltage: Sequence[float], rates: Sequence[float],
                     motor: FinMotor) -> ElectricalPower:
    """The message at time ``t`` from each drive's motor current (A; NaN: it did not answer),
    supply voltage (V) and fin rate (rad/s)."""
    per_fin = tuple(motor.battery_power(i, w) if math.isfinite(i) and math.isfinite(w) else math.nan
                    for i, w in zip(current, rates))
    return ElectricalPower(t, tuple(current), tuple(voltage), per_fin, math.fsum(per_fin))  # type: ignore[arg-type]
