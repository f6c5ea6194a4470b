"""The leak detector: its input read from a GPIO value file (water, dry, unreadable: never
taken for dry), and water injected at the emulated detector of the in-process simulator and
of the emulated rig (through its rig faults), which surfaces the robot until it is dry again."""

from __future__ import annotations

import pytest
from support import Collector, Console, wait_for

from ucat_console.backend.access import LOCAL
from ucat_console.backend.devices.leak import LeakConfig, LeakInput
from ucat_console.backend.supervisor import CommandRefused
from ucat_console.config import load_config
from ucat_console.ui.status_bar import vehicle_parts

TOKEN = "leak-token"
PILOT = 1


@pytest.mark.parametrize("active_high", [True, False])
def test_the_input_reports_water_dry_and_an_unreadable_file(tmp_path, active_high: bool) -> None:
    value = tmp_path / "value"
    events = Collector()
    leak = LeakInput(LeakConfig(active_high=active_high), str(value), events, lambda: 1.0)
    water, dry = ("1", "0") if active_high else ("0", "1")
    value.write_text(dry + "\n")
    leak.read()
    leak.read()
    assert events.codes() == ["dry"] and leak.wet is False
    value.write_text(water + "\n")
    leak.read()
    assert events.codes()[-1] == "water" and leak.wet is True
    value.write_text("x")
    leak.read()
    leak.read()
    assert events.codes()[-1] == "unreadable" and events.codes().count("unreadable") == 1 and leak.wet is None
    value.unlink()
    leak.read()
    assert events.codes().count("unreadable") == 1
    value.write_text(water)
    leak.read()
    assert events.codes()[-1] == "water"


def _leak(sup) -> str:
    """The leak detector's latest reading as its state: water, dry, unreadable ("": none yet)."""
    r = sup.sensors.latest("leak")
    return "" if r is None else "unreadable" if not r.readable else "water" if r.water else "dry"


def _surfaced(sup, events) -> None:
    ev = next(e for e in events if e.source == "failsafe" and e.code == "leak")
    assert ev.data["action"] == "surface" and "water" in ev.data["cause"]
    assert sup.setpoints.depth == 0.0 and sup.armed
    assert next(x for x in vehicle_parts(sup.state()) if x.name == "Leak").state == "bad"


def test_water_at_the_simulators_emulated_detector_surfaces_the_robot(tmp_path) -> None:
    cfg = load_config("sim-tuned")
    c = Console(cfg.replace(console=cfg.console.replace(record_on_arm=False)), tmp_path)
    sup = c.sup
    try:
        wait_for(lambda: _leak(sup) == "dry", what="the emulated detector read dry")
        sup.step(1.0)
        assert next(x for x in vehicle_parts(sup.state()) if x.name == "Leak").state == "ok"
        sup.arm(LOCAL)
        sup.set_setpoints(LOCAL, depth=1.0)
        sup.inject_leak(LOCAL, True)
        wait_for(lambda: _leak(sup) == "water", what="the detector reading water")
        sup.step(0.1)
        _surfaced(sup, c.events)
        with pytest.raises(CommandRefused, match="leak"):
            sup.inject_leak(LOCAL, "yes")
        sup.inject_leak(LOCAL, False)
        wait_for(lambda: _leak(sup) == "dry", what="the detector reading dry")
        sup.step(0.1)
        assert not sup.safety.is_active("leak")
    finally:
        c.stop()


@pytest.mark.slow
def test_water_at_the_rigs_emulated_detector_surfaces_the_robot(tmp_path) -> None:
    cfg = load_config("sim-devices")
    cfg = cfg.replace(access=cfg.access.replace(token=TOKEN), console=cfg.console.replace(record_on_arm=False))
    c = Console(cfg, tmp_path, clock=None)
    sup = c.sup
    try:
        c.fly(PILOT, TOKEN)
        wait_for(lambda: sup.loop.time > 1.0 and not sup.safety.active(), what="the rig running, no failsafe")
        sup.arm(PILOT)
        assert sup.rig_control.fault_tables()[0]["leak"] == ("water",)  # the Safety tab's rig faults
        with pytest.raises(CommandRefused, match="only 'water'"):
            sup.inject_fault(PILOT, "leak", "water", duration=2.0)
        sup.inject_fault(PILOT, "leak", "water")
        wait_for(lambda: sup.safety.is_active("leak"), what="the leak failsafe")
        wait_for(lambda: c.event("failsafe", "leak"), what="its event")
        wait_for(lambda: sup.setpoints.depth == 0.0, what="the surfacing setpoints")
        _surfaced(sup, c.events)
        sup.clear_fault(PILOT, "leak")
        wait_for(lambda: not sup.safety.is_active("leak"), what="the failsafe clearing")
    finally:
        c.stop()
