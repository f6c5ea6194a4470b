"""The plausibility checks of the sensors' readings, with hand-chosen values on both sides
of each limit; their reports; the failsafes' label of what they dropped; the in-process
simulator's compiled path through them; the simulator's own readings on a fast pitching and
heaving manoeuvre and out of the water, honest and lying."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from support import Collector, wait_for

from ucat_console.backend.devices import plausibility as pl
from ucat_console.backend.devices.config import DevicesConfig
from ucat_console.backend.devices.dvl_emulator import DvlEmulator
from ucat_console.backend.devices.imu_emulator import ImuEmulator
from ucat_console.backend.devices.plausibility import Plausibility, PlausibilityConfig, loop_current_problem
from ucat_console.backend.devices.pressure import PressureConfig, PressureDriver
from ucat_console.backend.devices.pressure_emulator import PressureEmulator
from ucat_console.backend.loop.closed_loop import ClosedLoop
from ucat_console.backend.loop.commands import SetSetpoints
from ucat_console.backend.loop.config import LoopConfig
from ucat_console.backend.safety import SafetyMonitor
from ucat_console.backend.sim_rig import SimRig
from ucat_console.backend.sim_robot_io import SimRobotIO
from ucat_console.backend.failsafe_config import FailsafeConfig, FailsafeRule
from ucat_console.config import AppConfig
from ucat_console.control.allocation import BodySetpoints
from ucat_console.control.params import ManoeuvreConfig
from ucat_console.backend.sim.variants import family_name, plant_config
from ucat_console.robot import reading_rows as rr
from ucat_console.robot.readings import DepthReading, DvlVelocity, FinFeedback, ImuReading
from ucat_console.robot.rotations import quaternion_from_euler
from ucat_console.robot.units import GRAVITY, LOOP_MIN_MA, RHO_FRESH, current_to_pressure, pressure_to_depth
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.stream import TelemetryStream

CFG = PlausibilityConfig(max_depth=10.0)
LEVEL = (1.0, 0.0, 0.0, 0.0)
REST = (0.0, 0.0, -GRAVITY)  # specific force, level and at rest


def depth(t: float, d: float) -> DepthReading:
    """A depth reading whose pressure says the same depth (fresh water)."""
    return DepthReading(t, d, d * RHO_FRESH * GRAVITY)


def imu(t: float, accel=REST, gyro=(0.0, 0.0, 0.0), q=LEVEL) -> ImuReading:
    return ImuReading(t, accel, gyro, q)


def dvl(t: float, vx: float = 0.0, vy: float = 0.0, vz: float = 0.0, valid: bool = True) -> DvlVelocity:
    return DvlVelocity(t, vx, vy, vz, valid, 2.0, 0.002)


def code(checks: Plausibility, reading) -> int:
    row = np.full(rr.ROW, math.nan)
    rr.to_row(reading, row)
    return pl.check_row(checks.limits, checks.state, row)


# ------------------------------------------------------------------ configuration
def test_the_limits_are_configured_with_ranges_and_a_depth_limit_no_shallower_than_the_envelope() -> None:
    assert DevicesConfig().plausibility == PlausibilityConfig()
    with pytest.raises(ValueError, match="max_depth"):
        PlausibilityConfig(max_depth=-1.0)
    with pytest.raises(ValueError, match="gyro_range"):
        PlausibilityConfig(gyro_range=2000.0)
    app = AppConfig()
    with pytest.raises(ValueError, match=r"devices.plausibility.max_depth: 10 m is shallower than loop.max_depth 50 m"):
        app.replace(devices=app.devices.replace(plausibility=CFG))
    ok = app.replace(loop=app.loop.replace(max_depth=8.0), devices=app.devices.replace(plausibility=CFG))
    assert AppConfig.from_dict(ok.to_dict()).devices.plausibility.max_depth == 10.0


# ------------------------------------------------------------------ each limit, both sides
@pytest.mark.parametrize("d, expected", [
    (9.99, pl.OK), (10.01, pl.DEEP), (104.8, pl.DEEP), (-0.49, pl.OK), (-0.51, pl.ABOVE),
])
def test_depth_within_the_configured_limit_and_not_far_above_the_surface(d: float, expected: int) -> None:
    assert code(Plausibility(CFG), depth(0.0, d)) == expected


@pytest.mark.parametrize("jump, expected", [(0.149, pl.OK), (0.151, pl.DEPTH_JUMP), (-0.151, pl.DEPTH_JUMP)])
def test_depth_changes_no_faster_than_the_robot_moves(jump: float, expected: int) -> None:
    checks = Plausibility(CFG)  # 1 m/s and 0.05 m: 0.15 m in 0.1 s
    assert code(checks, depth(0.0, 2.0)) == pl.OK
    assert code(checks, depth(0.1, 2.0 + jump)) == expected


def test_a_depth_jump_is_judged_against_the_last_reading_that_passed_and_a_zeroing_is_no_jump() -> None:
    checks = Plausibility(CFG)
    assert code(checks, depth(0.0, 2.0)) == pl.OK
    assert code(checks, depth(0.05, 7.0)) == pl.DEPTH_JUMP
    assert code(checks, depth(0.10, 2.01)) == pl.OK  # the jump never became the reference
    # zeroed at another surface pressure: the depth moves, the pressure does not
    assert code(checks, DepthReading(0.15, 0.5, 2.01 * RHO_FRESH * GRAVITY)) == pl.OK
    # long after the last reading, as far as the robot could have gone
    assert code(checks, depth(5.0, 6.9)) == pl.OK


@pytest.mark.parametrize("accel_g, expected", [(7.99, pl.OK), (-7.99, pl.OK), (8.01, pl.ACCEL), (1e6, pl.ACCEL)])
def test_each_axis_of_the_specific_force_within_the_accelerometers_range(accel_g: float, expected: int) -> None:
    checks = Plausibility(CFG)
    for axis in range(3):
        a = [0.0, 0.0, 0.0]
        a[axis] = accel_g * GRAVITY
        assert code(checks, imu(0.01 * axis, accel=tuple(a), q=None)) == expected


@pytest.mark.parametrize("rate, expected", [
    (math.radians(299.0), pl.OK), (-math.radians(299.0), pl.OK), (math.radians(301.0), pl.GYRO), (1000.0, pl.GYRO),
])
def test_each_axis_of_the_rate_within_the_gyros_range(rate: float, expected: int) -> None:
    checks = Plausibility(CFG)
    for axis in range(3):
        g = [0.0, 0.0, 0.0]
        g[axis] = rate
        assert code(checks, imu(0.01 * axis, gyro=tuple(g), q=None)) == expected


@pytest.mark.parametrize("norm, expected", [(1.009, pl.OK), (0.991, pl.OK), (1.011, pl.Q_NORM), (0.989, pl.Q_NORM),
                                            (0.0, pl.Q_NORM)])
def test_an_orientation_is_a_unit_quaternion(norm: float, expected: int) -> None:
    q = tuple(norm * c for c in quaternion_from_euler(0.1, -0.2, 2.0))
    assert code(Plausibility(CFG), imu(0.0, q=q)) == expected


@pytest.mark.parametrize("turn_deg, expected", [(8.0, pl.OK), (10.0, pl.Q_JUMP), (90.0, pl.Q_JUMP)])
def test_the_orientation_turns_no_faster_than_the_gyro_measures(turn_deg: float, expected: int) -> None:
    # in 0.01 s: sqrt(3) * 300 deg/s * 0.01 s = 5.2 deg, and 0.05 rad = 2.9 deg of noise: 8.1 deg
    checks = Plausibility(CFG)
    assert code(checks, imu(0.0, q=quaternion_from_euler(0.0, 0.0, 1.0))) == pl.OK
    assert code(checks, imu(0.01, q=quaternion_from_euler(0.0, 0.0, 1.0 + math.radians(turn_deg)))) == expected


@pytest.mark.parametrize("v, expected", [((1.99, 0.0, 0.0), pl.OK), ((1.2, 1.2, 1.1), pl.DVL_SPEED),
                                         ((0.0, -2.01, 0.0), pl.DVL_SPEED), ((5.0, 0.0, 0.0), pl.DVL_SPEED)])
def test_the_dvl_velocity_within_its_range(v: tuple[float, float, float], expected: int) -> None:
    assert code(Plausibility(CFG), dvl(0.0, *v)) == expected


def test_missing_and_non_finite_data_pass_to_the_arming_gate_and_teach_nothing() -> None:
    checks = Plausibility(CFG)
    assert code(checks, dvl(0.0, math.nan, math.nan, math.nan, valid=False)) == pl.OK
    assert code(checks, dvl(0.1, 50.0, 0.0, 0.0, valid=False)) == pl.OK  # no bottom lock: not a velocity
    assert code(checks, imu(0.0, accel=(math.nan, 0.0, 0.0))) == pl.OK
    assert code(checks, imu(0.0, q=(math.nan, 0.0, 0.0, 0.0))) == pl.OK
    assert code(checks, depth(0.0, math.nan)) == pl.OK
    assert code(checks, FinFeedback(0.0, 0, 5.0, 100.0)) == pl.OK
    assert math.isnan(checks.state[pl.S_DEPTH_T]) and math.isnan(checks.state[pl.S_Q_T])


# ------------------------------------------------------------------ agreement
def run_agreement(checks: Plausibility, dvl_down: float, depth_rate: float, seconds: float) -> list[int]:
    """Depth at 20 Hz changing at ``depth_rate`` and DVL reports at 8 Hz of ``dvl_down``
    (a level robot), in time order; the codes of every reading."""
    events = sorted([(k / 20.0, "depth") for k in range(int(seconds * 20))]
                    + [(k / 8.0, "dvl") for k in range(int(seconds * 8))])
    codes = []
    for t, kind in events:
        r = depth(t, 1.0 + depth_rate * t) if kind == "depth" else dvl(t, vz=dvl_down)
        codes.append(code(checks, r))
    return codes


def test_depth_rate_and_the_dvls_vertical_velocity_agree_within_the_tolerance_over_the_window() -> None:
    checks = Plausibility(CFG)  # 0.2 m/s over 2 s
    assert set(run_agreement(checks, 0.3, 0.3, 20.0)) == {pl.OK}  # diving, both see it
    assert set(run_agreement(Plausibility(CFG), 0.15, 0.0, 20.0)) == {pl.OK}  # apart, within the tolerance
    apart = Plausibility(CFG)
    codes = run_agreement(apart, 0.25, 0.0, 20.0)
    assert pl.APART in codes and codes[:20] == [pl.OK] * 20  # judged over the window: not at once
    assert apart.dropped("depth") > 0 and apart.dropped("dvl") > 0  # which one is wrong is not known
    assert "depth rate and the DVL's vertical velocity 0.2" in apart.reason("depth")


def test_the_dvl_velocity_is_turned_to_the_vertical_by_the_imus_orientation() -> None:
    # pitched 30 deg nose down, 0.8 m/s along the body: 0.4 m/s down, as the depth says
    nose_down = quaternion_from_euler(0.0, math.radians(-30.0), 0.0)

    def run(q: tuple[float, float, float, float]) -> set[int]:
        checks = Plausibility(CFG)
        codes = set()
        for k in range(200):
            t = k / 20.0
            codes.add(code(checks, imu(t, q=q)))
            codes.add(code(checks, depth(t + 0.001, 1.0 + 0.4 * t)))
            if k % 2 == 0:
                codes.add(code(checks, dvl(t + 0.002, vx=0.8)))
        return codes

    assert run(nose_down) == {pl.OK}
    assert pl.APART in run(LEVEL)  # taken as level, the same reports disagree with the depth


# ------------------------------------------------------------------ reports
def test_dropped_readings_are_left_out_counted_and_reported_once_a_second_with_the_reason() -> None:
    events: list[Event] = []
    checks = Plausibility(CFG, events.append)
    good = depth(0.0, 1.0)
    assert checks.filter([good]) == [good]
    checks.report(0.0)
    assert not events
    for k in range(30):  # 1.5 s of one bad reading every 50 ms
        t = 0.05 * (k + 1)
        out = checks.filter([depth(t, 104.8), imu(t)])
        assert [type(r) for r in out] == [ImuReading]
        checks.report(t)
    assert checks.dropped("depth") == 30 and checks.dropped("imu") == 0
    assert len(events) == 2 and events[0].data["dropped"] == 1  # at once, then a second's worth
    ev = events[-1]
    assert (ev.source, ev.code, ev.level) == ("pressure", "implausible", "error")
    assert ev.data["reason"] == "depth 104.8 m beyond the 10 m limit"
    checks.report(2.1)  # the rest, once the second has passed
    assert sum(e.data["dropped"] for e in events) == 30


def test_the_failsafe_label_counts_the_dropped_readings_and_gives_the_reason() -> None:
    monitor = SafetyMonitor(FailsafeConfig(depth=FailsafeRule("disarm", 1.0)))
    monitor.on_message(ch.DEPTH, depth(0.0, 1.0))
    for dropped, t in ((1, 0.05), (11, 1.05)):
        monitor.on_event(Event(t, "pressure", "implausible", "", "error",
                               {"dropped": dropped, "reason": "depth 104.8 m beyond the 10 m limit"}))
    assert not monitor.check(0.9)
    (tr,) = [tr for tr in monitor.check(1.1) if tr.name == "depth"]
    assert tr.active
    assert tr.cause == ("DEPTH without a valid reading for 1.1 s "
                        "(implausible: 12 readings dropped, depth 104.8 m beyond the 10 m limit)")
    monitor.on_message(ch.DEPTH, depth(1.2, 1.0))
    (tr,) = [tr for tr in monitor.check(1.25) if tr.name == "depth"]
    assert not tr.active


@pytest.mark.parametrize("current, problem", [
    (3.9, "at or below 4 mA"), (4.0, "at or below 4 mA"), (4.0001, ""), (12.0, ""), (20.0, ""),
    (20.0001, "above 20 mA"), (20.4, "above 20 mA"),
])
def test_a_loop_current_outside_the_transducers_span_is_no_measurement(current: float, problem: str) -> None:
    found = loop_current_problem(current, 104.8)
    assert (problem in found) if problem else found == ""


# ------------------------------------------------------------------ the pressure driver, the emulators
def test_the_pressure_driver_drops_a_current_outside_the_span_and_reports_it_with_the_count() -> None:
    emulator = PressureEmulator(lambda t: 1.0).start()
    readings, events = Collector(), Collector()
    driver = PressureDriver(PressureConfig(port=emulator.port), readings, events)
    try:
        assert driver.start()
        wait_for(lambda: len(readings) > 2, what="readings")
        for current, dropped in ((20.0, False), (20.4, True), (4.0001, False), (4.0, True)):
            depth = (current - 4.0) / 16.0 * 1e6 / (RHO_FRESH * GRAVITY)  # what the current measures
            emulator.set_implausible(current_ma=current)
            emulator.inject("implausible")
            n, k = len(readings), len(events)
            if dropped:
                found = wait_for(lambda: [e for e in events.items[k:] if e.code == "implausible"],
                                 what=f"{current} mA dropped")
                assert found[0].data["dropped"] >= 1 and f"{current:.3f} mA" in found[0].data["reason"]
                # no depth came of it (a reading of the current before, still on its way, may)
                assert not [r for r in readings.items[n:] if r.depth_m == pytest.approx(depth, abs=2e-4)]
            else:
                wait_for(lambda: len(readings) > n + 2, what=f"readings at {current} mA")
                assert readings.items[-1].depth_m == pytest.approx(depth, abs=1e-3)
            emulator.clear()
    finally:
        driver.stop()
        emulator.stop()


def test_the_emulators_implausible_values_are_checked_and_named() -> None:
    pressure, imu_e, dvl_e = PressureEmulator(lambda t: 1.0), ImuEmulator(lambda t: None), DvlEmulator(lambda t: None)
    try:
        with pytest.raises(ValueError, match="current_ma/jump_m: give one"):
            pressure.set_implausible(current_ma=20.4, jump_m=1.0)
        with pytest.raises(ValueError, match="current_ma: expected 1 finite"):
            pressure.set_implausible(current_ma=math.inf)
        with pytest.raises(ValueError, match="gyro: expected 3 numbers"):
            imu_e.set_implausible(gyro=(0.0, 1000.0))
        with pytest.raises(ValueError, match="quaternion: expected 4 finite numbers"):
            imu_e.set_implausible(quaternion=(0.0, 0.0, "x", 0.0))
        with pytest.raises(ValueError, match="velocity: expected 3 numbers"):
            dvl_e.set_implausible(velocity="fast")
    finally:
        for e in (pressure, imu_e, dvl_e):
            e.stop()
    rig = SimRig(DevicesConfig())
    with pytest.raises(ValueError, match="velocity: not an argument of this fault; allowed: duration, current_ma"):
        rig.inject("pressure", "implausible", velocity=(5.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="gyro: not an argument of this fault; allowed: duration$"):
        rig.inject("imu", "silence", gyro=(0.0, 0.0, 1.0))


# ------------------------------------------------------------------ the in-process simulator
def test_the_simulators_readings_pass_the_checks_in_its_compiled_path() -> None:
    io = SimRobotIO(depth=12.0, plausibility=CFG)  # deeper than the limit: every depth dropped
    stream = TelemetryStream()
    seen: list = []
    stream.subscribe(lambda c, m: seen.append((c, m)), [ch.DEPTH, ch.IMU])
    events: list[Event] = []
    io.checks.on_event = events.append
    with ClosedLoop(LoopConfig(mode="baseline"), io, stream, setpoints=BodySetpoints(depth=9.0)) as loop:
        assert io.runs_core
        loop.run(2.0)
    assert io.checks.dropped("depth") >= 39 and io.checks.dropped("imu") == 0
    assert not [m for c, m in seen if c == ch.DEPTH]  # the loop never took one
    assert [m for c, m in seen if c == ch.IMU]
    assert events and events[0].source == "pressure" and "beyond the 10 m limit" in events[0].data["reason"]


@pytest.mark.slow
def test_nothing_the_simulator_measures_is_dropped_over_a_long_run() -> None:
    io = SimRobotIO(depth=1.0, velocity=0.1, seed=3)
    with ClosedLoop(LoopConfig(mode="baseline"), io,
                    setpoints=BodySetpoints(velocity=0.4, depth=2.5, yaw_rate=0.4)) as loop:
        loop.run(60.0)
        loop.submit(SetSetpoints(velocity=0.2, depth=0.0, yaw_rate=-0.4))
        loop.run(60.0)
    assert [io.checks.dropped(s) for s in pl.SENSORS] == [0, 0, 0]


# ------------------------------------------------------------------ the simulator's sensors, moving fast
class LyingSim(SimRobotIO):
    """The in-process simulator through the checks' Python path, its readings handed on as
    measured or changed by ``lie``: ``"dvl"`` a DVL that adds 0.3 m/s along its z axis,
    ``"pressure"`` a transducer frozen at its first depth. Keeps every reading that passed."""

    def __init__(self, *args, lie: str = "", **kw) -> None:
        super().__init__(*args, **kw)
        self.lie = lie
        self.frozen: DepthReading | None = None
        self.passed: list = []
        self.depths: list[float] = []
        self.pitches: list[float] = []

    def advance_to(self, t: float) -> list:
        measured = []
        for r in self.plant.advance_and_sample(t):
            if self.lie == "dvl" and type(r) is DvlVelocity and r.valid:
                r = dataclasses.replace(r, vz=r.vz + 0.3)
            elif self.lie == "pressure" and type(r) is DepthReading:
                self.frozen = self.frozen or r
                r = dataclasses.replace(self.frozen, t=r.t)
            measured.append(r)
        self.depths.append(self.plant.depth())
        self.pitches.append(self.plant.euler()[1])
        readings = self.checks.filter(measured)
        self.checks.report(t)
        self.passed += readings
        return readings


@pytest.mark.parametrize("lie", ["", "dvl", "pressure"])
def test_the_identification_manoeuvre_at_scaled_fin_gains_passes_honest_sensors_and_catches_lying_ones(
        lie: str) -> None:
    # E6's strongest plant through the identification manoeuvre (5 s steps), deep enough to
    # stay under water: pitching over 15 deg, heaving with the strokes, climbing more than a metre
    io = LyingSim(plant_config(family_name(9.2, "plate"), 0), depth=8.0, seed=2, lie=lie)
    with ClosedLoop(LoopConfig(mode="identify", manoeuvre=ManoeuvreConfig(step_s=5.0)), io) as loop:
        loop.run(30.0)
    assert max(abs(p) for p in io.pitches) > math.radians(15.0) and 8.0 - min(io.depths) > 1.0
    assert min(io.depths) > 0.5  # under water throughout
    if not lie:
        assert [io.checks.dropped(s) for s in pl.SENSORS] == [0, 0, 0]
    else:
        assert io.checks.dropped("dvl") > 0 and io.checks.dropped("depth") > 0
        assert "depth rate and the DVL's vertical velocity" in io.checks.reason("depth")


def test_a_robot_out_of_the_water_gets_no_depth_from_its_pinned_transducer_and_keeps_its_dvl() -> None:
    # pushed up through the surface: the transducer's loop current pins at NAMUR NE 43's
    # 3.8 mA, a current that measures nothing (the pressure driver drops it); the simulator
    # hands on no depth then, and the DVL's readings, which still measure, pass the checks
    io = LyingSim(depth=1.0, seed=1)
    io.plant.set_body_wrench(force=(0.0, 0.0, -60.0))
    while io.plant.time < 8.0:
        io.advance_to(io.next_reading_time())
    assert min(io.depths) < -1.5
    span = io.plant.cfg.sensors.pressure.span_pa
    floor = pressure_to_depth(current_to_pressure(LOOP_MIN_MA, 0.0, span), 0.0, RHO_FRESH)
    depths = [r for r in io.passed if type(r) is DepthReading]
    assert min(r.depth_m for r in depths) > floor + 0.01  # none pinned at the floor
    assert depths[-1].t < 5.0  # the robot was out of the water since
    assert [io.checks.dropped(s) for s in pl.SENSORS] == [0, 0, 0]
    dvl_times = [r.t for r in io.passed if type(r) is DvlVelocity and r.valid]
    assert dvl_times[-1] > 7.5 and max(np.diff(dvl_times)) < 0.5  # the DVL throughout, but its dropouts
