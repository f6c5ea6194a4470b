"""The loop's typed commands and their one channel (``backend.loop.commands``,
``backend.loop.command_channel``)."""

from __future__ import annotations

from typing import Any, Callable

import pytest

from ucat_console.backend.loop.closed_loop import ClosedLoop
from ucat_console.backend.loop.command_channel import CommandChannel
from ucat_console.backend.loop.commands import (
    CommandRefused,
    LoopWork,
    Restart,
    SetBlock,
    SetMode,
    SetSetpoints,
)
from ucat_console.backend.loop.config import LoopConfig
from ucat_console.backend.sim_robot_io import SimRobotIO
from ucat_console.control.allocation import BodySetpoints
from ucat_console.control.params import BaselineConfig, MpcConfig, PidGains
from ucat_console.telemetry import channels as tch
from ucat_console.telemetry.stream import TelemetryStream


class Target:
    """The loop's side of the channel, recording what it is asked (in order)."""

    def __init__(self) -> None:
        self.applied: list[tuple[Any, ...]] = []
        self.setpoints = BodySetpoints(depth=1.0)
        self.mode = "mpc"

    def apply_setpoints(self, sp: BodySetpoints, t: float) -> BodySetpoints:
        self.applied.append(("setpoints", sp, t))
        old, self.setpoints = self.setpoints, sp
        return old

    def apply_mode(self, mode: str, t: float, who: str) -> str:
        self.applied.append(("mode", mode, t, who))
        old, self.mode = self.mode, mode
        return old

    def apply_block(self, block: str, cfg: Any, t: float, who: str) -> None:
        self.applied.append(("block", block, cfg, t, who))

    def apply_restart(self, t: float) -> None:
        self.applied.append(("restart", t))


def channel() -> tuple[CommandChannel, Target]:
    target = Target()
    return CommandChannel(LoopConfig(mode="mpc"), BodySetpoints(depth=1.0), target), target


BAD: list[tuple[str, Callable[[], Any]]] = [
    ("velocity", lambda: SetSetpoints(velocity="fast")),  # type: ignore[arg-type]
    ("depth", lambda: SetSetpoints(depth=float("nan"))),
    ("yaw_rate", lambda: SetSetpoints(yaw_rate=True)),  # type: ignore[arg-type]
    ("mode", lambda: SetMode("turbo")),
    ("mpc config", lambda: SetBlock("mpc", BaselineConfig())),  # type: ignore[arg-type]
    ("block", lambda: SetBlock("pid", MpcConfig())),
    ("block: 'pid.pitch' is not one of mpc, pid.velocity", lambda: SetBlock("pid.pitch", PidGains())),
    ("mpc: /nonexistent", lambda: SetBlock("mpc", MpcConfig(force_model="table", table_path="/nonexistent.npz"))),
    ("pid.depth config: expected a PidGains", lambda: SetBlock("pid.depth", {"kp": 1.0})),
    ("loop work", lambda: LoopWork(None)),  # type: ignore[arg-type]
]


@pytest.mark.parametrize("field,make", BAD, ids=[f.split(":")[0] for f, _ in BAD])
def test_a_bad_command_is_refused_naming_its_field_before_anything_changes(field: str, make) -> None:
    ch, target = channel()
    before = ch.commanded
    with pytest.raises(CommandRefused, match=field):
        ch.submit(make())
    assert ch.commanded == before and not ch.waiting
    ch.drain(1.0)
    assert target.applied == []


def test_setpoints_outside_the_envelope_are_refused_at_submission_and_change_nothing() -> None:
    ch, target = channel()
    ch.submit(SetSetpoints(velocity=0.2))
    with pytest.raises(CommandRefused, match="velocity"):
        ch.submit(SetSetpoints(velocity=LoopConfig().max_velocity + 0.1))
    with pytest.raises(CommandRefused, match="depth"):
        ch.submit(SetSetpoints(depth=-1.0))
    assert ch.commanded.setpoints == BodySetpoints(velocity=0.2, depth=1.0)
    ch.drain(1.0)
    assert [a[0] for a in target.applied] == ["setpoints"]


