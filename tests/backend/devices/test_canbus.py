"""How far a CAN reader has heard (``canbus.HeardBus``): up to the arrival of the last frame
it handed on (frames are read in arrival order), or, when nothing came, up to the read's
start as far as the devices on the bus had run."""

from __future__ import annotations

import math
import time
import uuid

import can
import pytest

from ucat_console.backend.devices.canbus import HeardBus, arrival_time, open_bus


@pytest.fixture
def channel() -> str:
    return f"heard-{uuid.uuid4().hex[:8]}"


def test_a_frames_arrival_is_its_stamp_on_the_readers_clock() -> None:
    assert arrival_time(1000.0, now=50.0, wall=1000.25) == 50.0 - 0.25
    # a stamp from the future or from another clock counts as arriving when read
    assert arrival_time(1000.5, now=50.0, wall=1000.0) == 50.0
    assert arrival_time(0.0, now=50.0, wall=1000.0) == 50.0


def test_the_reader_has_heard_up_to_the_last_frame_it_handed_on(channel: str) -> None:
    clock = [100.0]
    bus = HeardBus(open_bus("virtual", channel), clock=lambda: clock[0])
    sender = open_bus("virtual", channel, stamped=True)
    try:
        wall = time.time()
        # two frames waited unread: they arrived 0.3 s and 0.1 s before they are read
        sender.send(can.Message(arbitration_id=0x715, data=b"\x05", is_extended_id=False, timestamp=wall - 0.3))
        sender.send(can.Message(arbitration_id=0x295, data=b"", is_extended_id=False, timestamp=wall - 0.1))
        assert bus.recv(1.0).arbitration_id == 0x715
        assert bus.heard_until == -math.inf  # read, but not handed on yet
        assert bus.recv(1.0).arbitration_id == 0x295
        # handed on: it arrived 0.3 s (and the time since) before clock[0]
        first = bus.heard_until
        assert 100.0 - 0.3 - 5.0 < first <= 100.0 - 0.3
        clock[0] = 101.0
        assert bus.recv(0.01) is None  # nothing more came: heard up to the present
        assert bus.heard_until == 101.0
    finally:
        bus.shutdown()
        sender.shutdown()


def test_an_empty_read_hears_only_as_far_as_the_in_process_devices_have_run(channel: str) -> None:
    """The emulated drives of the simulated rig run in this process: when a busy machine
    held them back, the bus is quiet because they have not run, not because they are gone."""
    bus = HeardBus(open_bus("virtual", channel), clock=lambda: 100.0, bus_time=lambda: 99.2)
    try:
        assert bus.recv(0.01) is None
        assert bus.heard_until == 99.2
    finally:
        bus.shutdown()
