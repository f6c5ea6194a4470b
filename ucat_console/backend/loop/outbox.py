"""The closed loop's telemetry out: the core's rows as messages, and the loop's own messages.

The compiled core (``control.loop_core``) keeps the rows of the telemetry it makes on
every sample (state, power, body command, readings) in its out table; :meth:`Outbox.publish_rows`
turns them into messages, those a subscriber takes, in the order the core kept them, and
publishes them at once. The rest is what the loop's Python publishes: events (mode
switches, tuning, late plans, overruns, stroke timeouts, stalls), each plan and each
executed cycle, each stroke's Strouhal number, the Status and the Setpoints.
:meth:`Outbox.wanted_flags` tells the core which of its rows anybody takes.
"""

from __future__ import annotations

import math
from dataclasses import fields, replace
from typing import Any, Callable

import numpy as np

from ucat_console.control import loop_core as lc
from ucat_console.control.allocation import BodySetpoints, cut_names
from ucat_console.control.cost import stroke_strouhal
from ucat_console.control.fin_cycle import CycleForce
from ucat_console.control.params import MpcConfig
from ucat_console.robot import reading_rows as rr
from ucat_console.robot.fins import N_FINS
from ucat_console.robot.readings import DepthReading, DvlVelocity, ImuReading
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.messages import (
    BodyAllocation,
    BodyCommand,
    BodyState,
    BodyTracking,
    FinCycle,
    FinPlan,
    FinState,
    FinStrouhal,
    Power,
    Setpoints,
    Status,
)
from ucat_console.telemetry.stream import TelemetryStream

FIN_STATE = tuple(ch.fin_state(pf) for pf in range(N_FINS))
FIN_CYCLE = tuple(ch.fin_cycle(pf) for pf in range(N_FINS))
#: the telemetry a flag of the core asks for
_WANTED = ((lc.F_BODY_COMMAND, (ch.BODY_COMMAND, ch.BODY_ALLOCATION, ch.BODY_TRACKING)),
           (lc.F_STATE, (ch.BODY_STATE, *FIN_STATE)), (lc.F_POWER, (ch.POWER,)), (lc.F_IMU, (ch.IMU,)),
           (lc.F_DEPTH, (ch.DEPTH,)), (lc.F_DVL, (ch.DVL,)))
#: the channel of each kind of reading the loop publishes
_READING_CHANNEL = {ImuReading: ch.IMU, DepthReading: ch.DEPTH, DvlVelocity: ch.DVL}

Add = Callable[[tuple[str, Any]], None]


