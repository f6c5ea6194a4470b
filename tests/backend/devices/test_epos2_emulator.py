"""The EPOS2 emulator against a plain canopen master (SDO, NMT, PDO) on the virtual bus.

The master here is canopen's own RemoteNode / BaseNode402, not the project's driver, so
these tests check the emulator's CiA 402 behaviour independently of the driver.
"""

from __future__ import annotations

import time
import uuid

import can
import canopen
import pytest
from support import FakeClock, wait_for
from canopen.profiles.p402 import BaseNode402
from canopen.sdo import SdoCommunicationError

from ucat_console.backend.devices.epos2 import EDS_PATH
from ucat_console.backend.devices.epos2_emulator import (
    Epos2Emulator,
    Epos2EmulatorConfig,
    TrapezoidalServo,
    start_emulated_nodes,
)
from ucat_console.robot.units import DriveUnits

NODE = 5
UNITS = DriveUnits(encoder_lines=512, gear_ratio=1.0)  # 2048 qc per turn


def _channel(tag: str) -> str:
    return f"emu-{tag}-{uuid.uuid4().hex[:8]}"


class _Master:
    """canopen master on its own virtual bus, plus a raw listener for frame counting."""

    def __init__(self, channel: str, node_cls=canopen.RemoteNode) -> None:
        self.network = canopen.Network(
            can.Bus(interface="virtual", channel=channel, ignore_config=True)
        )
        self.network.NOTIFIER_CYCLE = 0.1
        self.network.connect()
        self.node = node_cls(NODE, str(EDS_PATH))
        self.network.add_node(self.node)
        self.node.sdo.RESPONSE_TIMEOUT = 0.5
        self.frames: list[tuple[int, bytes]] = []
        self.raw = can.Bus(interface="virtual", channel=channel, ignore_config=True)

    def drain(self) -> list[can.Message]:
        out = []
        while (msg := self.raw.recv(timeout=0.0)) is not None:
            out.append(msg)
        return out

    def sw(self) -> int:
        return self.node.sdo[0x6041].raw

    def cw(self, value: int) -> None:
        self.node.sdo[0x6040].raw = value

    def close(self) -> None:
        self.raw.shutdown()
        self.network.disconnect()


@pytest.fixture
def tick_rig():
    """Emulator ticked by the test (no thread) and a canopen master."""
    channel = _channel("tick")
    group = start_emulated_nodes(channel, [NODE], config=Epos2EmulatorConfig(units=UNITS),
                                 run_thread=False)
    master = _Master(channel)
    yield group[NODE], master
    master.close()
    group.close()


def _to_operation_enabled(m: _Master) -> None:
    for cw in (0x06, 0x07, 0x0F):
        m.cw(cw)
    assert m.sw() & 0x6F == 0x27


# ------------------------------------------------------------------------------ servo model
def test_trapezoidal_servo_profile_hand_computed():
    # a = 10 rad/s2, v = 2 rad/s, 1 rad: 0.2 s ramp (0.2 rad), 0.3 s cruise (0.6 rad),
    # 0.2 s braking (0.2 rad): at the target after 0.7 s
    servo = TrapezoidalServo(acceleration=10.0, max_rate=50.0)
    servo.command(1.0, 2.0)
    prev_v, peak = 0.0, 0.0
    for _ in range(350):
        servo.step(0.001)
        _, v = servo.state()
        assert abs(v - prev_v) <= 10.0 * 0.001 + 1e-9  # acceleration limit
        prev_v, peak = v, max(peak, v)
    x, v = servo.state()
    assert x == pytest.approx(0.2 + 2.0 * 0.15, abs=0.01)  # mid-cruise at 0.35 s
    assert v == pytest.approx(2.0, abs=1e-9)
    servo.step(0.40)
    assert servo.state() == (1.0, 0.0)
    assert peak <= 2.0 + 1e-9


def test_trapezoidal_servo_caps_rate_and_quantises():
    servo = TrapezoidalServo(acceleration=1000.0, max_rate=3.0, resolution_rad=0.01)
    servo.command(10.0, 8.0)
    servo.step(0.5)
    x, v = servo.state()
    assert v == pytest.approx(3.0)
    assert round(x / 0.01) * 0.01 == pytest.approx(x)
    servo2 = TrapezoidalServo(resolution_rad=0.01, position=0.123)
    assert servo2.state()[0] == pytest.approx(0.12)


