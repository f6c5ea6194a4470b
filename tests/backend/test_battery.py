"""The battery failsafes: the lowest drive supply voltage and the energy the drives drew,
from the drives' electrical input; a drive that does not answer (NaN) is no zero volts. A
sagging supply injected in an emulated EPOS2 of the rig, and a simulated robot that uses up
a small capacity, each make the robot surface."""

from __future__ import annotations

import math

import pytest
from support import Console, wait_for

from ucat_console.backend.access import LOCAL
from ucat_console.backend.safety import SafetyMonitor
from ucat_console.backend.failsafe_config import FailsafeConfig, FailsafeRule
from ucat_console.config import load_config
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.messages import ElectricalPower
from ucat_console.ui.status_bar import bar_state, vehicle_parts

TOKEN = "battery-token"
PILOT = 1
NAN = math.nan


def power(t: float, volts: tuple[float, ...], watts: float = 10.0) -> ElectricalPower:
    return ElectricalPower(t, (0.5,) * 4, volts, (watts / 4,) * 4, watts)


def battery(transitions: list) -> list[tuple[str, bool]]:
    return [(tr.name, tr.active) for tr in transitions if tr.name.startswith("battery")]


def test_the_lowest_answering_drive_sets_the_voltage_and_a_nan_is_no_zero() -> None:
    cfg = FailsafeConfig(battery_low=FailsafeRule("warn", 1.0), battery_critical=FailsafeRule("surface", 1.0))
    mon = SafetyMonitor(cfg)
    mon.on_message(ch.POWER_ELECTRICAL, power(0.0, (NAN, NAN, NAN, NAN)))
    assert mon.battery()[0] is None and battery(mon.check(5.0)) == []
    mon.on_message(ch.POWER_ELECTRICAL, power(5.0, (24.0, NAN, 21.5, 24.0)))  # one drive silent
    assert mon.battery()[0] == (5.0, 21.5)
    assert battery(mon.check(5.9)) == []
    mon.on_message(ch.POWER_ELECTRICAL, power(6.0, (24.0, NAN, 21.5, 24.0)))
    assert battery(mon.check(6.0)) == [("battery_low", True)]
    assert "the lowest drive supply 21.5 V below 22 V" in next(s.cause for s in mon.states() if s.name == "battery_low")
    mon.on_message(ch.POWER_ELECTRICAL, power(6.5, (20.5, 20.5, 20.5, 20.5)))
    assert battery(mon.check(7.6)) == [("battery_critical", True)]
    mon.on_message(ch.POWER_ELECTRICAL, power(8.0, (NAN,) * 4))  # no answer: it stays
    assert battery(mon.check(8.0)) == []
    mon.on_message(ch.POWER_ELECTRICAL, power(8.5, (24.0,) * 4))
    assert sorted(battery(mon.check(8.5))) == [("battery_critical", False), ("battery_low", False)]


def test_the_energy_drawn_against_the_capacity() -> None:
    mon = SafetyMonitor(FailsafeConfig(battery_capacity=1.0))  # 1 Wh: 3600 J
    for k in range(0, 101):  # 360 W for 10 s in 0.1 s messages (the first only starts the count)
        mon.on_message(ch.POWER_ELECTRICAL, power(0.1 * k, (24.0,) * 4, watts=360.0))
    assert mon.battery()[1] == pytest.approx(1.0)
    assert battery(mon.check(10.0)) == [("battery_low", True), ("battery_critical", True)]
    assert "1.0 Wh of 1 Wh used, less than 15% left" in next(s.cause for s in mon.states()
                                                             if s.name == "battery_critical")
    mon.on_message(ch.POWER_ELECTRICAL, power(60.0, (24.0,) * 4, watts=360.0))  # after a gap: not counted
    assert mon.battery()[1] == pytest.approx(1.0)


def test_the_voltage_thresholds_are_ordered() -> None:
    with pytest.raises(ValueError, match="battery_critical_voltage: 23 V must be below battery_low_voltage 22 V"):
        FailsafeConfig(battery_critical_voltage=23.0)
    with pytest.raises(ValueError, match="battery_critical_reserve"):
        FailsafeConfig(battery_critical_reserve=0.5)


def _surfaced(sup, events: list) -> None:
    ev = wait_for(lambda: next((e for e in events if e.source == "failsafe" and e.code == "battery_critical"), None),
                  what="the battery_critical event")
    assert ev.data["action"] == "surface" and "battery: " in ev.data["cause"]
    assert sup.setpoints.depth == 0.0
    assert next(x for x in vehicle_parts(sup.state()) if x.name == "Battery").state == "bad"


def test_a_simulated_robot_that_uses_up_its_capacity_surfaces(tmp_path) -> None:
    cfg = load_config("sim-tuned")
    cfg = cfg.replace(console=cfg.console.replace(record_on_arm=False),
                      failsafe=cfg.failsafe.replace(battery_capacity=0.005))  # 18 J
    c = Console(cfg, tmp_path)
    sup = c.sup
    try:
        sup.step(1.0)
        assert next(x for x in vehicle_parts(sup.state()) if x.name == "Battery").state == "ok"
        sup.arm(LOCAL)
        sup.set_setpoints(LOCAL, velocity=0.2, depth=1.0)
        for _ in range(120):
            sup.step(0.5)
            if sup.safety.is_active("battery_critical"):
                break
        _surfaced(sup, c.events)
        assert "Wh used" in bar_state(sup.state(), None, dark=False, uuids={})["battery"]
    finally:
        c.stop()


@pytest.mark.slow
def test_a_sagging_supply_injected_in_an_emulated_drive_surfaces_the_rig(tmp_path) -> None:
    cfg = load_config("sim-devices")
    cfg = cfg.replace(access=cfg.access.replace(token=TOKEN), console=cfg.console.replace(record_on_arm=False),
                      failsafe=cfg.failsafe.replace(battery_low=FailsafeRule("warn", 1.0),
                                                    battery_critical=FailsafeRule("surface", 1.0)))
    c = Console(cfg, tmp_path, clock=None)
    sup = c.sup
    try:
        c.fly(PILOT, TOKEN)
        wait_for(lambda: sup.safety.battery()[0] is not None and not sup.safety.active(),
                 what="the drives' supply voltage, no failsafe")
        sup.arm(PILOT)
        sup.inject_fault(PILOT, "epos2", "low_voltage", fin=2, volts=20.0)
        _surfaced(sup, c.events)
        assert sup.safety.is_active("battery_low")
        assert "20.0 V" in next(x for x in vehicle_parts(sup.state()) if x.name == "Battery").why
        sup.clear_fault(PILOT, "epos2", "low_voltage")
        wait_for(lambda: not sup.safety.is_active("battery_critical"), what="the failsafe clearing")
    finally:
        c.stop()
