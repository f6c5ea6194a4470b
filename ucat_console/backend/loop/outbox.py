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
# the columns of the core's rows (their declared layouts, ``loop_core.*_ROW``)
_BC, _ST, _PW = lc.BODY_COMMAND_ROW, lc.STATE_ROW, lc.POWER_ROW
_BC_FX, _BC_FY, _BC_YAW, _BC_CUT, _BC_DRIVING = (_BC.at(f) for f in ("force_x", "force_y", "yaw_force", "cut", "driving"))
_BC_ASKED, _BC_APPLIED, _BC_REFS, _BC_ERRORS = (_BC.span(f) for f in ("asked", "applied", "references", "errors"))
_S_POS, _S_Q, _S_V, _S_RATES = (_ST.span(f) for f in ("position", "orientation", "velocity", "rates"))
_S_DEPTH, _S_ANGLE, _S_RATE, _S_SET_ANGLE, _S_SET_RATE = (
    _ST.at(f) for f in ("depth", "fin_angle", "fin_rate", "fin_set_angle", "fin_set_rate"))
_P_POWER, _P_ENERGY, _P_MEAN = (_PW.span(f) for f in ("power", "energy", "mean"))
_P_DISTANCE = _PW.at("distance")
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
        t = v[lc.O_T]
        if wants(ch.BODY_STATE):
            add((ch.BODY_STATE, BodyState(
                t=t, position=tuple(v[_S_POS]), orientation=tuple(v[_S_Q]), velocity=tuple(v[_S_V]),
                rates=tuple(v[_S_RATES]), depth=v[_S_DEPTH],
            )))
        for pf, channel in enumerate(FIN_STATE):
            if wants(channel):
                a = v[_S_ANGLE + pf]
                add((channel, FinState(t, pf, 0.0 if a != a else a, v[_S_RATE + pf], v[_S_SET_ANGLE + pf],
                                       v[_S_SET_RATE + pf])))

    def _body_messages(self, v: list[float], add: Add, tracking: bool) -> None:
        """The body command, the allocation and the tracking of a body-command row, those a
        subscriber takes."""
        t = v[lc.O_T]
        wants = self.stream.wants
        if wants(ch.BODY_COMMAND):
            add((ch.BODY_COMMAND, BodyCommand(t, v[_BC_FX], v[_BC_FY], v[_BC_YAW])))
        if wants(ch.BODY_ALLOCATION):
            add((ch.BODY_ALLOCATION, BodyAllocation(t, *v[_BC_ASKED], *v[_BC_APPLIED], cut_names(int(v[_BC_CUT])))))
        if wants(ch.BODY_TRACKING):
            refs, errors = v[_BC_REFS], v[_BC_ERRORS]
            if not tracking:  # the fins ignore the loops: no tracking to judge
                errors = [math.nan] * 3
            add((ch.BODY_TRACKING, BodyTracking(t, v[_BC_DRIVING] != 0.0, *refs, *errors)))

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
    per = [0.0 if x != x else x for x in v[_P_POWER]]
    energy = sum(v[_P_ENERGY])
    mean = sum(m for m in v[_P_MEAN] if m == m)
    d = v[_P_DISTANCE]
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