# ------------------------------------------------------------------------------ CiA 402
def test_every_state_transition_by_controlword(tick_rig):
    emu, m = tick_rig
    assert m.sw() & 0x4F == 0x40  # switch on disabled after boot
    m.cw(0x06)
    assert m.sw() & 0x6F == 0x21  # ready to switch on
    m.cw(0x07)
    assert m.sw() & 0x6F == 0x23  # switched on
    m.cw(0x0F)
    assert m.sw() & 0x6F == 0x27  # operation enabled
    m.cw(0x07)
    assert m.sw() & 0x6F == 0x23  # disable operation -> switched on
    m.cw(0x0F)
    m.cw(0x06)
    assert m.sw() & 0x6F == 0x21  # shutdown from operation enabled
    m.cw(0x07)
    m.cw(0x0F)
    m.cw(0x0B)
    assert m.sw() & 0x6F == 0x07  # quick stop active
    m.cw(0x0F)
    assert m.sw() & 0x6F == 0x27  # back to operation enabled from quick stop
    m.cw(0x0B)
    m.cw(0x00)
    assert m.sw() & 0x4F == 0x40  # disable voltage from quick stop
    m.cw(0x06)
    m.cw(0x07)
    m.cw(0x00)
    assert m.sw() & 0x4F == 0x40  # disable voltage from switched on


def test_fault_emcy_and_fault_reset_edge(tick_rig):
    emu, m = tick_rig
    frames: list[bytes] = []
    m.network.subscribe(0x80 + NODE, lambda cob, data, ts: frames.append(bytes(data)))
    _to_operation_enabled(m)
    emu.inject_emcy(0x2310)
    assert m.sw() & 0x4F == 0x08  # fault
    # EMCY: code 0x2310 little-endian, register generic (bit 0) | current (bit 1) = 0x03
    assert frames and frames[0][:3] == bytes([0x10, 0x23, 0x03])
    assert m.node.sdo[0x1001].raw == 0x03
    m.cw(0x0F)
    assert m.sw() & 0x4F == 0x08  # no way out but a fault reset
    m.cw(0x80)
    assert m.sw() & 0x4F == 0x40  # rising edge of bit 7 -> switch on disabled
    assert m.node.sdo[0x1001].raw == 0
    assert frames[-1][:2] == b"\x00\x00"  # EMCY error reset
    emu.inject_emcy(0xFF01)
    m.cw(0x80)  # bit 7 was already high: no edge, still in fault
    assert m.sw() & 0x4F == 0x08
    m.cw(0x00)
    m.cw(0x80)
    assert m.sw() & 0x4F == 0x40
    assert frames[-2][:3] == bytes([0x01, 0xFF, 0x81])  # device specific: bits 0 and 7


def test_profile_position_setpoint_ack_and_target_reached(tick_rig):
    emu, m = tick_rig
    m.node.sdo[0x6060].raw = 1
    assert m.node.sdo[0x6061].raw == 1
    m.node.sdo[0x6083].raw = 6000
    m.node.sdo[0x6084].raw = 6000
    _to_operation_enabled(m)
    assert m.sw() & 0x0400  # holding still: target reached
    m.node.sdo[0x607A].raw = 1000
    m.node.sdo[0x6081].raw = 120  # 120 rpm = 12.57 rad/s at gear 1
    m.cw(0x3F)
    sw = m.sw()
    assert sw & 0x1000  # set-point acknowledge
    assert not sw & 0x0400  # target not reached yet
    m.cw(0x0F)
    assert not m.sw() & 0x1000  # acknowledge follows bit 4 down
    now = 0.0
    for _ in range(1000):  # one simulated second in 1 ms ticks
        emu.tick(now)
        now += 0.001
    assert abs(m.node.sdo[0x6064].raw - 1000) <= 1
    assert m.node.sdo[0x606C].raw == 0
    assert m.sw() & 0x0400
    # relative move (bit 6): 500 qc further
    m.node.sdo[0x607A].raw = 500
    m.cw(0x7F)
    m.cw(0x4F)
    for _ in range(1000):
        emu.tick(now)
        now += 0.001
    assert abs(m.node.sdo[0x6064].raw - 1500) <= 1


