"""The robot behind the closed loop: in-process simulator, simulated rig through the drivers,
drivers on configured endpoints; fault injection; start-up errors naming the key."""

from __future__ import annotations

import math
import threading
import tomllib
import uuid
from types import SimpleNamespace
from typing import Any

import pytest
from support import Collector, wait_for

from ucat_console import shipped
from ucat_console.backend.devices.config import DevicesConfig, SimStartConfig
from ucat_console.backend.devices.device_robot_io import DeviceRobotIO, DeviceTime
from ucat_console.backend.devices.dvl import DvlConfig
from ucat_console.backend.devices.dvl_emulator import DvlEmulator
from ucat_console.backend.devices.epos2 import Epos2Config
from ucat_console.backend.devices.epos2_emulator import Epos2EmulatorConfig, start_emulated_nodes
from ucat_console.backend.devices.imu import ImuConfig
from ucat_console.backend.devices.imu_emulator import ImuEmulator
from ucat_console.backend.devices.pressure import PressureConfig
from ucat_console.backend.devices.pressure_emulator import PressureEmulator
from ucat_console.robot.motor import FinMotor
from ucat_console.robot.readings import DepthReading, DvlVelocity, FinFeedback, ImuReading
from ucat_console.robot.units import DriveUnits
from ucat_console.backend.loop.clock import PacedClock
from ucat_console.backend.loop.closed_loop import ClosedLoop
from ucat_console.backend.loop.config import LoopConfig
from ucat_console.backend.sim_robot_io import SimRobotIO
from ucat_console.backend.rig import connect_events, rig_of
from ucat_console.backend.robots import build_robot_io
from ucat_console.cli.devices import synthetic_depth, synthetic_dvl, synthetic_imu
from ucat_console.control.allocation import BodySetpoints
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.stream import TelemetryStream

# the plant's encoder: 512 lines, gear 35 -> 71680 qc per fin turn
UNITS = DriveUnits(encoder_lines=512, gear_ratio=35.0)
START_DEPTH = 1.0
SETPOINTS = BodySetpoints(velocity=0.3, depth=1.5)


def sim_devices_config(**changes: Any) -> DevicesConfig:
    """The rig with the plant's drive units and heartbeats lost after 0.5 s (a busy machine
    can hold the emulators' threads back for a few hundred milliseconds) unless changed."""
    blocks: dict[str, Any] = dict(
        epos2=Epos2Config(units=UNITS, heartbeat_ms=200, heartbeat_timeout_periods=2.5),
        start=SimStartConfig(depth=START_DEPTH, seed=7),
    )
    return DevicesConfig(enable_at_start=True, **{**blocks, **changes})


class LoopThread:
    """A closed loop on the paced clock in its own thread, recording any exception."""

    def __init__(self, loop: ClosedLoop, duration: float) -> None:
        self.loop = loop
        self.error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, args=(duration,), daemon=True)
        self._thread.start()

    def _run(self, duration: float) -> None:
        try:
            self.loop.run(duration)
        except BaseException as e:  # reported by the test
            self.error = e

    def stop(self) -> None:
        self.loop.stop()
        self._thread.join(timeout=5.0)
        assert not self._thread.is_alive()


# ---------------------------------------------------------------------- time base


def test_device_time_maps_the_wall_clock_to_loop_time_at_the_pace() -> None:
    clock = DeviceTime(pace=2.0)
    clock.anchor(2.0, 100.0)
    # 1.5 s of wall clock at pace 2 is 3 s of loop time
    assert clock.to_loop(101.5) == pytest.approx(5.0)
    assert clock.to_wall(5.0) == pytest.approx(101.5)
    assert clock.to_wall(clock.to_loop(123.456)) == pytest.approx(123.456)
    with pytest.raises(ValueError, match="pace"):
        DeviceTime(pace=0.0)


