"""The EPOS2 driver against emulated nodes on python-can's virtual bus."""

from __future__ import annotations

import math
import os
import threading
import time
import tomllib
import uuid
from typing import Any

import can
import pytest
from support import wait_for

from ucat_console.backend.devices import cia402
from ucat_console.backend.devices.canbus import open_bus
from ucat_console.backend.devices.epos2 import Epos2Config, Epos2Error
from ucat_console.backend.devices.epos2_probe import probe
from ucat_console.backend.devices.fin_drives import FinDrives
from ucat_console.backend.devices.epos2_emulator import (
    Epos2EmulatorConfig,
    start_emulated_nodes,
)
from ucat_console.robot.readings import FinFeedback
from ucat_console.robot.units import DriveUnits
from ucat_console.telemetry.events import Event

# 500 lines, gear 4: 8000 qc per fin turn = 1273.24 qc/rad; 1 rad/s = 38.197 rpm
UNITS = DriveUnits(encoder_lines=500, gear_ratio=4.0)
QC_PER_RAD = 8000 / (2 * math.pi)
HEARTBEAT_MS = 50


def _channel(tag: str) -> str:
    return f"drv-{tag}-{uuid.uuid4().hex[:8]}"


class Recorder:
    def __init__(self) -> None:
        self.feedback: list[FinFeedback] = []
        self.events: list[Event] = []
        self._cv = threading.Condition()

    def on_feedback(self, fb: FinFeedback) -> None:
        with self._cv:
            self.feedback.append(fb)
            self._cv.notify_all()

    def on_event(self, ev: Event) -> None:
        with self._cv:
            self.events.append(ev)
            self._cv.notify_all()

    def wait_event(self, code: str, source: str | None = None) -> Event:
        def find() -> Event | None:
            with self._cv:
                return next((ev for ev in self.events if ev.code == code and (source is None or ev.source == source)),
                            None)

        return wait_for(find, what=f"a {code} event from {source or 'any node'}")


class Rig:
    def __init__(self, node_ids: tuple[int, ...], supervise: bool = True, **overrides) -> None:
        self.channel = _channel("rig")
        self.emulators = start_emulated_nodes(
            self.channel, node_ids, config=Epos2EmulatorConfig(units=UNITS)
        )
        # the emulated nodes answer from Python threads: a busy machine's 1 s, as on the rig
        settings = dict(interface="virtual", channel=self.channel, units=UNITS, sdo_timeout=1.0,
                        heartbeat_ms=HEARTBEAT_MS, node_ids=(11, 12, 13, 14))
        settings.update(overrides)
        self.config = Epos2Config(**settings)
        self.rec = Recorder()
        self.drives = FinDrives(self.config, self.rec.on_feedback, self.rec.on_event,
                                fins=dict(enumerate(node_ids)), supervise=supervise)
        try:
            self.drives.connect()
        except BaseException:
            self.emulators.close()
            raise

    def close(self) -> None:
        self.drives.close()
        self.emulators.close()


def heard_past_now(rig: Rig) -> None:
    """Until the emulated nodes have sent all they were due to send up to now (a tick in
    progress may still send a heartbeat) and the drives' reader has handed on every frame
    sent by then: what the drives know of the nodes is final up to now."""
    now = time.monotonic()  # the emulators' and the drives' clock
    wait_for(lambda: rig.emulators.time >= now, what="the emulators ticked past now")
    sent = time.monotonic()
    wait_for(lambda: rig.drives.heard_until >= sent, what="the bus read up to now")


@pytest.fixture
def rig1():
    r = Rig((21,))
    yield r
    r.close()


@pytest.fixture
def rig2():
    r = Rig((21, 22))
    yield r
    r.close()


# ------------------------------------------------------------------------------ config
def test_bad_node_ids_name_the_key():
    with pytest.raises(ValueError, match=r"node_ids\[2\]"):
        Epos2Config(node_ids=(1, 2, 200, 4))
    with pytest.raises(ValueError, match=r"node_ids\[0\]"):
        Epos2Config(node_ids=(0, 2, 3, 4))
    with pytest.raises(ValueError, match=r"node_ids\[3\]"):
        Epos2Config(node_ids=(1, 2, 3, 1))
    with pytest.raises(ValueError, match=r"node_ids\[1\]"):
        Epos2Config.from_dict({"node_ids": [1, 128, 3, 4]})
    with pytest.raises(ValueError, match="master_heartbeat_id"):
        Epos2Config(master_heartbeat_id=3)
    with pytest.raises(ValueError, match=r"fins\[0\]"):
        FinDrives(Epos2Config(), lambda fb: None, lambda ev: None, fins={0: 128})


