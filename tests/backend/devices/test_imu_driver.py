"""IMU driver against the 3DM-CX5 emulator over a real pty pair."""

from __future__ import annotations

import math
import pytest

from ucat_console.backend.devices import mip
from ucat_console.backend.devices.faults import FaultSettings
from ucat_console.backend.devices.imu import ImuConfig, ImuDriver
from ucat_console.backend.devices.imu_emulator import ImuEmulator, ImuEmulatorConfig
from ucat_console.robot.readings import ImuReading

# values exactly representable in float32, so they survive the wire unchanged: the sensor
# sends the specific force in standard gravities (0.25, -0.5, -0.75) g0, the reading holds m/s^2
TRUTH = ImuReading(
    t=0.0, accel=(0.25 * 9.80665, -0.5 * 9.80665, -0.75 * 9.80665), gyro=(0.0, 0.125, -0.5),
    quaternion=(0.5, 0.5, -0.5, 0.5), euler=(0.25, -0.125, 1.5),
)


def truth(t: float) -> ImuReading:
    return TRUTH


def fast_config(port: str, **kw) -> ImuConfig:
    base = dict(port=port, rate_hz=100.0, command_timeout_s=0.3, command_retries=1, silence_timeout_s=0.3)
    base.update(kw)
    return ImuConfig(**base)


@pytest.fixture
def rig(collector):
    """Start an emulator and a driver; stop both at the end."""
    started = []

    def make(emulator_config=ImuEmulatorConfig(), source=truth, **driver_kw):
        emulator = ImuEmulator(source, emulator_config).start()
        readings, events = collector(), collector()
        driver = ImuDriver(fast_config(emulator.port, **driver_kw), readings, events)
        started.append((driver, emulator))
        return emulator, driver, readings, events

    yield make
    for driver, emulator in started:
        driver.stop()
        emulator.stop()


def test_configures_and_streams_quaternion(rig, wait_for) -> None:
    emulator, driver, readings, events = rig()
    assert driver.start()
    assert driver.streamed_fields == (mip.FIELD_ACCEL, mip.FIELD_GYRO, mip.FIELD_QUATERNION)
    assert driver.orientation_streamed == "quaternion"
    # the console's sequence, in order: idle, base rate, message format, enable stream, resume
    first_seen = list(dict.fromkeys(emulator.commands))  # a retried command counts once
    assert first_seen[:5] == [(0x01, 0x02), (0x0C, 0x06), (0x0C, 0x08), (0x0C, 0x11), (0x01, 0x06)]
    assert emulator.decimation == 10  # 1000 Hz base / 100 Hz requested
    assert not emulator.idle and emulator.stream_enabled
    wait_for(lambda: any(r.quaternion is not None for r in readings.items), what="quaternion readings")
    r = [r for r in readings.items if r.quaternion is not None][-1]
    assert r.accel == pytest.approx((2.4516625, -4.903325, -7.3549875), rel=1e-15)  # g0 = 9.80665 m/s^2
    assert r.gyro == TRUTH.gyro and r.quaternion == TRUTH.quaternion
    assert r.euler is None
    assert "configured" in events.codes()
    assert not [e for e in events.items if e.level in ("warning", "error")]


def test_decimation_follows_requested_rate(rig) -> None:
    emulator, driver, _, _ = rig(ImuEmulatorConfig(base_rate_hz=500), rate_hz=50.0, orientation="euler")
    assert driver.start()
    assert emulator.decimation == 10  # 500 Hz / 50 Hz
    assert emulator.message_format == (mip.FIELD_ACCEL, mip.FIELD_GYRO, mip.FIELD_EULER)