def test_a_command_is_commanded_at_once_and_applied_only_at_the_drain_in_submission_order() -> None:
    ch, target = channel()
    futures = [
        ch.submit(SetSetpoints(velocity=0.2)),
        ch.submit(SetMode("baseline", "pilot")),
        ch.submit(SetSetpoints(depth=2.0)),  # merged with the velocity commanded just before
        ch.submit(SetBlock("pid.depth", PidGains(kp=6.0), "pilot")),
        ch.submit(Restart()),
        ch.submit(LoopWork(lambda: "done", "work")),
    ]
    assert ch.commanded.mode == "baseline"
    assert ch.commanded.setpoints == BodySetpoints(velocity=0.2, depth=2.0)
    assert ch.commanded.blocks["pid.depth"] == PidGains(kp=6.0)
    assert target.applied == [] and not any(f.done() for f in futures)  # nothing in force yet
    ch.drain(1.5)
    assert target.applied == [
        ("setpoints", BodySetpoints(velocity=0.2, depth=1.0), 1.5),
        ("mode", "baseline", 1.5, "pilot"),
        ("setpoints", BodySetpoints(velocity=0.2, depth=2.0), 1.5),
        ("block", "pid.depth", PidGains(kp=6.0), 1.5, "pilot"),
        ("restart", 1.5),
    ]
    # each Future answers what its command returns: what was in force before
    assert futures[0].result(0) == BodySetpoints(depth=1.0)
    assert futures[1].result(0) == "mpc"
    assert futures[2].result(0) == BodySetpoints(velocity=0.2, depth=1.0)
    assert futures[5].result(0) == "done"


def test_a_cancelled_command_never_runs_and_the_others_do() -> None:
    ch, target = channel()
    ran: list[str] = []
    first = ch.submit(LoopWork(lambda: ran.append("first")))
    gave_up = ch.submit(LoopWork(lambda: ran.append("cancelled")))
    ch.submit(Restart())
    assert gave_up.cancel()
    ch.drain(2.0)
    assert ran == ["first"] and first.done() and gave_up.cancelled()
    assert target.applied == [("restart", 2.0)]


def test_an_exception_goes_through_the_future_and_the_next_commands_still_apply() -> None:
    ch, target = channel()

    def refuse() -> None:
        raise CommandRefused("arm: not now")

    refused = ch.submit(LoopWork(refuse))
    ch.submit(Restart())
    ch.drain(0.5)
    with pytest.raises(CommandRefused, match="not now"):
        refused.result(0)
    assert target.applied == [("restart", 0.5)]


def test_commands_still_queued_when_the_loop_stops_are_refused() -> None:
    ch, target = channel()
    fut = ch.submit(SetSetpoints(velocity=0.1))
    ch.fail_all("the loop is not running")
    with pytest.raises(CommandRefused, match="not running"):
        fut.result(0)
    ch.drain(1.0)
    assert target.applied == []


def test_the_loop_applies_a_submitted_command_at_its_next_event_not_before() -> None:
    stream = TelemetryStream()
    published: list[Any] = []
    stream.subscribe(lambda c, m: published.append(m), [tch.SETPOINTS])
    with ClosedLoop(LoopConfig(mode="baseline"), SimRobotIO(depth=1.0, seed=0), stream,
                    setpoints=BodySetpoints(depth=1.0)) as loop:
        loop.run_until(0.5)
        published.clear()
        fut = loop.submit(SetSetpoints(velocity=0.2))
        assert loop.setpoints == BodySetpoints(velocity=0.2, depth=1.0)  # commanded at once
        assert not fut.done() and published == []  # in force only from the loop's next event
        loop.run_until(0.6)
    assert fut.result(0) == BodySetpoints(depth=1.0)
    assert [(m.velocity, m.depth) for m in published] == [(0.2, 1.0)] and 0.5 <= published[0].t <= 0.6