def test_bad_bus_settings_name_the_key():
    with pytest.raises(ValueError, match="interface"):
        Epos2Config.from_dict({"interface": "carrier-pigeon"})
    with pytest.raises(ValueError, match="bitrate"):
        Epos2Config(bitrate=123)
    with pytest.raises(ValueError, match="interface"):
        open_bus("carrier-pigeon", "x")
    with pytest.raises(ValueError, match="units.gear_ratio"):
        Epos2Config.from_dict({"units": {"gear_ratio": -1.0}})
    with pytest.raises(ValueError, match="heartbeat_timeout_periods"):
        Epos2Config(heartbeat_timeout_periods=3.5)
    with pytest.raises(ValueError, match="node"):
        probe("virtual", "x", 0, None, 0.1, lambda item: None)


def test_config_toml_round_trip():
    cfg = Epos2Config(interface="virtual", channel="c", node_ids=(5, 6, 7, 8), units=UNITS)
    assert Epos2Config.from_dict(tomllib.loads(cfg.to_toml())) == cfg


def test_state_masks_from_the_spec():
    assert cia402.state_of(0x0021) == "ready_to_switch_on"
    assert cia402.state_of(0x0233) == "switched_on"
    assert cia402.state_of(0x1437) == "operation_enabled"
    assert cia402.state_of(0x0008) == "fault"
    assert cia402.state_of(0x0018) == "fault"
    assert cia402.state_of(0x0040) == "switch_on_disabled"
    assert cia402.state_of(0x0017) == "quick_stop_active"
    assert cia402.emcy_name(0x8611) == "following error"
    assert cia402.emcy_name(0x81FD) == "CAN bus off"
    assert cia402.emcy_name(0xFF03).startswith("device specific")


# ------------------------------------------------------------------------------ start-up
def test_start_up_configures_the_node(rig1):
    emu = rig1.emulators[21]
    assert emu.nmt_state == "OPERATIONAL"
    assert emu.value(0x1017) == HEARTBEAT_MS
    assert emu.value(0x6060) == 1
    # 64 rad/s2 at the fin, gear 4: 64 * 4 * 60 / (2 pi) = 2444.6 rpm/s
    assert emu.value(0x6083) == 2445
    assert emu.value(0x6084) == 2445
    assert emu.value(0x6085) == 4889  # 128 rad/s2
    assert emu.value(0x1A00, 0) == 2
    assert emu.value(0x1A00, 1) == 0x60410010
    assert emu.value(0x1A01, 1) == 0x60640020
    assert emu.value(0x1A01, 2) == 0x606C0020
    assert emu.value(0x1801, 5) == 10  # 100 Hz feedback
    assert emu.value(0x1600, 1) == 0x60400010
    assert emu.value(0x1601, 1) == 0x607A0020
    assert emu.value(0x1601, 2) == 0x60810020
    assert emu.value(0x1402, 1) & 0x80000000  # unused RPDO disabled
    assert emu.value(0x1803, 1) & 0x80000000
    assert rig1.drives.drive(0).uses_rpdo


def test_node_that_never_answers_raises():
    channel = _channel("absent")
    cfg = Epos2Config(interface="virtual", channel=channel, boot_timeout=0.1)
    rec = Recorder()
    drives = FinDrives(cfg, rec.on_feedback, rec.on_event, fins={0: 40})
    with pytest.raises(Epos2Error, match="did not answer"):
        drives.connect()
    assert rec.events[-1].code == "no_answer"
    assert rec.events[-1].source == "epos2.40"


