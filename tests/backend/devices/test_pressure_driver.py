"""Pressure transducer: current -> pressure -> depth by hand, zeroing, faults over a pty."""

from __future__ import annotations

import pytest

from ucat_console.backend.devices.faults import FaultSettings
from ucat_console.backend.devices.pressure import (
    AdcIssue,
    AdcLineError,
    AdcLineParser,
    PressureConfig,
    PressureDriver,
    format_adc_line,
    parse_adc_line,
)
from ucat_console.backend.devices.pressure_emulator import PressureEmulator, PressureEmulatorConfig
from ucat_console.robot.units import current_to_pressure, depth_to_pressure, pressure_to_current, pressure_to_depth


def test_current_to_depth_by_hand() -> None:
    # 4.8 mA on a 0..10 bar (1e6 Pa) transducer: 0.8/16 of the span = 50 000 Pa
    p = current_to_pressure(4.8, 0.0, 1.0e6)
    assert p == pytest.approx(50_000.0, rel=1e-12)
    # fresh water: 50 000 / (997 * 9.80665) = 50 000 / 9777.23005 = 5.113923 m
    assert pressure_to_depth(p, 0.0, 997.0) == pytest.approx(5.113923, rel=1e-6)
    # salt water and a 2000 Pa surface offset: 48 000 / (1029 * 9.80665) = 4.756694 m
    assert pressure_to_depth(p, 2000.0, 1029.0) == pytest.approx(4.756694, rel=1e-6)
    # ends of the loop
    assert current_to_pressure(4.0, -1000.0, 2.0e5) == -1000.0
    assert current_to_pressure(20.0, -1000.0, 2.0e5) == pytest.approx(199_000.0)


def test_conversions_round_trip() -> None:
    for i in (4.0, 7.3, 12.0, 19.99):
        assert pressure_to_current(current_to_pressure(i, 500.0, 6.0e5), 500.0, 6.0e5) == pytest.approx(i)
    for d in (0.0, 0.5, 12.25, 80.0):
        assert pressure_to_depth(depth_to_pressure(d, 321.0, 1029.0), 321.0, 1029.0) == pytest.approx(d)


def test_adc_line_format() -> None:
    assert parse_adc_line(b"I=12.345mA") == 12.345
    assert parse_adc_line(b"I=4mA") == 4.0
    assert format_adc_line(12.345) == b"I=12.3450mA\r\n"
    for bad in (b"", b"I=mA", b"I=12.3", b"V=1.2V", b"I=nanmA", b"I=1.2.3mA", b"I=12.345uA"):
        with pytest.raises(AdcLineError):
            parse_adc_line(bad)


def test_adc_parser_framing_and_issues() -> None:
    parser = AdcLineParser()
    assert parser.feed(b"I=4.5mA\r\nI=5") == [4.5]
    items = parser.feed(b".5mA\nJUNK\r\nI=6mA\n")
    assert items[0] == 5.5 and items[2] == 6.0
    assert isinstance(items[1], AdcIssue) and items[1].kind == "malformed_line"
    assert "JUNK" in items[1].detail


def test_config_bounds() -> None:
    with pytest.raises(ValueError, match="rho"):
        PressureConfig(rho=5.0)
    with pytest.raises(ValueError, match="span_pa"):
        PressureConfig(span_pa=0.0)


# ---------------------------------------------------------------- driver over a pty


class Depth:
    """A settable depth source."""

    def __init__(self, depth: float) -> None:
        self.depth = depth

    def __call__(self, t: float) -> float:
        return self.depth


@pytest.fixture
def rig(collector):
    made = []

    def make(depth=0.0, offset=0.0, **cfg_kw):
        source = Depth(depth)
        transducer = PressureConfig(rho=1029.0)
        emulator = PressureEmulator(
            source,
            PressureEmulatorConfig(rate_hz=100.0, surface_offset_pa=offset,
                                   faults=FaultSettings(slow_delay_s=0.1)),
            transducer,
        ).start()
        readings, events = collector(), collector()
        cfg = dict(port=emulator.port, rho=1029.0, silence_timeout_s=0.3)
        cfg.update(cfg_kw)
        driver = PressureDriver(PressureConfig(**cfg), readings, events)
        made.append((driver, emulator))
        return source, emulator, driver, readings, events

    yield make
    for driver, emulator in made:
        driver.stop()
        emulator.stop()