def test_a_resync_anchors_the_device_clock_and_drops_the_readings_of_the_stall() -> None:
    """The loop skipped a stall: its time t is now. The drivers' readings queued meanwhile
    are stale; the next batch holds the latest of each kind, at the loop's time, and later
    readings map to loop time from the new anchor."""
    wall = [500.0]
    io = DeviceRobotIO(DevicesConfig(), wall_clock=lambda: wall[0])
    io.resync(0.0)
    io.advance_to(0.0)
    for k in range(5):  # a second of readings queued while the loop was held back
        io._on_reading(DepthReading(t=500.2 + 0.2 * k, depth_m=1.0 + k, pressure_pa=0.0))
        io._on_reading(ImuReading(t=500.2 + 0.2 * k, accel=(0.0, 0.0, -9.80665), gyro=(0.0, 0.0, float(k))))
    wall[0] = 501.5
    io.resync(0.5)  # the loop skipped ahead: its 0.5 s is due now, at 501.5
    batch = io.advance_to(0.5)
    assert sorted(type(r).__name__ for r in batch) == ["DepthReading", "ImuReading"]
    assert all(r.t == 0.5 for r in batch)
    assert {r.depth_m for r in batch if isinstance(r, DepthReading)} == {5.0}  # the latest
    io._on_reading(DepthReading(t=501.6, depth_m=2.0, pressure_pa=0.0))
    wall[0] = 501.7
    [r] = io.advance_to(0.7)
    assert r.t == pytest.approx(0.6)  # 0.1 s after the new anchor
    io.close()


# ---------------------------------------------------------------------- robot = sim


def test_sim_robot_is_the_in_process_simulator_at_the_configured_start() -> None:
    io, close = build_robot_io("sim", DevicesConfig(start=SimStartConfig(depth=2.5, yaw=0.5)))
    try:
        assert isinstance(io, SimRobotIO)
        truth = io.truth()
        assert truth.depth == pytest.approx(2.5)
        assert truth.euler[2] == pytest.approx(0.5)
        assert rig_of(io) is None
        connect_events(io, Collector())()  # nothing to connect, nothing fails
    finally:
        close()


# ---------------------------------------------------------------------- robot = sim-devices


@pytest.mark.parametrize("configured, expected", [(0.3, 1.0), (2.0, 2.0)])
def test_drivers_give_the_emulated_drives_the_rigs_sdo_timeout(configured: float, expected: float) -> None:
    epos2 = Epos2Config(units=UNITS, sdo_timeout=configured)
    io, close = build_robot_io("sim-devices", sim_devices_config(epos2=epos2))
    try:
        assert io.config.epos2.sdo_timeout == expected  # the rig's 1 s at least, a longer one kept
        for driver in io.drives.drivers.values():
            assert driver.node.sdo.RESPONSE_TIMEOUT == expected
    finally:
        close()