def test_tpdo_rate_follows_the_event_timer(tick_rig):
    emu, m = tick_rig
    m.node.nmt.state = "OPERATIONAL"
    m.node.sdo[0x6041].raw  # round trip: the NMT command has been handled
    m.drain()
    for k in range(1001):  # 0 .. 1.000 s in 1 ms ticks
        emu.tick(k / 1000.0)
    frames = m.drain()
    feedback = [f for f in frames if f.arbitration_id == 0x280 + NODE]
    # event timer 10 ms (EDS default): frames at 0, 10, ..., 1000 ms -> 101
    assert abs(len(feedback) - 101) <= 1
    assert all(len(f.data) == 8 for f in feedback)
    status = [f for f in frames if f.arbitration_id == 0x180 + NODE]
    assert abs(len(status) - 101) <= 1
    assert len(status[0].data) == 3  # statusword (16 bit) + mode display (8 bit)


def test_no_pdos_outside_operational(tick_rig):
    emu, m = tick_rig
    m.drain()
    for k in range(100):
        emu.tick(k / 1000.0)
    assert not [f for f in m.drain() if f.arbitration_id in (0x180 + NODE, 0x280 + NODE)]


def test_rpdo_writes_reach_the_object_dictionary(tick_rig):
    emu, m = tick_rig
    m.node.sdo[0x6060].raw = 1
    m.node.rpdo.read()
    m.node.nmt.state = "OPERATIONAL"
    m.node.sdo[0x6041].raw
    m.node.rpdo[2]["Target position"].raw = -1234
    m.node.rpdo[2]["Profile velocity"].raw = 77
    m.node.rpdo[2].transmit()
    for cw in (0x06, 0x07, 0x0F):
        m.node.rpdo[1]["Controlword"].raw = cw
        m.node.rpdo[1].transmit()
    assert m.node.sdo[0x607A].raw == -1234
    assert m.node.sdo[0x6081].raw == 77
    assert m.sw() & 0x6F == 0x27


def test_heartbeat_consumer_faults_with_life_guard_emcy():
    channel = _channel("lifeguard")
    now = [100.0]
    emu = Epos2Emulator(channel, NODE, config=Epos2EmulatorConfig(units=UNITS),
                        clock=lambda: now[0])
    m = _Master(channel)
    frames: list[bytes] = []
    m.network.subscribe(0x80 + NODE, lambda cob, data, ts: frames.append(bytes(data)))
    try:
        m.node.sdo[0x1016][1].raw = (0x7E << 16) | 100  # master 0x7E, 100 ms
        m.network.send_message(0x700 + 0x7E, bytes([5]))
        m.sw()  # ordered bus: the heartbeat was handled before this reply
        now[0] += 0.09
        emu.tick(now[0])
        assert emu.state != "fault"
        now[0] += 0.02  # 110 ms since the last master heartbeat
        emu.tick(now[0])
        assert m.sw() & 0x4F == 0x08
        # 0x8130, register generic | communication = 0x11
        assert frames[-1][:3] == bytes([0x30, 0x81, 0x11])
    finally:
        m.close()
        emu.close()


def test_reset_communication_restores_defaults_and_sends_bootup(tick_rig):
    emu, m = tick_rig
    m.node.sdo[0x1017].raw = 30
    m.node.sdo[0x1A01][0].raw = 0
    m.drain()
    m.node.nmt.send_command(0x82)
    m.sw()
    frames = m.drain()
    assert any(f.arbitration_id == 0x700 + NODE and bytes(f.data) == b"\x00" for f in frames)
    assert m.node.sdo[0x1017].raw == 0
    assert m.node.sdo[0x1A01][0].raw == 2


