"""The shared fault description: activation, expiry and clearing, on a fake clock."""

from __future__ import annotations

import pytest
from support import FakeClock

from ucat_console.backend.devices.faults import Fault, FaultSet, FaultSettings, as_fault
from ucat_console.backend.devices.reporting import EventReporter


def test_fault_expires_after_its_duration() -> None:
    clock = FakeClock(100.0)
    faults = FaultSet(clock)
    faults.inject("silence", duration=2.0)
    faults.inject(Fault.CORRUPT)
    assert faults.snapshot() == {Fault.SILENCE, Fault.CORRUPT}
    clock.now = 101.9
    assert faults.active(Fault.SILENCE)
    clock.now = 102.0
    assert not faults.active("silence")
    assert faults.active("corrupt")  # no duration: until cleared
    faults.clear("corrupt")
    assert faults.snapshot() == frozenset()


def test_clear_all_and_bad_names() -> None:
    faults = FaultSet(FakeClock(100.0))
    faults.inject("slow")
    faults.inject("invalid")
    faults.clear()
    assert not faults.snapshot()
    with pytest.raises(ValueError, match="fault: 'melt'"):
        as_fault("melt")
    with pytest.raises(ValueError, match="duration"):
        faults.inject("slow", duration=0.0)
    with pytest.raises(ValueError, match="slow_delay_s"):
        FaultSettings(slow_delay_s=-1.0)


def test_reporter_throttles_and_reports_conditions_on_edges() -> None:
    clock = FakeClock(100.0)
    events = []
    rep = EventReporter("imu", events.append, clock, min_interval_s=1.0)
    assert rep.throttled("checksum", "bad")
    assert not rep.throttled("checksum", "bad")
    assert not rep.throttled("checksum", "bad")
    clock.now += 1.0
    assert rep.throttled("checksum", "bad")
    assert events[-1].data["suppressed"] == 2 and events[-1].t == 101.0
    rep.condition("silence", True, "quiet", "error")
    rep.condition("silence", True, "quiet", "error")
    rep.condition("silence", False, "back")
    assert [e.code for e in events[2:]] == ["silence", "recovered"]
    assert events[-1].data["fault"] == "silence" and events[-1].level == "info"


def test_reporter_survives_a_failing_sink() -> None:
    def broken(event):
        raise RuntimeError("sink down")

    EventReporter("dvl", broken, FakeClock(100.0)).emit("silence", "quiet")  # must not raise


def test_an_in_process_device_is_silent_only_for_as_long_as_it_has_run() -> None:
    """An emulator held back by a busy machine has not sent its samples yet: the reader's
    silence runs up to the device's time at its latest read, not up to the present."""
    from ucat_console.backend.devices.reporting import SilenceWatch

    clock = FakeClock(100.0)
    device = [100.0]
    events = []
    watch = SilenceWatch(EventReporter("imu", events.append, clock), clock, 0.5, "packet", "packets",
                         device_time=lambda: device[0])
    watch.reset()
    clock.now = 101.5  # the reader looks 1.5 s later, but the device ran only 0.4 s of it
    device[0] = 100.4
    watch.reading()
    assert watch.check() == pytest.approx(0.4) and not events
    device[0] = 100.6  # the device ran on and sent nothing: silent
    clock.now = 101.6
    watch.reading()
    assert watch.check() == pytest.approx(0.6)
    assert [e.code for e in events] == ["silence"]
    # without a device time (the robot's own devices), the present counts
    plain = SilenceWatch(EventReporter("imu", events.append, clock), clock, 0.5, "packet", "packets")
    plain.reset()
    clock.now += 0.7
    plain.reading()
    assert plain.check() == pytest.approx(0.7)