# one ADC step (1e-4 mA) is 1e-4/16 * 1e6 Pa = 6.25 Pa, i.e. 0.6 mm of sea water
STEP_PA = 6.25


def test_surface_zeroing_removes_the_sensor_offset(rig, wait_for) -> None:
    source, emulator, driver, readings, events = rig(depth=0.0, offset=2500.0)
    assert driver.start()
    wait_for(lambda: len(readings) > 2, what="readings")
    # before zeroing the 2500 Pa offset reads as 2500 / (1029 * 9.80665) = 0.24775 m
    assert readings.items[-1].depth_m == pytest.approx(0.24775, abs=1e-3)
    surface = driver.zero(samples=10)
    assert surface == pytest.approx(2500.0, abs=STEP_PA)
    assert events.with_code("zeroed")
    source.depth = 3.0
    wait_for(lambda: abs(readings.items[-1].depth_m - 3.0) < 1e-3, what="depth 3 m after zeroing")
    assert readings.items[-1].pressure_pa == pytest.approx(2500.0 + 3.0 * 1029.0 * 9.80665, abs=STEP_PA)


def test_broken_loop_is_a_fault_never_a_depth(rig, wait_for) -> None:
    source, emulator, driver, readings, events = rig(depth=5.0)
    assert driver.start()
    wait_for(lambda: len(readings) > 2, what="readings")
    emulator.inject("invalid")  # the ADC reads 0 mA
    broken = wait_for(lambda: events.with_code("broken_loop"), what="broken_loop event")
    assert broken[0].data["current_ma"] == 0.0 and broken[0].level == "error"
    n = len(readings)
    emulator.clear()
    wait_for(lambda: events.with_code("recovered"), what="recovered")
    wait_for(lambda: len(readings) > n + 2, what="readings after recovery")
    assert all(abs(r.depth_m - 5.0) < 1e-2 for r in readings.items)  # no bogus depth got through
    assert len(events.with_code("broken_loop")) == 1


def test_over_range_current_is_a_fault(rig, wait_for) -> None:
    # 110 m of sea water: 110 * 1029 * 9.80665 = 1.110e6 Pa -> 4 + 16 * 1.110 = 21.8 mA > 20.5
    source, emulator, driver, readings, events = rig(depth=110.0)
    assert driver.start()
    broken = wait_for(lambda: events.with_code("broken_loop"), what="broken_loop event")
    assert broken[0].data["current_ma"] == pytest.approx(21.76, abs=0.01)
    assert len(readings) == 0


def test_corrupt_lines_are_reported(rig, wait_for) -> None:
    source, emulator, driver, readings, events = rig(depth=1.0)
    assert driver.start()
    emulator.inject("corrupt")
    wait_for(lambda: events.with_code("malformed_line"), what="malformed_line event")
    emulator.clear()
    n = len(readings)
    wait_for(lambda: len(readings) > n + 2, what="readings after corruption")
    assert all(abs(r.depth_m - 1.0) < 1e-2 for r in readings.items)


def test_silence_and_recovery(rig, wait_for) -> None:
    source, emulator, driver, readings, events = rig(depth=1.0)
    assert driver.start()
    wait_for(lambda: len(readings) > 1, what="readings")
    emulator.inject("silence")
    wait_for(lambda: events.with_code("silence"), what="silence")
    emulator.clear()
    wait_for(lambda: events.with_code("recovered"), what="recovered")


def test_zeroing_without_readings_fails_cleanly(rig) -> None:
    source, emulator, driver, readings, events = rig(depth=0.0)
    emulator.inject("silence")
    assert driver.start()
    assert driver.zero(samples=5, timeout_s=0.2) is None
    assert driver.surface_pressure_pa == 0.0
    assert events.with_code("zero_failed")


def test_missing_port_is_an_event(collector, tmp_path) -> None:
    events = collector()
    driver = PressureDriver(PressureConfig(port=str(tmp_path / "nope")), lambda r: None, events)
    try:
        assert driver.start() is False
    finally:
        driver.stop()
    assert events.with_code("port_error")
