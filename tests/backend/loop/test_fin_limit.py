"""The body layer's allocation limits follow the mode's planners: a fixed beat frequency
makes less force than the fin model's deliverable force, and the allocation must know it, so
that what the fins cannot serve is cut in priority order (heave, yaw, surge) instead of being
lost in the strokes' saturation (the yaw differential first)."""

from __future__ import annotations

import numpy as np
import pytest

from ucat_console.backend.loop.closed_loop import ClosedLoop
from ucat_console.backend.loop.commands import SetBlock, SetMode
from ucat_console.backend.loop.config import LoopConfig
from ucat_console.backend.sim_robot_io import SimRobotIO
from ucat_console.control.allocation import NA, BodySetpoints, allocate_body_wrench
from ucat_console.control.baseline import fin_model_inverse
from ucat_console.control.body import B_ALLOC
from ucat_console.control.params import BaselineConfig
from ucat_console.control.stroke_timing import deliverable_force
from ucat_console.telemetry.stream import TelemetryStream


def peak(cfg: LoopConfig, frequency: float) -> float:
    ex = cfg.executor
    return fin_model_inverse(cfg.mpc, cfg.baseline.replace(frequency=frequency), ex.acceleration,
                             ex.max_rate).peak_force


def test_a_slow_beat_makes_less_than_the_fin_models_deliverable_force() -> None:
    cfg = LoopConfig()
    ex = cfg.executor
    full = deliverable_force(cfg.mpc, ex.acceleration, ex.max_rate)
    forces = [peak(cfg, f) for f in (0.5, 0.75, 1.0)]
    assert forces == sorted(forces)  # the faster the beat, the more it makes
    assert forces[0] < 0.25 * full  # 0.5 Hz: a fraction of what the fin model can make


def test_the_loop_limits_the_fins_by_the_mode_and_the_baseline_frequency_in_force() -> None:
    cfg = LoopConfig(mode="baseline", baseline=BaselineConfig(frequency=0.5))
    ex = cfg.executor
    full = deliverable_force(cfg.mpc, ex.acceleration, ex.max_rate)
    loop = ClosedLoop(cfg, SimRobotIO(depth=1.0, velocity=0.1, seed=0), TelemetryStream(),
                      setpoints=BodySetpoints(velocity=0.1, depth=1.0))
    try:
        assert loop.body.fin_force == pytest.approx(peak(cfg, 0.5))
        limits_slow = loop.body.state[B_ALLOC:B_ALLOC + NA].copy()
        loop.submit(SetBlock("baseline", cfg.baseline.replace(frequency=2.0), "pilot"))
        loop.run_until(0.2)
        assert loop.body.fin_force == pytest.approx(min(full, peak(cfg, 2.0)))  # 2 Hz: the fin model's
        loop.submit(SetBlock("baseline", cfg.baseline.replace(frequency=0.75), "pilot"))
        loop.run_until(0.4)
        assert loop.body.fin_force == pytest.approx(peak(cfg, 0.75))
        loop.submit(SetMode("mpc", "pilot"))
        loop.run_until(0.6)
        assert loop.body.fin_force == pytest.approx(full)  # the MPC chooses its own rate
        loop.submit(SetMode("baseline", "pilot"))
        loop.submit(SetBlock("baseline", cfg.baseline.replace(frequency=0.5), "pilot"))
        loop.run_until(0.8)
        assert np.array_equal(loop.body.state[B_ALLOC:B_ALLOC + NA], limits_slow)
    finally:
        loop.close()


def test_at_a_slow_beat_a_surge_beyond_the_fins_is_cut_and_the_yaw_moment_kept() -> None:
    cfg = LoopConfig(mode="baseline", baseline=BaselineConfig(frequency=0.5))
    loop = ClosedLoop(cfg, SimRobotIO(depth=1.0, velocity=0.1, seed=0), TelemetryStream(),
                      setpoints=BodySetpoints(velocity=0.1, depth=1.0))
    try:
        params = loop.body.state[B_ALLOC:B_ALLOC + NA]
        a = allocate_body_wrench(1.3, 0.0, -0.05, params)  # what the loops asked at 0.5 Hz
        assert "surge" in a.cut and "yaw" not in a.cut
        assert a.applied[2] == pytest.approx(-0.05)
        assert all(np.hypot(*f) <= loop.body.fin_force * (1 + 1e-9) for f in a.allocation.per_fin())
    finally:
        loop.close()


def test_the_body_loops_follow_the_fins_cycles_under_the_baseline_only() -> None:
    from ucat_console.control.params import DESIGN_DELAY
    from ucat_console.control.pid import PID_KP

    cfg = LoopConfig(mode="baseline", baseline=BaselineConfig(frequency=0.5))
    loop = ClosedLoop(cfg, SimRobotIO(depth=1.0, velocity=0.1, seed=0), TelemetryStream(),
                      setpoints=BodySetpoints(velocity=0.1, depth=1.0))
    try:
        loop.run_until(20.0)  # 2-s cycles: the loops run the gains of a 2-s delay
        assert loop.body.delay == pytest.approx(cfg.body.schedule_max_delay, rel=0.05)
        kp_slow = loop.body.yaw_pid.state[PID_KP]
        loop.submit(SetMode("mpc", "pilot"))
        loop.run_until(20.5)
        assert loop.body.delay == DESIGN_DELAY  # the MPC holds its cycles: the configured gains
        assert loop.body.yaw_pid.scale == (1.0, 1.0, 1.0) and loop.body.yaw_pid.state[PID_KP] != kp_slow
        loop.submit(SetMode("baseline", "pilot"))
        loop.run_until(21.0)
        assert loop.body.delay == pytest.approx(cfg.body.schedule_max_delay)  # from the longest, as after a reset
    finally:
        loop.close()