# ------------------------------------------------------------------------------ CiA 402
def test_enable_walks_to_operation_enabled_then_quick_stop_and_disable(rig1):
    emu = rig1.emulators[21]
    drive = rig1.drives.drive(0)
    assert emu.state == "switch_on_disabled"
    assert rig1.drives.enable_all()
    assert emu.controlword_log[-3:] == [0x0006, 0x0007, 0x000F]
    assert emu.statusword & 0x6F == 0x27
    assert drive.state == "operation_enabled"
    assert rig1.drives.quick_stop_all()
    assert emu.controlword_log[-1] == 0x000B
    assert emu.statusword & 0x6F == 0x07
    assert rig1.drives.disable_all()
    assert emu.controlword_log[-1] == 0x0000
    assert emu.statusword & 0x4F == 0x40
    assert rig1.drives.enable_all()
    assert rig1.drives.disable_all()  # shutdown from operation enabled
    assert emu.controlword_log[-1] == 0x0006
    assert emu.statusword & 0x6F == 0x21
    assert not drive.command(0.2, 1.0)  # strokes need operation enabled
    assert rig1.rec.wait_event("command_rejected").data["state"] == "ready_to_switch_on"


# ------------------------------------------------------------------------------ strokes
def _stroke_reaches_target(rig: Rig) -> None:
    emu = rig.emulators[21]
    assert rig.drives.enable_all()
    assert rig.drives.command(0, 0.5, 4.0)
    target_qc = round(0.5 * QC_PER_RAD)  # 636.6 -> 637
    assert target_qc == 637
    assert wait_for(lambda: abs(emu.position_quadcounts - target_qc) <= 1 and emu.statusword & 0x0400)
    assert emu.target_quadcounts == target_qc
    assert emu.value(0x6081) == 153  # 4 rad/s * 4 * 60 / (2 pi) = 152.8 rpm
    # set-point handshake: 0x003F, acknowledge, bit 4 cleared with 0x000F
    i = len(emu.controlword_log) - 1 - emu.controlword_log[::-1].index(0x003F)
    assert emu.controlword_log[i + 1] == 0x000F
    assert not emu.statusword & 0x1000
    # feedback at rest on the target, within one quadcount
    resolution = 1.0 / QC_PER_RAD

    def at_rest_on_target() -> bool:
        fb = rig.rec.feedback[-1]
        return abs(fb.position_rad - 0.5) <= resolution and fb.velocity_rad_s == 0.0

    assert wait_for(at_rest_on_target)
    last = rig.rec.feedback[-1]
    assert isinstance(last, FinFeedback) and last.fin == 0
    assert last.state == "operation_enabled"
    moving = [fb for fb in rig.rec.feedback if fb.velocity_rad_s > 0.0]
    assert moving and max(fb.velocity_rad_s for fb in moving) <= 4.0 + 1 / 38.19  # 1 rpm


def test_stroke_by_rpdo_reaches_the_servo_target(rig1):
    _stroke_reaches_target(rig1)


def test_stroke_by_sdo_fallback_reaches_the_servo_target():
    rig = Rig((21,), setpoint_transport="sdo")
    try:
        assert not rig.drives.drive(0).uses_rpdo
        _stroke_reaches_target(rig)
    finally:
        rig.close()


def test_next_stroke_needs_no_wait(rig1):
    emu = rig1.emulators[21]
    assert rig1.drives.enable_all()
    assert rig1.drives.command(0, 0.3, 6.0)
    assert rig1.drives.command(0, -0.3, 6.0)  # replaces the first set-point immediately
    target_qc = round(-0.3 * QC_PER_RAD)
    assert wait_for(lambda: abs(emu.position_quadcounts - target_qc) <= 1 and emu.statusword & 0x0400)


# ------------------------------------------------------------------------------ faults
def test_emcy_fault_safe_state_and_fault_reset(rig2):
    a, b = rig2.emulators[21], rig2.emulators[22]
    assert rig2.drives.enable_all()
    a.inject_emcy(0x4210)
    emcy = rig2.rec.wait_event("emcy", "epos2.21")
    assert emcy.data["code"] == 0x4210
    assert emcy.data["register"] == 0x09  # generic | temperature
    assert emcy.data["name"] == "overtemperature"
    assert emcy.level == "error"
    fault = rig2.rec.wait_event("fault", "epos2.21")
    assert fault.data["statusword"] & 0x4F == 0x08
    # safe state: the healthy node gets a quick stop
    rig2.rec.wait_event("quick_stop", "epos2.22")
    assert wait_for(lambda: b.statusword & 0x6F == 0x07)
    assert 0x000B in b.controlword_log
    # fault reset from the console: rising edge of bit 7, then operation enabled
    assert rig2.drives.fault_reset(0)
    i = len(a.controlword_log) - 1 - a.controlword_log[::-1].index(0x0080)
    assert a.controlword_log[i - 1] & 0x80 == 0
    assert a.statusword & 0x6F == 0x27
    rig2.rec.wait_event("fault_cleared", "epos2.21")
    rig2.rec.wait_event("emcy_reset", "epos2.21")
    assert rig2.drives.drive(1).enable()  # out of quick stop again
    assert b.statusword & 0x6F == 0x27