def test_orientation_nack_falls_back_to_gyro_and_accel(rig, wait_for) -> None:
    emulator, driver, readings, events = rig(ImuEmulatorConfig(orientation_supported=False))
    assert driver.start()
    assert driver.streamed_fields == (mip.FIELD_ACCEL, mip.FIELD_GYRO)
    assert driver.orientation_streamed is None
    nacks = events.with_code("nack")
    assert len(nacks) == 1 and nacks[0].data["nack_code"] == mip.NACK_INVALID_PARAM
    assert nacks[0].source == "imu" and nacks[0].level == "warning"
    assert events.with_code("orientation_unavailable")
    assert emulator.message_format == (mip.FIELD_ACCEL, mip.FIELD_GYRO)
    n = len(readings)
    wait_for(lambda: len(readings) > n + 5, what="readings after fallback")
    assert all(r.quaternion is None for r in readings.items[n:])


def test_checksum_corruption_is_reported_and_stream_recovers(rig, wait_for) -> None:
    emulator, driver, readings, events = rig()
    assert driver.start()
    wait_for(lambda: len(readings) > 3, what="first readings")
    emulator.inject("corrupt")
    wait_for(lambda: events.with_code("checksum"), what="checksum event")
    emulator.clear()
    n = len(readings)
    wait_for(lambda: len(readings) > n + 5, what="readings after the corruption ends")
    e = events.with_code("checksum")[0]
    assert e.source == "imu" and e.t > 0.0
    assert all(r.accel == TRUTH.accel for r in readings.items)  # nothing corrupted got through


def test_silence_is_reported_then_recovery(rig, wait_for) -> None:
    emulator, driver, readings, events = rig()
    assert driver.start()
    wait_for(lambda: len(readings) > 3, what="first readings")
    emulator.inject("silence")
    silence = wait_for(lambda: events.with_code("silence"), what="silence event")
    assert silence[0].level == "error" and silence[0].data["timeout_s"] == 0.3
    emulator.clear()
    recovered = wait_for(lambda: events.with_code("recovered"), what="recovered event")
    assert recovered[0].data["fault"] == "silence"
    assert len(events.with_code("silence")) == 1  # a lasting condition is reported once


def test_invalid_samples_are_dropped_and_reported(rig, wait_for) -> None:
    emulator, driver, readings, events = rig()
    assert driver.start()
    emulator.inject("invalid")
    wait_for(lambda: events.with_code("invalid_data"), what="invalid_data event")
    emulator.clear()
    assert all(all(math.isfinite(v) for v in r.accel) for r in readings.items)


def test_slow_replies_within_timeout_still_configure(rig) -> None:
    emulator, driver, _, events = rig(
        ImuEmulatorConfig(faults=FaultSettings(slow_delay_s=0.1)), command_timeout_s=0.5
    )
    emulator.inject("slow")
    assert driver.start()
    assert not events.with_code("no_reply")


def test_replies_slower_than_the_timeout_are_no_reply(rig) -> None:
    emulator, driver, _, events = rig(
        ImuEmulatorConfig(faults=FaultSettings(slow_delay_s=0.5)), command_timeout_s=0.1,
        command_retries=0,
    )
    emulator.inject("slow")
    assert driver.start() is False
    assert events.with_code("no_reply")


def test_device_that_never_answers(rig) -> None:
    emulator, driver, _, events = rig(command_timeout_s=0.05, command_retries=0)
    emulator.inject("silence")
    assert driver.start() is False
    no_reply = events.with_code("no_reply")
    assert no_reply and no_reply[0].level == "error" and no_reply[0].data["command"] == mip.CMD_IDLE


def test_missing_port_is_an_event_not_an_exception(collector, tmp_path) -> None:
    events = collector()
    driver = ImuDriver(fast_config(str(tmp_path / "no-such-tty")), lambda r: None, events)
    try:
        assert driver.start() is False
    finally:
        driver.stop()
    assert events.with_code("port_error")[0].level == "error"


def test_garbage_written_into_the_line_is_skipped(rig, wait_for) -> None:
    emulator, driver, readings, events = rig()
    assert driver.start()
    wait_for(lambda: len(readings) > 2, what="first readings")
    emulator.send_raw(b"\x13\x37garbage\x75")
    wait_for(lambda: events.with_code("garbage") or events.with_code("checksum"), what="garbage report")
    n = len(readings)
    wait_for(lambda: len(readings) > n + 3, what="readings after garbage")
