"""A synthetic run whose figures are known by hand: constant fin powers and speed, strokes
alternating in and out of the corridor, tracking errors of known mean magnitude."""

from __future__ import annotations

from typing import Any

from ucat_console.telemetry import channels as C
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.messages import (
    BodyState,
    BodyTracking,
    ElectricalPower,
    FinCycle,
    FinPlan,
    FinState,
    FinStrouhal,
    Power,
)

PER_FIN = (0.5, 1.0, 1.5, 1.0)  # W: 4 W in all
BATTERY = (2.0, 3.0, 4.0, 3.0)  # W: 12 W in all (the drives' electrical input, when recorded)
MASS = 22.0


def run_items(duration: float = 20.0, scale: float = 1.0, speed: float = 0.2,
              events: tuple[Event, ...] = (), cycle_scale: Any = None,
              battery_from: float | None = None) -> list[tuple[str, Any]]:
    """Messages of a run from t=0: power sampled at 10 Hz (fin i: ``scale * PER_FIN[i]``,
    or ``cycle_scale(k)`` times it in cycle k), distance ``speed * t``; with ``battery_from``
    the drives' electrical input from that time at 10 Hz too (fin i: ``BATTERY[i]`` times
    the same scale), none without; tracking errors
    +0.01/-0.03 m/s in turn (MAE 0.02), depth 0.05 m, heading -0.1 rad; each fin a stroke
    every 0.5 s, St 0.30 and 0.40 in turn (corridor 0.25..0.35, optimum 0.30); fin 0 ends a
    cycle every second; plans with opening |0.5 - 0.4| = 0.1 rad; fin angles 0.01 t rad."""
    items: list[tuple[str, Any]] = []
    n = int(round(duration * 10))
    energy = 0.0
    for k in range(n):
        t = k / 10.0
        s = scale * (cycle_scale(int(t)) if cycle_scale else 1.0)
        per = tuple(s * p for p in PER_FIN)
        items.append((C.POWER, Power(t, per, sum(per), sum(per), energy, speed * t, float("nan"))))
        energy += 0.1 * sum(per)
        if battery_from is not None and t >= battery_from - 1e-9:
            bat = tuple(s * b for b in BATTERY)
            items.append((C.POWER_ELECTRICAL, ElectricalPower(t, (1.0,) * 4, (24.0,) * 4, bat, sum(bat))))
        items.append((C.BODY_TRACKING, BodyTracking(t, True, speed, 1.0, 0.0, 0.0,
                                                    0.01 if k % 2 == 0 else -0.03, 0.05, -0.1)))
        items.append((C.BODY_STATE, BodyState(t, (speed * t, 0.0, 1.0), (1.0, 0.0, 0.0, 0.0),
                                              (speed, 0.0, 0.0), (0.0, 0.0, 0.0), 1.0)))
        for fin in range(4):
            items.append((C.fin_state(fin), FinState(t, fin, 0.01 * t, 0.01, 0.0, 0.0)))
            if k % 5 == 0:
                st = 0.30 if k % 10 == 0 else 0.40
                items.append((C.fin_strouhal(fin), FinStrouhal(t, fin, st, 0.25, 0.35, 0.30, speed,
                                                               0.5 if k % 10 == 0 else -0.4, 3.0)))
            if k % 10 == 0:
                items.append((C.fin_plan(fin), FinPlan(
                    t, fin, "mpc", (-0.1, 0.0), speed, 0.0, (0.5, -0.4, 3.0, 3.0), (0.5, -0.4, 3.0, 3.0),
                    (0.5, 3.0, 0.1, 3.0), 0.0, 0.0, 0.0, 0.0, 0.0, 0.3, (0.0, 0.0), 0.001, False)))
        if k % 10 == 0 and k > 0:
            items.append((C.fin_cycle(0), FinCycle(t, 0, "mpc", (-0.1, 0.0), (-0.1, 0.0), 0.0, 0.0, 1.0, 1.0)))
    for e in events:
        items.append((C.EVENTS, e))
    items.sort(key=lambda it: it[1].t)
    return items
