"""The loop's compiled per-sample core: the simulator running it gives the trajectory the
loop gives driving the robot event by event, Python runs only when it has something to do,
and bad readings are refused naming the field."""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest

from backend.loop import trajectory
from ucat_console.backend.loop.closed_loop import ClosedLoop
from ucat_console.backend.loop.config import LoopConfig
from ucat_console.backend.sim_robot_io import SimRobotIO
from ucat_console.control import loop_core as lc
from ucat_console.control.allocation import BodySetpoints
from ucat_console.robot.interface import RobotIO
from ucat_console.robot.readings import DepthReading, DvlVelocity, FinFeedback, ImuReading, Reading
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.stream import TelemetryStream


class EventByEvent(SimRobotIO):
    """The simulator driven through ``advance_to``, one event at a time (as the console's
    arming gate and every device-backed robot drive the loop)."""

    def advance_to(self, t: float) -> list[Reading]:
        return super().advance_to(t)


@pytest.mark.parametrize("mode", list(trajectory.SCENARIOS))
def test_the_simulator_running_the_core_gives_the_event_by_event_trajectory(mode, monkeypatch):
    fast = trajectory.run(mode)
    monkeypatch.setattr(trajectory, "SimRobotIO", EventByEvent)
    slow = trajectory.run(mode)
    assert sorted(fast) == sorted(slow)
    for key in fast:
        np.testing.assert_array_equal(fast[key], slow[key], err_msg=key)


def test_the_ekf_attitude_runs_the_same_on_both_paths():
    def run(io_type: type) -> dict[str, list]:
        stream = TelemetryStream()
        rows: dict[str, list] = {}
        stream.subscribe(lambda c, m: rows.setdefault(c, []).append(m), [ch.BODY_STATE, ch.IMU])
        io = io_type(depth=1.0, velocity=0.2)
        with ClosedLoop(LoopConfig(mode="baseline", attitude="ekf"), io, stream,
                        setpoints=BodySetpoints(velocity=0.2, depth=1.1)) as loop:
            loop.run_until(2.0)
        return rows

    fast, slow = run(SimRobotIO), run(EventByEvent)
    assert len(fast[ch.BODY_STATE]) == 101 and len(fast[ch.IMU]) == 201  # t = 0 .. 2 s
    assert fast == slow
    # the EKF's attitude, not the IMU's own: the two differ by the IMU's attitude noise
    q_imu = np.array(fast[ch.IMU][-1].quaternion)
    q_ekf = np.array(fast[ch.BODY_STATE][-1].orientation)
    assert 0.0 < np.abs(q_imu - q_ekf).max() < 0.05


def test_headless_the_core_returns_only_for_what_python_does():
    """With nothing subscribed, the simulator and the core run every sample and tick in
    compiled code: the loop's Python runs at stroke ends, plan hand-overs, status ticks and
    the first plans' requests, a few times a second per fin, never per sample."""
    io = SimRobotIO(depth=1.0, velocity=0.2)
    returns: Counter[int] = Counter()
    run_core = io.run_core

    def counted(core):
        st = run_core(core)
        returns[st] += 1
        return st

    io.run_core = counted  # type: ignore[method-assign]
    with ClosedLoop(LoopConfig(mode="mpc"), io, TelemetryStream(),
                    setpoints=BodySetpoints(velocity=0.2, depth=1.0)) as loop:
        loop.run_until(20.0)
        strokes, plans = loop.plans_made * 2, loop.plans_made
    assert set(returns) <= {lc.STROKE, lc.DELIVER, lc.STATUS, lc.CONTROL, lc.END}
    assert returns[lc.STATUS] == 21  # t = 0 .. 20 s
    assert returns[lc.DELIVER] <= plans
    assert returns[lc.STROKE] <= strokes + 8
    assert sum(returns.values()) < 20 * 20  # under 20 a second, where samples come at 100 a second
    assert plans > 40


class ScriptedRobot(RobotIO):
    """Readings from a script: ``script[k]`` at t = k * 10 ms."""

    def __init__(self, script: list[list[Reading]]) -> None:
        self.script = script
        self.k = 0

    def command_fin(self, fin, target_rad, profile_velocity_rad_s):
        pass

    def next_reading_time(self) -> float:
        return self.k * 0.01 if self.k < len(self.script) else math.inf

    def advance_to(self, t: float) -> list[Reading]:
        out: list[Reading] = []
        while self.k < len(self.script) and self.k * 0.01 <= t + 1e-9:
            out += self.script[self.k]
            self.k += 1
        return out


def _imu(t: float, gyro_z: float = 0.0) -> ImuReading:
    return ImuReading(t, (0.0, 0.0, -1.0), (0.0, 0.0, gyro_z), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0))


@pytest.mark.parametrize("bad, field", [
    (DepthReading(0.02, math.nan, 1e5), "depth.depth_m"),
    (DvlVelocity(0.02, math.inf, 0.0, 0.0, True, 2.0, 0.01), "dvl.vx"),
    (_imu(0.02, math.nan), r"imu.gyro\[2\]"),
])
def test_a_bad_reading_is_refused_naming_its_field(bad, field):
    script = [[_imu(0.0)], [_imu(0.01)], [bad]]
    with ClosedLoop(LoopConfig(mode="baseline"), ScriptedRobot(script)) as loop:
        with pytest.raises(ValueError, match=field):
            loop.run_until(0.1)


def test_encoder_samples_out_of_order_are_refused_naming_the_fin():
    script = [[FinFeedback(0.0, 2, 0.1, 0.0)], [FinFeedback(0.01, 2, 0.1, 0.0)], [FinFeedback(0.005, 2, 0.1, 0.0)]]
    with ClosedLoop(LoopConfig(mode="baseline"), ScriptedRobot(script)) as loop:
        with pytest.raises(ValueError, match="fin 2"):
            loop.run_until(0.1)


def test_the_readings_the_loop_publishes_are_the_robots():
    """Through the core's outbox, each reading reaches the stream as the robot gave it."""
    script = [[_imu(0.01 * k, 0.001 * k), DepthReading(0.01 * k, 1.0 + 0.01 * k, 1.1e5)] for k in range(30)]
    script[5].append(DvlVelocity(0.05, math.nan, math.nan, math.nan, False, math.nan, math.nan))
    stream = TelemetryStream()
    got: list[tuple[str, Reading]] = []
    stream.subscribe(lambda c, m: got.append((c, m)), [ch.IMU, ch.DEPTH, ch.DVL])
    with ClosedLoop(LoopConfig(mode="baseline"), ScriptedRobot(script), stream) as loop:
        loop.run_until(0.295)
    sent = [r for rs in script for r in rs]
    assert [m for _, m in got if type(m) is ImuReading] == [r for r in sent if type(r) is ImuReading]
    assert [m for _, m in got if type(m) is DepthReading] == [r for r in sent if type(r) is DepthReading]
    dvl = [m for _, m in got if type(m) is DvlVelocity]
    assert len(dvl) == 1 and not dvl[0].valid and math.isnan(dvl[0].vx)