def test_silence_and_slow_replies():
    """The node ticked by the test on its own clock: what it sends in a stretch of its time
    is sent when the test ticks, whatever the machine's speed."""
    channel = _channel("silence")
    clock = FakeClock(100.0)
    group = start_emulated_nodes(channel, [NODE], config=Epos2EmulatorConfig(units=UNITS),
                                 run_thread=False, clock=clock)
    m = _Master(channel)
    emu = group[NODE]

    def heartbeats() -> list[can.Message]:
        return [f for f in m.drain() if f.arbitration_id == 0x700 + NODE]

    try:
        m.node.sdo[0x1017].raw = 20
        group.tick(clock.advance(0.001))
        assert heartbeats()  # beating
        emu.silence()
        m.node.sdo.RESPONSE_TIMEOUT = 0.1
        with pytest.raises(SdoCommunicationError):
            m.sw()
        group.tick(clock.advance(0.06))  # three periods silent
        assert not heartbeats()
        emu.unsilence()
        assert m.sw() & 0x4F == 0x40
        group.tick(clock.advance(0.06))
        assert heartbeats()
        emu.slow_replies(0.25)
        with pytest.raises(SdoCommunicationError):
            m.sw()
        # let the late reply pass before the next request
        wait_for(lambda: [f for f in m.drain() if f.arbitration_id == 0x580 + NODE], what="the late SDO reply")
        m.node.sdo.RESPONSE_TIMEOUT = 1.0
        assert m.sw() & 0x4F == 0x40
        emu.slow_replies(0.0)
    finally:
        m.close()
        group.close()


def test_canopen_p402_master_reaches_operation_enabled():
    """canopen's own CiA 402 helper (setup_pdos(upload=True) needs a known NMT state)."""
    channel = _channel("p402")
    group = start_emulated_nodes(channel, [NODE], config=Epos2EmulatorConfig(units=UNITS))
    m = _Master(channel, node_cls=BaseNode402)
    try:
        m.node.sdo[0x1017].raw = 20
        m.node.nmt.wait_for_heartbeat(timeout=1.0)
        assert m.node.nmt.state == "PRE-OPERATIONAL"
        m.node.setup_402_state_machine(read_pdos=True)
        m.node.nmt.state = "OPERATIONAL"
        wait_for(lambda: group[NODE].nmt_state == "OPERATIONAL", what="the node operational")
        m.node.op_mode = "PROFILED POSITION"
        assert m.node.op_mode == "PROFILED POSITION"
        m.node.state = "OPERATION ENABLED"
        assert m.node.statusword & 0x6F == 0x27
        assert group[NODE].state == "operation_enabled"
    finally:
        m.close()
        group.close()


def test_a_late_tick_sends_the_heartbeat_it_owed_once_stamped_when_due_and_before_its_pdos():
    """A tick held back by a busy machine: the drive would have sent its heartbeat on time,
    so the emulator sends the latest one it owed (not a burst of them), stamped with the
    time it was due, and before the frames of the tick's own time: a reader takes frames in
    that order and never sees a later frame before the heartbeat that came earlier."""
    channel = _channel("beat")
    now = [50.0]
    group = start_emulated_nodes(channel, [NODE], config=Epos2EmulatorConfig(units=UNITS),
                                 run_thread=False, clock=lambda: now[0])
    m = _Master(channel)
    try:
        m.node.sdo[0x1017].raw = 100  # heartbeat every 100 ms
        m.node.nmt.state = "OPERATIONAL"
        m.node.sdo[0x6041].raw  # round trip: the NMT command has been handled
        group.tick(now[0])  # the first heartbeat, due at once
        assert [f for f in m.drain() if f.arbitration_id == 0x700 + NODE]
        now[0] += 0.35  # the next tick comes 3.5 periods later
        before = time.time()
        group.tick(now[0])
        after = time.time()
        frames = m.drain()
        beats = [i for i, f in enumerate(frames) if f.arbitration_id == 0x700 + NODE]
        pdos = [i for i, f in enumerate(frames) if f.arbitration_id in (0x180 + NODE, 0x280 + NODE)]
        assert len(beats) == 1 and pdos and beats[0] < min(pdos)
        assert bytes(frames[beats[0]].data) == bytes([0x05])  # operational
        # due 0.3 s after the first: 0.05 s before the tick that sent it
        assert before - 0.05 <= frames[beats[0]].timestamp <= after - 0.05
        assert group.time == now[0]
    finally:
        m.close()
        group.close()
