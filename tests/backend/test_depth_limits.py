"""The depth limit and the minimum altitude above the floor: the monitor's rules on readings
it is given, then the robot diving past each, on the in-process simulator and through the
emulated rig's pressure sensor and DVL: it surfaces, the Limits light says why, and the
failsafe clears once the robot is back within the limit."""

from __future__ import annotations

import math

import pytest
from support import Console, wait_for

from ucat_console.backend.access import LOCAL
from ucat_console.backend.safety import SafetyMonitor
from ucat_console.backend.failsafe_config import FailsafeConfig, FailsafeRule
from ucat_console.config import load_config
from ucat_console.robot.readings import DepthReading, DvlVelocity
from ucat_console.telemetry import channels as ch
from ucat_console.ui.status_bar import vehicle_parts

TOKEN = "limits-token"
PILOT = 1


def dvl(t: float, altitude: float, valid: bool = True) -> DvlVelocity:
    return DvlVelocity(t=t, vx=0.0, vy=0.0, vz=0.0, valid=valid, altitude=altitude, fom=0.01)


def depth(t: float, d: float) -> DepthReading:
    return DepthReading(t=t, depth_m=d, pressure_pa=101325.0 + 1e4 * d)


def only(name: str, transitions: list) -> list:
    return [tr for tr in transitions if tr.name == name]


def test_the_depth_limit_triggers_after_its_timeout_beyond_the_limit_and_clears_within_it() -> None:
    mon = SafetyMonitor(FailsafeConfig(max_depth=2.0, depth_limit=FailsafeRule("surface", 1.0)))
    mon.on_message(ch.DEPTH, depth(0.0, 2.1))
    assert only("depth_limit", mon.check(0.9)) == []
    mon.on_message(ch.DEPTH, depth(0.95, 2.2))
    [tr] = only("depth_limit", mon.check(1.0))
    assert (tr.name, tr.active, tr.action) == ("depth_limit", True, "surface")
    assert "depth 2.20 m deeper than the limit 2 m" in tr.cause
    mon.on_message(ch.DEPTH, depth(1.1, math.nan))  # not a depth: changes nothing
    assert only("depth_limit", mon.check(1.2)) == []
    mon.on_message(ch.DEPTH, depth(1.3, 1.9))
    [tr] = only("depth_limit", mon.check(1.4))
    assert (tr.name, tr.active) == ("depth_limit", False)


def test_an_invalid_altitude_is_not_a_zero_altitude() -> None:
    mon = SafetyMonitor(FailsafeConfig(min_altitude=0.5, altitude=FailsafeRule("surface", 1.0)))
    for k, alt in enumerate((math.nan, -1.0, 0.0)):  # none, the A50's "no lock", zero
        mon.on_message(ch.DVL, dvl(0.1 * k, alt, valid=alt == 0.0))
    assert only("altitude", mon.check(5.0)) == []
    mon.on_message(ch.DVL, dvl(5.0, 0.3))
    assert only("altitude", mon.check(5.5)) == []
    mon.on_message(ch.DVL, dvl(5.6, math.nan, valid=False))  # neither clears it
    [tr] = only("altitude", mon.check(6.0))
    assert tr.active and "altitude 0.30 m above the floor, below the minimum 0.5 m" in tr.cause
    mon.on_message(ch.DVL, dvl(6.1, 0.6))
    assert [tr.active for tr in only("altitude", mon.check(6.2))] == [False]


#: the failsafe -> the failsafe configuration that a dive from 1 m to 2 m passes (the floor at 2.5 m)
LIMITS = {"depth_limit": {"max_depth": 1.3}, "altitude": {"min_altitude": 1.2}}


def _config(base: str | None, name: str):
    cfg = load_config(base)
    plant = cfg.plant.replace(sensors=cfg.plant.sensors.replace(dvl=cfg.plant.sensors.dvl.replace(bottom_depth=2.5)))
    return cfg.replace(access=cfg.access.replace(token=TOKEN), console=cfg.console.replace(record_on_arm=False),
                       devices=cfg.devices.replace(start=cfg.devices.start.replace(depth=1.0)), plant=plant, failsafe=cfg.failsafe.replace(**LIMITS[name]))


def _surfaced(sup, name: str, events: list) -> None:
    ev = next(e for e in events if e.source == "failsafe" and e.code == name)
    assert ev.data["action"] == "surface"
    assert sup.setpoints.depth == 0.0 and sup.armed
    light = next(x for x in vehicle_parts(sup.state()) if x.name == "Limits")
    assert light.state == "bad" and f"failsafe {name}" in light.why


@pytest.mark.parametrize("name", sorted(LIMITS))
def test_the_simulated_robot_diving_past_a_limit_surfaces_until_it_is_back_within(tmp_path, name: str) -> None:
    c = Console(_config("sim-tuned", name), tmp_path)
    sup = c.sup
    try:
        sup.step(1.0)
        assert next(x for x in vehicle_parts(sup.state()) if x.name == "Limits").state == "ok"
        sup.arm(LOCAL)
        sup.set_setpoints(LOCAL, depth=2.0)
        for _ in range(120):
            sup.step(0.5)
            if sup.safety.is_active(name):
                break
        _surfaced(sup, name, c.events)
        for _ in range(240):
            sup.step(0.5)
            if not sup.safety.is_active(name):
                break
        assert c.event("failsafe", "cleared") is not None and not sup.safety.is_active(name)
    finally:
        c.stop()


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(LIMITS))
def test_the_rig_diving_past_a_limit_surfaces_through_its_pressure_sensor_and_dvl(tmp_path, name: str) -> None:
    c = Console(_config("sim-devices", name), tmp_path, clock=None)
    sup = c.sup
    try:
        c.fly(PILOT, TOKEN)
        wait_for(lambda: sup.loop.time > 1.0 and not sup.safety.active(), what="the rig running, no failsafe")
        sup.arm(PILOT)
        sup.set_setpoints(PILOT, depth=2.0)
        wait_for(lambda: sup.safety.is_active(name), timeout=120, what=f"the {name} failsafe")
        wait_for(lambda: c.event("failsafe", name), what="its event")
        _surfaced(sup, name, c.events)
        wait_for(lambda: not sup.safety.is_active(name), timeout=120, what="the robot back within the limit")
    finally:
        c.stop()