def test_malformed_emcy_frame_is_reported(rig1):
    bus = can.Bus(interface="virtual", channel=rig1.channel, ignore_config=True)
    try:
        bus.send(can.Message(arbitration_id=0x80 + 21, data=b"\x10\x23\x03", is_extended_id=False))
        ev = rig1.rec.wait_event("invalid_data", "epos2.21")
        assert ev.data["frame"] == "102303"
    finally:
        bus.shutdown()


def test_a_stopped_heartbeat_is_lost_after_the_configured_periods_and_restored(rig1):
    emu = rig1.emulators[21]
    emu.stop_heartbeat()
    lost = rig1.rec.wait_event("heartbeat_lost", "epos2.21")
    period = HEARTBEAT_MS / 1000.0
    # the configured rule: more than 2 periods heard without one, and never before that
    assert lost.data["silent_for_s"] > 2.0 * period
    assert lost.t - lost.data["last_heartbeat_t"] >= lost.data["silent_for_s"]
    assert rig1.drives.drive(0).heartbeat_lost
    emu.resume_heartbeat()
    rig1.rec.wait_event("heartbeat_restored", "epos2.21")
    assert not rig1.drives.drive(0).heartbeat_lost


@pytest.fixture
def unsupervised_rig():
    r = Rig((21,), supervise=False)
    yield r
    r.close()


def stop_heartbeat(rig: Rig) -> tuple[Any, float, float]:
    """Node 21's heartbeat stopped and every beat before it heard: (its driver, the last
    beat's time, the heartbeat period)."""
    drive = rig.drives.drive(0)
    rig.emulators[21].stop_heartbeat()
    heard_past_now(rig)
    return drive, drive.last_heartbeat_t, HEARTBEAT_MS / 1000.0


def test_heartbeat_rule_on_the_drivers_clock(unsupervised_rig):
    rig = unsupervised_rig
    drive, last, period = stop_heartbeat(rig)
    drive.check(last + 1.9 * period)
    assert not [e for e in rig.rec.events if e.code == "heartbeat_lost"]
    drive.check(last + 2.1 * period)
    drive.check(last + 2.5 * period)
    lost = [e for e in rig.rec.events if e.code == "heartbeat_lost"]
    assert len(lost) == 1
    assert lost[0].data["silent_for_s"] == pytest.approx(2.1 * period)


def test_a_heartbeat_is_missing_only_for_as_long_as_the_reader_has_heard(unsupervised_rig):
    """A busy machine holds the bus's reader back: frames wait unread, a heartbeat among
    them. The silence counts up to what the reader has heard (``heard_until``), not up to
    the present, so however late the check runs, an unheard beat is not a lost one."""
    rig = unsupervised_rig
    drive, last, period = stop_heartbeat(rig)
    # ten periods late by the clock, but heard only 1.9 periods past the last beat
    drive.check(last + 10 * period, heard_until=last + 1.9 * period)
    assert not [e for e in rig.rec.events if e.code == "heartbeat_lost"]
    assert not drive.heartbeat_lost
    drive.check(last + 10 * period, heard_until=last + 2.2 * period)
    lost = [e for e in rig.rec.events if e.code == "heartbeat_lost"]
    assert len(lost) == 1 and lost[0].data["silent_for_s"] == pytest.approx(2.2 * period)


def test_silent_node_is_reported(rig1):
    emu = rig1.emulators[21]
    assert rig1.drives.enable_all()
    emu.silence()
    rig1.rec.wait_event("heartbeat_lost", "epos2.21")
    assert rig1.drives.command(0, 0.4, 2.0)  # sent, but nobody acknowledges
    rig1.rec.wait_event("setpoint_timeout", "epos2.21")
    emu.unsilence()
    rig1.rec.wait_event("heartbeat_restored", "epos2.21")