class Outbox:
    """What the loop publishes on ``stream``."""

    def __init__(self, stream: TelemetryStream) -> None:
        self.stream = stream
        self._wanted_key: frozenset[str] | None = None
        self._wanted_flags = 0

    # ------------------------------------------------------------------ the core's rows
    def wanted_flags(self) -> int:
        """The core's flags (``lc.F_STATE`` ...) of the rows some subscriber takes."""
        wanted = self.stream.wanted
        if wanted is not self._wanted_key:
            self._wanted_key = wanted
            self._wanted_flags = sum(f for f, chans in _WANTED if any(c in wanted for c in chans))
        return self._wanted_flags

    def publish_rows(self, s: np.ndarray, out: np.ndarray, tracking: bool) -> None:
        """The core's telemetry rows (``out``, its count in ``s``) as messages, in the order
        it kept them, published at once (``publish_many``); ``tracking``: whether the fins
        follow the body loops (else a tracking message carries no errors)."""
        n = int(s[lc.C_OUT_N])
        s[lc.C_OUT_N] = 0.0
        items: list[tuple[str, Any]] = []
        add = items.append
        for v in out[:n].tolist():
            kind = v[lc.O_KIND]
            if kind == lc.O_STATE:
                self._state_messages(v, add)
            elif kind == lc.O_POWER:
                add((ch.POWER, _power_message(v)))
            elif kind == lc.O_BODY_COMMAND:
                self._body_messages(v, add, tracking)
            else:
                r = rr.reading_of(v)
                add((_READING_CHANNEL[type(r)], r))
        self.stream.publish_many(items)

    def _state_messages(self, v: list[float], add: Add) -> None:
        """The body state and the fin states of a state row, those a subscriber takes."""
        wants = self.stream.wants
        t, b = v[lc.O_T], lc.O_V
        if wants(ch.BODY_STATE):
            add((ch.BODY_STATE, BodyState(
                t=t, position=(v[b], v[b + 1], v[b + 2]), orientation=(v[b + 3], v[b + 4], v[b + 5], v[b + 6]),
                velocity=(v[b + 7], v[b + 8], v[b + 9]), rates=(v[b + 10], v[b + 11], v[b + 12]), depth=v[b + 13],
            )))
        f = lc.O_STATE_FINS
        for pf, channel in enumerate(FIN_STATE):
            if wants(channel):
                a = v[f + pf]
                add((channel, FinState(t, pf, 0.0 if a != a else a, v[f + N_FINS + pf],
                                       v[f + 2 * N_FINS + pf], v[f + 3 * N_FINS + pf])))

    def _body_messages(self, v: list[float], add: Add, tracking: bool) -> None:
        """The body command, the allocation and the tracking of a body-command row, those a
        subscriber takes."""
        t, b = v[lc.O_T], lc.O_V
        wants = self.stream.wants
        if wants(ch.BODY_COMMAND):
            add((ch.BODY_COMMAND, BodyCommand(t, v[b], v[b + 1], v[b + 2])))
        if wants(ch.BODY_ALLOCATION):
            add((ch.BODY_ALLOCATION, BodyAllocation(t, v[b + 3], v[b + 4], v[b + 5], v[b + 6], v[b + 7], v[b + 8],
                                                    cut_names(int(v[b + 9])))))
        if wants(ch.BODY_TRACKING):
            refs, errors = v[b + 11:b + 15], v[b + 15:b + 18]
            if not tracking:  # the fins ignore the loops: no tracking to judge
                errors = [math.nan] * 3
            add((ch.BODY_TRACKING, BodyTracking(t, v[b + 10] != 0.0, *refs, *errors)))

    # ------------------------------------------------------------------ the loop's own
    def event(self, t: float, code: str, message: str, level: str, data: dict) -> None:
        self.stream.publish(ch.EVENTS, Event(t=t, source="loop", code=code, message=message, level=level, data=data))

    def tuning_event(self, t: float, block: str, old: Any, new: Any, who: str) -> None:
        """The one event of a tuning change: what changed in ``block``, and who changed it."""
        changes = {}
        for f in fields(new):
            a, b = getattr(old, f.name), getattr(new, f.name)
            if a != b:
                changes[f.name] = [_jsonable(a), _jsonable(b)]
        text = ", ".join(f"{block}.{k} {v[0]} -> {v[1]}" for k, v in changes.items()) or f"{block}: no change"
        self.event(t, "tuning", f"{who + ': ' if who else ''}{text}", "info",
                   {"block": block, "changes": changes, **({"who": who} if who else {})})

    def fin_plan(self, fin: int, outcome: FinPlan, t: float, mode: str, late: bool) -> None:
        """The plan ``outcome`` handed to robot fin ``fin`` at ``t``."""
        channel = ch.fin_plan(fin)
        if self.stream.wants(channel):
            self.stream.publish(channel, replace(outcome, t=t, fin=fin, mode=mode, late=late))

    def fin_cycle(self, t: float, fin: int, mode: str, c: CycleForce) -> None:
        self.stream.publish(FIN_CYCLE[fin], FinCycle(
            t=t, fin=fin, mode=mode, target=c.target, delivered=c.delivered, direction_error=c.direction_error,
            magnitude_error=c.magnitude_error, duration=c.duration, planned_duration=c.planned_duration))

    def wants_cycle(self, fin: int) -> bool:
        return self.stream.wants(FIN_CYCLE[fin])

    def stroke(self, t: float, fin: int, stroke: float, rate: float, v_body: float, m: MpcConfig) -> None:
        """Robot fin ``fin`` starts a stroke of ``stroke`` rad at ``rate`` rad/s: its Strouhal number."""
        if not self.stream.wants(ch.fin_strouhal(fin)):
            return
        self.stream.publish(ch.fin_strouhal(fin), FinStrouhal(
            t, fin, stroke_strouhal(rate, v_body, m), m.st_low, m.st_high, m.st_opt, v_body, stroke, rate,
        ))

    def setpoints(self, t: float, sp: BodySetpoints) -> None:
        self.stream.publish(ch.SETPOINTS, Setpoints(t, sp.velocity, sp.depth, sp.yaw_rate))

    def status(self, t: float, status: Status, sp: BodySetpoints) -> None:
        self.stream.publish(ch.STATUS, status)
        self.setpoints(t, sp)


def _power_message(v: list[float]) -> Power:
    per = [0.0 if x != x else x for x in v[lc.O_V:lc.O_V + N_FINS]]
    energy = 0.0
    mean = 0.0
    for pf in range(N_FINS):
        energy += v[lc.O_POWER_ENERGY + pf]
        m = v[lc.O_POWER_MEAN + pf]
        mean += m if m == m else 0.0
    d = v[lc.O_POWER_DISTANCE]
    return Power(
        t=v[lc.O_T], per_fin=(per[0], per[1], per[2], per[3]), total=sum(per), mean_total=mean,
        energy=energy, distance=d, energy_per_metre=energy / d if d > 0.0 else math.nan,
    )


def _jsonable(v: Any) -> Any:
    if isinstance(v, tuple):
        return [_jsonable(x) for x in v]
    if isinstance(v, (int, float, str, bool)) or v is None:
        return v
    return str(v)
