"""Each change's effect: the figures before and after a change, by hand on a synthetic run,
and from the supervisor (an Event the session records)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from synthetic_run import run_items

from ucat_console.backend.loop.clock import SimulatedClock
from ucat_console.backend.review.effects import ChangeEffects
from ucat_console.backend.review.metrics import MetricsConfig
from ucat_console.backend.sessions.reader import SessionReader
from ucat_console.backend.supervisor import Supervisor
from ucat_console.backend.access import AccessConfig
from ucat_console.config import AppConfig, ConsoleConfig
from ucat_console.telemetry import channels as C
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.stream import TelemetryStream


def test_the_figures_before_a_change_at_once_and_after_it_when_its_window_passed():
    stream = TelemetryStream()
    published: list[Event] = []
    fx = ChangeEffects(MetricsConfig(before=5.0, after=5.0), published.append)
    stream.subscribe(fx.on_message, fx.channels)
    change = Event(10.0, "loop", "tuning", "mpc.lam_st 5 -> 2", "info", {"block": "mpc"})
    # twice the power from the cycle starting at 10 s, at the same speed
    for channel, m in run_items(cycle_scale=lambda k: 1.0 if k < 10 else 2.0, events=(change,)):
        stream.publish(channel, m)
        if m.t <= 12.0:
            fx.check(m.t)
    [pending] = fx.entries()
    assert pending.after is None and not published
    # [5, 10): 4 W, and the trapezoid from the 4 W sample at 9.9 s to the 8 W one at 10 s
    assert pending.before["power"] == pytest.approx((4.0 * 4.9 + 0.5 * (4.0 + 8.0) * 0.1) / 5.0)
    assert pending.before["st_in"] == pytest.approx(50.0)
    [done] = fx.check(15.0)
    assert done.after["power"] == pytest.approx(8.0)
    assert done.after["energy_per_metre"] == pytest.approx(40.0)  # 8 W at 0.2 m/s
    [ev] = published
    assert (ev.source, ev.code, ev.data["change_t"]) == ("review", "effect", 10.0)
    assert ev.data["after"]["power"] == pytest.approx(8.0)
    assert "8.00 W" in ev.message and ev.message.startswith("mpc.lam_st 5 -> 2")
    json.dumps(ev.data, allow_nan=False)  # NaN figures are null
    assert fx.check(30.0) == []  # once


def _effect(battery_from: float) -> tuple[Event, Event]:
    """A change at 10 s doubling the power, its effect published at 15 s."""
    stream = TelemetryStream()
    published: list[Event] = []
    fx = ChangeEffects(MetricsConfig(before=5.0, after=5.0), published.append)
    stream.subscribe(fx.on_message, fx.channels)
    change = Event(10.0, "loop", "tuning", "mpc.lam_st 5 -> 2", "info", {"block": "mpc"})
    for channel, m in run_items(cycle_scale=lambda k: 1.0 if k < 10 else 2.0, events=(change,),
                                battery_from=battery_from):
        stream.publish(channel, m)
        if m.t <= 12.0:
            fx.check(m.t)
    fx.check(15.0)
    [ev] = published
    return ev, change


def test_a_changes_effect_is_of_the_battery_power_when_both_windows_have_it():
    ev, _ = _effect(battery_from=0.0)
    assert ev.data["power_source"] == "electrical (battery)"
    # 12 W of the battery before, 24 W after; the estimate's 4 and 8 W beside them
    assert ev.data["before"]["power"] == pytest.approx((12.0 * 4.9 + 0.5 * (12.0 + 24.0) * 0.1) / 5.0)
    assert ev.data["after"]["power"] == pytest.approx(24.0)
    assert ev.data["after"]["energy_per_metre"] == pytest.approx(120.0)
    assert ev.data["after"]["mech_power"] == pytest.approx(8.0)
    assert "electrical (battery): " in ev.message and "24.00 W" in ev.message


def test_a_changes_effect_compares_the_estimates_when_a_window_has_no_electrical_readings():
    # the drives report from 12 s: the window before the change has none
    ev, _ = _effect(battery_from=12.0)
    assert ev.data["power_source"] == "mechanical (shaft estimate): electrical readings not in both windows"
    assert ev.data["before"]["power"] == pytest.approx((4.0 * 4.9 + 0.5 * (4.0 + 8.0) * 0.1) / 5.0)
    assert ev.data["after"]["power"] == pytest.approx(8.0)
    assert "mechanical (shaft estimate)" in ev.message


def test_the_supervisor_records_each_tuning_changes_effect(tmp_path: Path):
    from ucat_console.backend.access import LOCAL

    cfg = AppConfig(console=ConsoleConfig(supervise_period=0.05), access=AccessConfig(token="t" * 12),
                    metrics=MetricsConfig(before=1.0, after=1.0))
    sup = Supervisor(cfg, clock=SimulatedClock(), sessions_dir=tmp_path)
    try:
        sup.start_recording(LOCAL)
        sup.arm(LOCAL)
        sup.step(1.5)
        sup.set_params(LOCAL, {"mpc.lam_st": 2.0})
        sup.step(1.5)
        [effect] = [e for e in sup.effects.entries() if e.code == "tuning"]
        assert effect.after is not None and effect.after["power"] is not None and effect.after["power"] > 0.0
        paths = sup.stop_recording(LOCAL)
    finally:
        sup.stop()
    with SessionReader(paths[0], tmp_path) as r:
        recorded = [m for _, m in r.messages([C.EVENTS]) if m.code == "effect"]
    assert len(recorded) == 1 and recorded[0].data["code"] == "tuning"
    assert recorded[0].data["before"].keys() == recorded[0].data["after"].keys()
    # the in-process simulator's drives report their electrical input: the battery's figures
    assert recorded[0].data["power_source"] == "electrical (battery)"
    assert recorded[0].data["after"]["power"] > recorded[0].data["after"]["mech_power"] > 0.0


def test_undo_puts_the_latest_tuning_change_back_in_one_step_and_only_for_the_pilot(tmp_path: Path):
    from ucat_console.backend.supervisor import CommandRefused

    cfg = AppConfig(console=ConsoleConfig(supervise_period=0.05), access=AccessConfig(token="t" * 12))
    sup = Supervisor(cfg, clock=SimulatedClock(), sessions_dir=tmp_path)
    try:
        sup.client_connected(1)
        sup.client_connected(2)
        assert sup.take_control(1, "t" * 12)
        with pytest.raises(CommandRefused, match="no tuning change"):
            sup.undo_tuning(1)
        lam_st, kp = sup.param_value("mpc.lam_st"), sup.param_value("pid.depth.kp")
        sup.set_params(1, {"mpc.lam_f": 2.5})
        sup.step(0.1)
        sup.set_params(1, {"mpc.lam_st": 2.0, "pid.depth.kp": 7.0})
        sup.step(0.2)
        with pytest.raises(Exception, match="pilot"):
            sup.undo_tuning(2)
        sup.undo_tuning(1)
        sup.step(0.2)
        # both parameters of the latest change back, the earlier change kept
        assert (sup.param_value("mpc.lam_st"), sup.param_value("pid.depth.kp")) == (lam_st, kp)
        assert sup.param_value("mpc.lam_f") == 2.5
    finally:
        sup.stop()