def test_slow_replies_surface_as_events():
    rig = Rig((21,), sdo_timeout=0.1)
    listener = can.Bus(interface="virtual", channel=rig.channel, ignore_config=True)
    try:
        emu = rig.emulators[21]
        assert rig.drives.drive(0).read_current() == 0.0
        while listener.recv(timeout=0.0) is not None:  # the replies so far
            pass
        emu.slow_replies(0.3)
        assert rig.drives.drive(0).read_current() is None
        ev = rig.rec.wait_event("sdo_timeout", "epos2.21")
        assert ev.level == "warning"
        emu.slow_replies(0.0)

        def late_reply() -> bool:  # it passes before the rig closes
            while (msg := listener.recv(timeout=0.0)) is not None:
                if msg.arbitration_id == 0x580 + 21:
                    return True
            return False

        wait_for(late_reply, what="the late SDO reply")
    finally:
        listener.shutdown()
        rig.close()


def test_master_heartbeat_sets_the_consumer_time():
    rig = Rig((21,), master_heartbeat_id=100, heartbeat_ms=100)
    try:
        # producer 100, consumer time 2 x 100 ms
        assert rig.emulators[21].value(0x1016, 1) == (100 << 16) | 200
        assert rig.drives.enable_all()
        # the console's heartbeat keeps the node out of fault: judged by the node over 1.5
        # consumer times of its own (however late its ticks come on a busy machine)
        enabled = time.monotonic()
        wait_for(lambda: rig.emulators.time >= enabled + 0.3, what="the node ticked 0.3 s on")
        assert rig.emulators[21].state == "operation_enabled"
    finally:
        rig.close()


# ------------------------------------------------------------------------------ probe
def test_probe_streams_feedback_from_an_emulated_node():
    channel = _channel("probe")
    group = start_emulated_nodes(channel, [7])
    items: list[dict] = []
    try:
        assert probe("virtual", channel, 7, None, 0.3, items.append) == 0
        assert group[7].state == "ready_to_switch_on"  # disabled at the end
    finally:
        group.close()
    feedback = [i for i in items if i["kind"] == "feedback"]
    assert len(feedback) >= 10  # 100 Hz for 0.3 s
    assert set(feedback[-1]) == {"kind", "t", "position_rad", "velocity_rad_s", "state"}
    assert "operation_enabled" in {i["state"] for i in feedback}
    assert all(i["t"] >= 0.0 for i in items)


def test_probe_reports_a_missing_node():
    items: list[dict] = []
    assert probe("virtual", _channel("probe-none"), 9, None, 0.1, items.append) == 1
    assert items[-1]["kind"] == "fault" and "did not answer" in items[-1]["reason"]


# ------------------------------------------------------------------------------ robot bus
@pytest.mark.skipif(not os.path.exists("/sys/class/net/can0"), reason="no can0 on this machine")
def test_socketcan_can0_opens():
    bus = open_bus("socketcan", "can0", 1_000_000)
    try:
        assert "can0" in bus.channel_info
    finally:
        bus.shutdown()


def test_unexpected_bootup_is_reported_and_restart_recovers(rig1):
    emu = rig1.emulators[21]
    assert rig1.drives.enable_all()
    bus = can.Bus(interface="virtual", channel=rig1.channel, ignore_config=True)
    try:
        bus.send(can.Message(arbitration_id=0x000, data=bytes([0x81, 21]), is_extended_id=False))
    finally:
        bus.shutdown()
    ev = rig1.rec.wait_event("bootup", "epos2.21")
    assert ev.level == "error"
    assert not rig1.drives.drive(0).started
    assert emu.state == "switch_on_disabled"  # reset node: application reset
    rig1.drives.restart(0)
    assert rig1.drives.enable_all()
    assert emu.statusword & 0x6F == 0x27


def test_drive_without_event_timer_falls_back_to_on_change_feedback():
    from canopen.sdo import SdoAbortedError

    channel = _channel("no-timer")
    group = start_emulated_nodes(channel, [21], config=Epos2EmulatorConfig(units=UNITS))

    def refuse_event_timer(index, subindex, od, data):
        if 0x1800 <= index <= 0x1803 and subindex == 5:
            raise SdoAbortedError(0x06090011)  # sub-index does not exist

    group[21].node.add_write_callback(refuse_event_timer)
    rec = Recorder()
    cfg = Epos2Config(interface="virtual", channel=channel, units=UNITS, node_ids=(11, 12, 13, 14),
                      sdo_timeout=1.0)
    drives = FinDrives(cfg, rec.on_feedback, rec.on_event, fins={0: 21})
    try:
        drives.connect()
        refused = [e for e in rec.events if e.code == "no_event_timer"]
        assert len(refused) == 3  # TPDO1, TPDO2 and TPDO3 (current and supply voltage)
        assert all(e.data["abort_code"] == 0x06090011 for e in refused)
        assert group[21].value(0x1801, 3) == 100  # inhibit time 10 ms in 100 us units
        assert group[21].value(0x1802, 3) == 200  # 20 ms: the electrical period
        assert drives.enable_all()
    finally:
        drives.close()
        group.close()


