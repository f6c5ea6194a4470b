"""The loop watchdog: a thread of its own disarms when the control loop stops stepping (its
thread held by a fault injection), on the in-process simulator and on the emulated rig,
where it turns the drives off while the loop is still stuck."""

from __future__ import annotations

import pytest
from support import Console, FakeClock, wait_for

from ucat_console.backend.devices import cia402
from ucat_console.backend.supervisor import CommandRefused, Supervisor
from ucat_console.backend.supervisor.watchdog import LoopWatchdog
from ucat_console.backend.failsafe_config import FailsafeRule, LoopWatchdogRule
from ucat_console.config import load_config
from ucat_console.ui.status_bar import lights, vehicle_parts

TOKEN = "watchdog-token"
PILOT = 1


def test_the_watchdog_acts_once_when_the_beats_stop_and_resumes_with_the_next_beat() -> None:
    clock = FakeClock()
    stuck: list[float] = []
    resumed: list[bool] = []
    dog = LoopWatchdog(0.5, stuck.append, lambda: resumed.append(True), clock=clock)
    dog.beat()
    for _ in range(5):
        assert dog.check(clock.advance(0.1)) is None
    assert dog.check(clock.advance(0.1)) == pytest.approx(0.6)
    assert dog.check(clock.advance(0.1)) is None  # once
    assert stuck == [pytest.approx(0.6)] and not resumed
    dog.beat()
    assert resumed == [True] and not dog.tripped
    assert dog.check(clock.advance(0.1)) is None


def test_a_watchdog_held_back_itself_looks_again_before_it_acts() -> None:
    clock = FakeClock()
    stuck: list[float] = []
    dog = LoopWatchdog(0.5, stuck.append, lambda: None, clock=clock)
    assert dog.check(clock.advance(2.0)) is None  # the whole process was held back
    assert not stuck
    dog.beat()  # the loop ran as soon as it could
    assert dog.check(clock.advance(0.02)) is None
    assert dog.check(clock.advance(2.0)) is None
    assert dog.check(clock.advance(0.02)) == pytest.approx(2.04)  # still silent: stuck


def test_the_watchdog_rule_only_disarms_or_warns() -> None:
    with pytest.raises(ValueError, match="action"):
        LoopWatchdogRule("hold", 1.0)
    with pytest.raises(ValueError, match="escalate"):
        LoopWatchdogRule("warn", 1.0, escalate="disarm")


def _console(tmp_path, base: str, **failsafes: FailsafeRule) -> Supervisor:
    cfg = load_config(base)
    cfg = cfg.replace(access=cfg.access.replace(token=TOKEN), console=cfg.console.replace(record_on_arm=False),
                      failsafe=cfg.failsafe.replace(**failsafes))
    c = Console(cfg, tmp_path, clock=None)
    c.fly(PILOT, TOKEN)
    return c.sup


def _light(sup: Supervisor, name: str):
    return next(x for x in vehicle_parts(sup.state()) if x.name == name)


@pytest.mark.slow
@pytest.mark.parametrize("base", [None, "sim-devices"])
def test_a_stuck_loop_is_disarmed_by_the_watchdog_and_the_failsafe_clears_when_it_steps_again(tmp_path, base) -> None:
    sup = _console(tmp_path, base)
    try:
        wait_for(lambda: sup.loop.time > 1.0 and not sup.safety.active(), what="the loop running, no failsafe")
        sup.arm(PILOT)
        events = []
        sup.stream.subscribe(lambda c, m: events.append(m), ["events"])
        rig = sup.rig
        if rig is not None:
            assert all(n.state == cia402.OPERATION_ENABLED for n in rig.nodes.nodes.values())
        t_loop = sup.loop.time
        sup.stall_loop(PILOT, 30.0)
        wait_for(lambda: not sup.armed, what="the watchdog disarming")
        ev = wait_for(lambda: next((e for e in events if e.source == "failsafe" and e.code == "loop_watchdog"), None),
                      what="the loop_watchdog event")
        assert ev.data["action"] == "disarm" and "has not stepped for" in ev.data["cause"]
        wait_for(lambda: any(e.source == "supervisor" and e.code == "disarmed" for e in events),
                 what="the disarmed event")
        assert _light(sup, "Loop").state == "bad"
        vehicle = next(x for x in lights(sup.state()) if x.name == "Vehicle")  # the bar's one light for it
        assert vehicle.state == "bad" and vehicle.why.startswith("Loop: failsafe loop_watchdog")
        with pytest.raises(CommandRefused, match="loop_watchdog"):
            sup.request_arm(PILOT)
        if rig is not None:  # the drives are off while the loop is still held
            wait_for(lambda: all(n.state != cia402.OPERATION_ENABLED for n in rig.nodes.nodes.values()),
                     what="every drive's power stage off")
        assert sup.loop.time < t_loop + 0.5  # the loop is still stuck
        sup._unstall.set()
        wait_for(lambda: not sup.safety.is_active("loop_watchdog"), what="the failsafe clearing")
        assert any(e.source == "failsafe" and e.code == "cleared" and e.data["failsafe"] == "loop_watchdog"
                   for e in events)
        assert _light(sup, "Loop").state == "ok"
    finally:
        sup.stop()


def test_a_loop_on_the_simulated_clock_held_back_is_a_slower_run_not_a_disarm(tmp_path) -> None:
    # a headless run as fast as it goes: the simulated robot stands still with its loop
    cfg = load_config(None)
    cfg = cfg.replace(access=cfg.access.replace(token=TOKEN), console=cfg.console.replace(record_on_arm=False),
                      failsafe=cfg.failsafe.replace(loop_watchdog=LoopWatchdogRule("disarm", 0.1)))
    c = Console(cfg, tmp_path)  # the simulated clock
    sup = c.sup
    try:
        c.fly(PILOT, TOKEN)
        sup.arm(PILOT)
        t_loop = sup.loop.time
        sup.stall_loop(PILOT, 1.0)  # ten times the timeout
        wait_for(lambda: sup.loop.time > t_loop + 5.0, what="the loop past its stall")
        assert sup.armed
        assert not sup.safety.is_active("loop_watchdog")
        assert not any(e.source == "failsafe" and e.code == "loop_watchdog" for e in c.events)
    finally:
        c.stop()


def test_stalling_the_loop_is_refused_with_its_reason(tmp_path) -> None:
    sup = _console(tmp_path, None)
    try:
        for bad in (0.0, -1.0, 61.0, float("nan"), "x"):
            with pytest.raises(CommandRefused, match="seconds|stall"):
                sup.stall_loop(PILOT, bad)
    finally:
        sup.stop()