def test_simulated_robot_runs_closed_loop_through_drivers_and_emulators() -> None:
    # reference: the same loop on the in-process simulator, same start and seed
    ref_io = SimRobotIO(depth=START_DEPTH, seed=7)
    with ClosedLoop(LoopConfig(mode="baseline"), ref_io, setpoints=SETPOINTS) as ref:
        ref.run(3.0)
        ref_truth = ref_io.truth()
    ref_dive, ref_speed = ref_truth.depth - START_DEPTH, ref_truth.velocity[0]

    sink = Collector()
    io, close = build_robot_io("sim-devices", sim_devices_config(), event_sink=sink)
    stream = TelemetryStream()
    got: dict[str, list[Any]] = {ch.IMU: [], ch.DVL: [], ch.DEPTH: [], ch.EVENTS: [], ch.fin_state(0): [],
                                 ch.POWER_ELECTRICAL: []}
    stream.subscribe(lambda c, m: got[c].append(m), channels=list(got))
    io.add_telemetry_sink(stream.publish)  # as the supervisor connects it
    loop = ClosedLoop(LoopConfig(mode="baseline"), io, stream, PacedClock(1.0), setpoints=SETPOINTS,
                      source="sim-devices")
    try:
        assert isinstance(io, DeviceRobotIO)
        rig = rig_of(io)
        assert rig is not None
        start = io.truth()
        loop.run(3.0)
        end = io.truth()
        during = list(got[ch.POWER_ELECTRICAL])  # the drives keep reporting after the loop stopped
        commands = [loop.fin_command(f) for f in range(4)]

        # depth and forward velocity move towards the setpoints, as on the in-process robot
        dive, speed = end.depth - start.depth, end.velocity[0] - start.velocity[0]
        assert 0.001 < dive < SETPOINTS.depth - START_DEPTH
        assert 0.002 < speed < SETPOINTS.velocity
        assert dive > 0.25 * ref_dive
        assert speed > 0.25 * ref_speed

        # every fin took its strokes through CANopen: new set-points (controlword 0x003F)
        # reached its node, whose target is the loop's last command, and the plant's fin
        # (the node's servo) settles there once the loop stops commanding
        for fin, node in enumerate(io.config.epos2.node_ids):
            emulator = rig.nodes[node]
            assert emulator.controlword_log.count(0x003F) >= 2, (
                f"fin {fin}: controlwords {emulator.controlword_log}; "
                f"loop events {[(e.t, e.source, e.code) for e in got[ch.EVENTS]]}; "
                f"robot events {[(e.t, e.source, e.code) for e in sink.items]}; "
                f"fin 0 states {got[ch.fin_state(0)][::10]}"
            )
            target = commands[fin][0]
            wait_for(lambda: emulator.target_quadcounts == UNITS.to_quadcounts(target), what=f"fin {fin} target")
            wait_for(lambda: abs(rig.truth().fin_angles[fin] - target) < 2e-3, what=f"fin {fin} angle")

        # the drives' electrical input: every drive answered, at the plant's supply voltage,
        # each draws at least its own consumption, and the plant's motors carry current while
        # the loop drives them
        wait_for(lambda: len(got[ch.POWER_ELECTRICAL]) >= 5, what="electrical power messages")
        electrical = got[ch.POWER_ELECTRICAL]
        motor = FinMotor()
        for m in electrical:
            assert m.voltage == (motor.supply_voltage,) * 4
            assert min(m.per_fin) >= motor.quiescent_power - 1e-9
            assert m.total == pytest.approx(sum(m.per_fin))
        assert max(max(abs(i) for i in m.current) for m in electrical) > 0.05
        # stamped in the loop's time (those reported while it ran)
        assert during and all(0.0 <= m.t <= loop.time + io.config.resync_s + 0.05 for m in during), (
            f"loop time {loop.time:.3f} s, reported at {[round(m.t, 3) for m in during]}")
        assert [m.t for m in during] == sorted(m.t for m in during)  # the channel's time never goes back

        # the sensors reached the loop through their drivers and agree with the plant
        assert got[ch.IMU] and got[ch.DVL] and got[ch.DEPTH]
        # the newest depth reading is the plant's depth when it was taken: the robot still dives,
        # so it may trail the truth read at the end by the dive rate times the reading's age
        last = got[ch.DEPTH][-1]
        age = max(0.0, end.t - last.t)
        assert age < 1.0
        assert abs(last.depth_m - end.depth) <= 0.02 + (abs(end.velocity[2]) + 0.05) * age
        valid = [r for r in got[ch.DVL] if r.valid and r.t > loop.time - 1.0]
        assert valid and abs(valid[-1].vx - end.velocity[0]) < 0.03
        # readings reached the loop in its own time
        # (ahead of the loop by at most the re-alignment threshold when the loop lags)
        assert all(0.0 <= r.t <= loop.time + io.config.resync_s + 0.05 for r in got[ch.IMU])

        bad = [(e.source, e.code) for e in sink.items if e.level in ("error", "fatal")]
        assert not bad
    finally:
        loop.close()
        close()


# device, fault, arguments, source and codes of the fault's event, code of its end
FAULTS = [
    ("epos2", "emcy", {"fin": 1, "code": 0x2310}, "epos2.2", ("emcy",), "fault_cleared"),
    ("epos2", "heartbeat_loss", {"fin": 2}, "epos2.3", ("heartbeat_lost",), "heartbeat_restored"),
    ("imu", "corrupt", {}, "imu", ("checksum", "garbage"), None),
    ("dvl", "invalid", {}, "dvl", ("bottom_lock_lost",), "recovered"),
    ("pressure", "silence", {}, "pressure", ("silence",), "recovered"),
]