# ------------------------------------------------------------------------------ electrical input
class _LoadedServo:
    """A still servo with a fixed motor current (A), or none it knows."""

    def __init__(self, amps: float | None = None) -> None:
        if amps is not None:
            self.current = lambda: amps

    def command(self, target_rad: float, profile_velocity_rad_s: float) -> None:
        pass

    def state(self) -> tuple[float, float]:
        return 0.0, 0.0

    def step(self, dt: float) -> None:
        pass


def _sdo_upload(bus: can.BusABC, node: int, index: int, sub: int) -> bytes:
    """The raw reply of an expedited SDO upload of ``index:sub`` from ``node``."""
    while bus.recv(timeout=0.0) is not None:
        pass  # older frames
    bus.send(can.Message(arbitration_id=0x600 + node, is_extended_id=False,
                         data=bytes([0x40, index & 0xFF, index >> 8, sub, 0, 0, 0, 0])))
    deadline = time.monotonic() + 2.0
    while time.monotonic() < deadline:
        msg = bus.recv(timeout=0.1)
        if msg is not None and msg.arbitration_id == 0x580 + node \
                and bytes(msg.data[1:4]) == bytes([index & 0xFF, index >> 8, sub]):
            return bytes(msg.data)  # (the driver's own replies pass by on this bus too)
    raise AssertionError(f"no SDO reply from node {node} for 0x{index:04X}:{sub}")


def test_current_and_voltage_frames_are_the_epos2s_and_the_driver_reads_them():
    """0x2027 (INT16 mA) and 0x2200 sub 1 (UINT16, 0.1 V) by SDO, byte for byte, then through
    the driver: a fixed 1.234 A at 23.7 V. (The round's thread runs in test_rig's closed loop.)"""
    channel = _channel("elec")
    emulators = start_emulated_nodes(channel, (21,), lambda node: _LoadedServo(amps=1.234),
                                     config=Epos2EmulatorConfig(units=UNITS, supply_voltage=23.7))
    raw = can.Bus(interface="virtual", channel=channel, ignore_config=True)
    cfg = Epos2Config(interface="virtual", channel=channel, units=UNITS, sdo_timeout=1.0,
                      heartbeat_ms=HEARTBEAT_MS)
    rec = Recorder()
    drives = FinDrives(cfg, rec.on_feedback, rec.on_event, fins={0: 21})
    try:
        drives.connect()
        assert drives.enable_all()
        emu = emulators[21]
        # the averaged current settles on the motor current (1234 mA = 0x04D2)
        wait_for(lambda: emu.value(0x2027) == 1234, what="the emulated current")
        def settled() -> tuple | None:  # one round, by fin (its TPDO3 may be from before the settling)
            [(fin, reading)] = drives.read_electrical().items()
            return (fin, reading) if reading is not None and abs(reading.current_a - 1.234) < 1e-9 else None

        fin, reading = wait_for(settled, what="the settled current read")
        assert fin == 0 and reading.fin == 0
        assert reading.current_a == pytest.approx(1.234, abs=1e-12)
        assert reading.voltage_v == pytest.approx(23.7, abs=1e-12)

        assert _sdo_upload(raw, 21, 0x2027, 0) == bytes([0x4B, 0x27, 0x20, 0x00, 0xD2, 0x04, 0, 0])
        # 23.7 V = 237 x 0.1 V = 0x00ED
        assert _sdo_upload(raw, 21, 0x2200, 1) == bytes([0x4B, 0x00, 0x22, 0x01, 0xED, 0x00, 0, 0])
    finally:
        drives.close()
        raw.shutdown()
        emulators.close()


def test_emulated_current_is_the_servo_s_or_the_no_load_current_and_none_without_power_stage():
    """A servo that knows its motor's current (the simulated rig's plant) gives it; one that
    does not leaves the no-load current (0.05 A); 0 A with the power stage off."""
    channel = _channel("shaft")
    group = start_emulated_nodes(channel, (21, 22), lambda node: _LoadedServo(amps=2.05 if node == 21 else None),
                                 config=Epos2EmulatorConfig(units=UNITS), run_thread=False)
    try:
        emu, idle = group[21], group[22]
        group.tick(0.0)
        assert emu.motor_current() == 0.0
        assert emu.value(0x6078) == 0
        emu._state = idle._state = cia402.OPERATION_ENABLED  # the state machine itself is tested elsewhere
        assert emu.motor_current() == pytest.approx(2.05)
        assert emu.value(0x6078) == 2050
        assert idle.motor_current() == pytest.approx(0.05)
        for k in range(1, 201):  # 0.2 s of 1 ms ticks: 20 time constants
            group.tick(k * 1e-3)
        assert emu.value(0x2027) == 2050
    finally:
        group.close()


def test_the_electrical_tpdo_is_the_epos2s_and_brings_a_sagging_supply_at_once():
    """TPDO3 (0x380 + node): 0x2027 (INT16 mA) then 0x2200 sub 1 (UINT16 0.1 V), byte for
    byte as the drive maps them, every electrical period; the driver's reading is the last
    one, stamped on arrival, without an SDO request (the node's SDO replies held back for
    longer than the test waits); a node that stops sending gives no reading (SDO then, which
    it does not answer either)."""
    channel = _channel("tpdo3")
    emulators = start_emulated_nodes(channel, (21,), lambda node: _LoadedServo(amps=1.234),
                                     config=Epos2EmulatorConfig(units=UNITS, supply_voltage=23.7))
    raw = can.Bus(interface="virtual", channel=channel, ignore_config=True)
    cfg = Epos2Config(interface="virtual", channel=channel, units=UNITS, sdo_timeout=1.0,
                      heartbeat_ms=HEARTBEAT_MS, electrical_period_ms=20)
    rec = Recorder()
    drives = FinDrives(cfg, rec.on_feedback, rec.on_event, fins={0: 21})
    try:
        drives.connect()
        assert drives.enable_all()
        emu = emulators[21]
        wait_for(lambda: emu.value(0x2027) == 1234, what="the emulated current")

        def tpdo3() -> bool:  # 1234 mA = 0x04D2, then 237 x 0.1 V = 0x00ED (older ones: the current settling)
            msg = raw.recv(timeout=0.1)
            return msg is not None and msg.arbitration_id == 0x380 + 21 and \
                bytes(msg.data) == bytes([0xD2, 0x04, 0xED, 0x00])

        wait_for(tpdo3, what="the TPDO3 of 1.234 A at 23.7 V from the node")
        emu.slow_replies(30.0)  # from now on, what the driver reads comes by PDO
        emu.set_supply_voltage(20.0)
        reading = wait_for(lambda: (r := drives.drive(0).read_electrical()) is not None and r.voltage_v < 23
                           and r, what="the sagging supply read")
        assert reading.voltage_v == pytest.approx(20.0, abs=1e-12)
        assert reading.current_a == pytest.approx(1.234, abs=1e-12)
        assert not [e for e in rec.events if e.code.startswith("sdo")]
        emu.slow_replies(0.0)
        emu.silence()
        assert wait_for(lambda: drives.drive(0).read_electrical() is None, what="no reading from a silent node")
    finally:
        drives.close()
        raw.shutdown()
        emulators.close()


def test_a_node_that_does_not_answer_gives_no_electrical_reading_and_one_event():
    """By SDO (no electrical TPDO: ``electrical_period_ms`` 0, as for a node that refuses it)."""
    rig = Rig((21,), sdo_timeout=0.1, electrical_period_ms=0)
    try:
        emu = rig.emulators[21]
        emu.slow_replies(0.3)
        assert rig.drives.drive(0).read_electrical() is None
        assert rig.drives.drive(0).read_electrical() is None
        ev = rig.rec.wait_event("sdo_timeout", "epos2.21")
        assert ev.level == "warning" and "current and voltage" in ev.message
        assert sum(e.code == "sdo_timeout" for e in rig.rec.events) == 1  # throttled
        emu.slow_replies(0.0)
        time.sleep(0.4)  # the late replies pass
    finally:
        rig.close()