@pytest.mark.parametrize("device, fault, kw, source, codes, end", FAULTS, ids=[f"{d}-{f}" for d, f, *_ in FAULTS])
def test_injected_fault_surfaces_as_an_event_and_the_loop_keeps_running(
    device: str, fault: str, kw: dict, source: str, codes: tuple[str, ...], end: str | None
) -> None:
    io, close = build_robot_io("sim-devices", sim_devices_config())
    sink = Collector()
    connect_events(io, sink)
    loop = ClosedLoop(LoopConfig(mode="baseline"), io, clock=PacedClock(1.0), setpoints=SETPOINTS)
    runner = LoopThread(loop, 30.0)
    try:
        wait_for(lambda: loop.time > 0.3, what="the loop running")
        assert sink.find(source, codes) is None
        t_inject = loop.time
        injected = rig_of(io).inject(device, fault, **kw)
        assert injected.code == "fault_injected" and injected.data["fault"] == fault

        event = wait_for(lambda: sink.find(source, codes), what=f"{source} {codes}")
        assert isinstance(event, Event) and event.level in ("warning", "error")
        # stamped in the loop's time, after the injection
        assert t_inject - 0.05 <= event.t <= loop.time + 0.05
        if fault == "emcy":
            assert event.data["code"] == 0x2310
        # the injection itself is on the sink too
        assert sink.find("rig", ("fault_injected",)) is not None

        t_event = loop.time
        wait_for(lambda: loop.time > t_event + 0.3, what="the loop going on after the fault")
        assert runner.error is None

        # the fault ends when its cause does: the emulator's fault cleared, or the drive reset
        seen = len(sink)
        if fault == "emcy":
            assert io.reset_drive_faults()
        else:
            rig_of(io).clear(device, fault)
        if end is not None:
            wait_for(lambda: sink.find(source, (end,), after=seen), what=f"{source} {end}")
    finally:
        runner.stop()
        loop.close()
        close()
    assert runner.error is None


def test_fault_injection_refuses_unknown_devices_faults_and_arguments() -> None:
    io, close = build_robot_io("sim-devices", sim_devices_config())
    try:
        rig = rig_of(io)
        with pytest.raises(ValueError, match="device: 'sonar'"):
            rig.inject("sonar", "silence")
        with pytest.raises(ValueError, match="fault: 'emcy' is not a fault of imu"):
            rig.inject("imu", "emcy")
        with pytest.raises(ValueError, match="fin: 7"):
            rig.inject("epos2", "emcy", fin=7)
        with pytest.raises(ValueError, match="colour: not an argument"):
            rig.inject("dvl", "slow", colour="red")
        with pytest.raises(ValueError, match="duration"):
            rig.inject("pressure", "silence", duration=-1.0)
    finally:
        close()


# ---------------------------------------------------------------------- robot = hardware


@pytest.fixture
def stand_ins():
    """Emulators standing in for the robot's devices at addresses given in a hardware config."""
    channel = f"rig-hw-{uuid.uuid4().hex[:8]}"
    nodes = start_emulated_nodes(channel, (1, 2, 3, 4), config=Epos2EmulatorConfig(units=UNITS))
    imu = ImuEmulator(synthetic_imu).start()
    dvl = DvlEmulator(synthetic_dvl).start()
    pressure = PressureEmulator(synthetic_depth).start()
    config = DevicesConfig(
        # margins for drives emulated in this process on a busy machine (a real EPOS2: 0.3 s)
        epos2=Epos2Config(interface="virtual", channel=channel, units=UNITS, boot_timeout=1.0,
                          sdo_timeout=1.0),
        imu=ImuConfig(port=imu.port),
        dvl=DvlConfig(host="127.0.0.1", port=dvl.port, connect_timeout_s=1.0),
        pressure=PressureConfig(port=pressure.port),
    )
    yield config
    for emulator in (imu, dvl, pressure):
        emulator.stop()
    nodes.close()


def test_hardware_robot_uses_the_configured_endpoints(stand_ins: DevicesConfig) -> None:
    io, close = build_robot_io("hardware", stand_ins)
    try:
        assert isinstance(io, DeviceRobotIO)
        assert io.truth() is None and rig_of(io) is None
        assert io.enable_drives()
        io.command_fin(0, 0.3, 2.0)
        seen: list[Any] = []
        t = 0.0
        last_per_kind: dict[object, float] = {}

        def collect() -> bool:
            nonlocal t
            t += 0.02
            batch = io.advance_to(t)
            assert [r.t for r in batch] == sorted(r.t for r in batch)
            for r in batch:
                key = (FinFeedback, r.fin) if isinstance(r, FinFeedback) else type(r)
                assert r.t > last_per_kind.get(key, -math.inf)
                last_per_kind[key] = r.t
            seen.extend(batch)
            fin0 = [r for r in seen if isinstance(r, FinFeedback) and r.fin == 0]
            kinds = {type(r) for r in seen}
            return kinds == {FinFeedback, ImuReading, DvlVelocity, DepthReading} and fin0 and \
                abs(fin0[-1].position_rad - 0.3) < 1e-3

        wait_for(collect, what="readings of every kind and fin 0 at 0.3 rad")
        depths = [r.depth_m for r in seen if isinstance(r, DepthReading)]
        assert all(0.79 < d < 1.21 for d in depths)  # synthetic depth: 1 m +- 0.2 m
        dvl = [r for r in seen if isinstance(r, DvlVelocity)]
        assert all(r.valid and r.vx == pytest.approx(0.3, abs=1e-6) for r in dvl)
        imu = [r for r in seen if isinstance(r, ImuReading)]
        assert imu[-1].accel == pytest.approx((0.0, 0.0, -9.80665), abs=1e-5)  # level: -g0, in m/s^2
    finally:
        close()


# ---------------------------------------------------------------------- bad configuration


@pytest.mark.parametrize("data, key", [
    ({"epos2": {"interface": "carrier-pigeon"}}, "epos2.interface"),
    ({"epos2": {"node_ids": [1, 2, 3, 128]}}, r"epos2.node_ids\[3\]"),
    ({"epos2": {"node_ids": [0, 2, 3, 4]}}, r"epos2.node_ids\[0\]"),
    ({"imu": {"baud": 1234}}, "imu.baud"),
    ({"rig": {"pace": 0.0}}, "rig.pace"),
])
def test_bad_configuration_values_name_the_key(data: dict, key: str) -> None:
    with pytest.raises(ValueError, match=f"^{key}"):
        DevicesConfig.from_dict(data)


def test_a_robot_is_built_only_from_a_known_robot_and_a_devices_block() -> None:
    with pytest.raises(ValueError, match="^robot: 'submarine'"):
        build_robot_io("submarine", DevicesConfig())
    with pytest.raises(ValueError, match="^devices: expected"):
        build_robot_io("sim-devices", SimpleNamespace())  # type: ignore[arg-type]


def _threads() -> set[str]:
    return {t.name for t in threading.enumerate()}


def test_start_up_errors_name_the_key_and_leave_nothing_running(stand_ins: DevicesConfig) -> None:
    good = stand_ins
    closed = DvlEmulator(synthetic_dvl).start()
    closed_port = closed.port
    closed.stop()  # nobody listens there any more
    before = _threads()
    cases = [
        (good.replace(imu=good.imu.replace(port="/dev/ucat-no-such-imu")), r"^imu\.port"),
        (good.replace(pressure=good.pressure.replace(port="/dev/ucat-no-such-adc")), r"^pressure\.port"),
        (good.replace(dvl=good.dvl.replace(port=closed_port)), r"^dvl\.host"),
        (good.replace(epos2=good.epos2.replace(interface="socketcan", channel="ucatnocan9")), r"^epos2\.channel"),
        (good.replace(epos2=good.epos2.replace(channel=f"empty-{uuid.uuid4().hex[:6]}", boot_timeout=0.05)),
         r"^epos2\.node_ids\[0\]"),
    ]
    for config, key in cases:
        with pytest.raises(ValueError, match=key):
            build_robot_io("hardware", config)
        assert not {"dvl-client", "imu-reader", "pressure-reader", "epos2-supervision"} & (_threads() - before)


# ---------------------------------------------------------------------- configuration files


@pytest.mark.parametrize("name, robot", [("robot", "hardware"), ("sim-devices", "sim-devices")])
def test_shipped_configuration_files_hold_valid_device_blocks(name: str, robot: str) -> None:
    with open(shipped.config_path(name), "rb") as fh:
        data = tomllib.load(fh)
    assert data["robot"] == robot  # the one robot selector
    devices = DevicesConfig.from_dict(data["devices"])
    if robot == "hardware":
        assert (devices.epos2.interface, devices.epos2.channel) == ("socketcan", "can0")
        assert devices.epos2.bitrate == 1_000_000
