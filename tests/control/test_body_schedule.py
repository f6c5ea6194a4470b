"""The designed body layer scheduled on the fins' executed cycle period: the gains and the
speed low-pass follow the period (bounded, filtered), bumplessly; cycles of the design delay
or shorter keep the configured gains."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ucat_console.control import body as bd
from ucat_console.control import pid as pd
from ucat_console.control.allocation import BodySetpoints
from ucat_console.control.body import BodyController
from ucat_console.control.body_design import HullModel, designed_gains, gain_schedule
from ucat_console.control.params import DESIGN_DELAY, DESIGN_FACTOR, BodyConfig, PidGains
from ucat_console.control.pid import Pid
from ucat_console.robot.readings import DepthReading, DvlVelocity, ImuReading

LOOPS = (("velocity", "velocity"), ("depth", "depth"), ("yaw_rate", "heading"))


def gains_run(ctl: BodyController, loop: str) -> tuple[float, float, float]:
    s = ctl.pid(loop).state
    return float(s[pd.PID_KP]), float(s[pd.PID_KI]), float(s[pd.PID_KD])


def cycles(ctl: BodyController, period: float, n: int, t0: float = 0.0) -> float:
    """Every paper fin begins a cycle each ``period`` s, ``n`` times; the last time."""
    t = t0
    for _ in range(n):
        for k in range(4):
            ctl.on_cycle(k, (-0.1, 0.0), (-0.1, 0.0), t)
        t += period
    return t - period


def test_the_schedule_at_the_design_delay_is_one():
    g = gain_schedule(HullModel(), DESIGN_DELAY, DESIGN_DELAY, DESIGN_FACTOR)
    assert all(x == 1.0 for a in g.values() for x in (a.kp, a.ki, a.kd))


def test_the_schedule_is_the_ratio_of_the_designed_gains():
    hull = HullModel()
    g = gain_schedule(hull, 2.0, DESIGN_DELAY, DESIGN_FACTOR)
    slow, shipped = designed_gains(hull, 2.0, DESIGN_FACTOR), designed_gains(hull, DESIGN_DELAY, DESIGN_FACTOR)
    for loop in ("velocity", "depth", "heading"):
        assert g[loop].kp * shipped[loop].kp == pytest.approx(slow[loop].kp)
        assert g[loop].ki * shipped[loop].ki == pytest.approx(slow[loop].ki)
        assert g[loop].kp < 1.0 and g[loop].ki < 1.0  # a longer delay: slower loops
    assert g["depth"].kd == 1.0  # the heave loop is proportional: no kd to scale


def test_cycles_no_longer_than_the_design_delay_keep_the_configured_gains():
    cfg = BodyConfig()
    ctl = BodyController(cfg)
    before = {loop: gains_run(ctl, loop) for loop, _ in LOOPS}
    cycles(ctl, 0.5, 40)  # the baseline's 2 Hz
    cycles(ctl, DESIGN_DELAY, 40, 20.0)
    assert ctl.delay == DESIGN_DELAY
    for loop, _ in LOOPS:
        assert gains_run(ctl, loop) == before[loop]
        g = getattr(cfg, loop)
        assert gains_run(ctl, loop) == (g.kp, g.ki, g.kd)
    assert ctl.state[bd.B_SPEED_TAU] == cfg.speed_filter


def test_long_cycles_run_the_gains_designed_for_their_period_within_the_bound():
    cfg = BodyConfig(schedule_max_delay=2.5)
    ctl = BodyController(cfg)
    cycles(ctl, 1.8, 60)  # 108 s: the filtered estimate has settled
    assert ctl.delay == pytest.approx(1.8, rel=1e-3)
    scale = gain_schedule(cfg.hull, ctl.delay, DESIGN_DELAY, DESIGN_FACTOR)
    for loop, name in LOOPS:
        g, k = getattr(cfg, loop), scale[name]
        assert gains_run(ctl, loop) == pytest.approx((g.kp * k.kp, g.ki * k.ki, g.kd * k.kd))
    assert ctl.state[bd.B_SPEED_TAU] == pytest.approx(cfg.speed_filter * 1.8 / DESIGN_DELAY)
    cycles(ctl, 6.0, 30, 200.0)  # beyond the bound
    assert ctl.delay == pytest.approx(2.5)
    ctl.reset()
    assert ctl.delay == cfg.schedule_min_delay
    assert gains_run(ctl, "depth") == (cfg.depth.kp, cfg.depth.ki, cfg.depth.kd)


def test_the_period_estimate_is_low_passed():
    ctl = BodyController(BodyConfig(schedule_filter=5.0))
    cycles(ctl, 1.0, 10)
    t = cycles(ctl, 2.0, 2, 10.0)  # one long cycle of each fin
    assert DESIGN_DELAY < ctl.delay < 1.9
    cycles(ctl, 2.0, 30, t + 2.0)
    assert ctl.delay == pytest.approx(2.0, rel=1e-3)


def test_unscheduled_or_paper_layers_keep_their_gains():
    for cfg in (BodyConfig(schedule=False), BodyConfig(layer="paper", yaw_rate=PidGains(kp=3.0, limit=0.5))):
        ctl = BodyController(cfg)
        before = gains_run(ctl, "velocity")
        cycles(ctl, 3.0, 30)
        assert gains_run(ctl, "velocity") == before


def test_the_bounds_are_checked():
    with pytest.raises(ValueError, match="schedule_min_delay"):
        BodyConfig(schedule_min_delay=2.0, schedule_max_delay=1.5)
    with pytest.raises(ValueError, match="t"):
        BodyController(BodyConfig()).on_cycle(0, (-0.1, 0.0), (-0.1, 0.0), math.nan)


def test_a_pid_rescheduled_gives_the_same_output_then_runs_the_new_gains():
    p = Pid(PidGains(kp=2.0, ki=0.5, kd=1.0, limit=100.0))
    p.update((1.0, 0.0), 0.0)
    before = p.update((1.0, 0.3), 0.5)  # proportional, integral and derivative terms all nonzero
    p.schedule((0.5, 0.25, 0.4))
    s = p.state
    assert (s[pd.PID_KP], s[pd.PID_KI], s[pd.PID_KD]) == pytest.approx((1.0, 0.125, 0.4))
    assert p.update((1.0, 0.3), 0.5) == pytest.approx(before)  # same time, same inputs: no bump
    p.set_gains(PidGains(kp=4.0, ki=0.5, kd=1.0, limit=100.0))  # new gains keep the schedule
    assert s[pd.PID_KP] == pytest.approx(2.0)
    with pytest.raises(ValueError, match="scale.kd"):
        p.schedule((1.0, 1.0, -1.0))


def test_the_loops_outputs_do_not_jump_when_the_schedule_moves():
    """Speed, depth and heading held off their references, a long cycle moves the schedule:
    the next control step on the same readings asks for what an unscheduled twin asks; the
    steps after it run the new gains."""
    cfg = BodyConfig(median_window=1, schedule_filter=0.0, schedule_max_delay=3.0)
    ctl, twin = BodyController(cfg), BodyController(cfg.replace(schedule=False))
    sp = BodySetpoints(velocity=0.2, depth=1.0)

    def step(t: float, yaw: float | None) -> list[np.ndarray]:
        q = None if yaw is None else (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
        out = []
        for c in (ctl, twin):
            c.on_dvl(DvlVelocity(t=t, vx=0.1, vy=0.0, vz=0.0, valid=True, altitude=1.0, fom=0.01))
            c.on_depth(DepthReading(t=t, depth_m=0.8, pressure_pa=0.0))
            c.on_imu(ImuReading(t=t, accel=(0.0, 0.0, 9.8), gyro=(0.0, 0.0, 0.01), quaternion=q))
            out.append(np.array(c.update(t, sp).outputs))
        return out

    for i in range(60):
        step(0.1 * i, 0.025 * i if i < 30 else None)
    for k in range(4):
        ctl.on_cycle(k, (-0.1, 0.0), (-0.1, 0.0), 3.0)
        ctl.on_cycle(k, (-0.1, 0.0), (-0.1, 0.0), 5.9)
    assert ctl.delay == pytest.approx(2.9)  # within the bound: the time between the two cycles
    for pid in (ctl.velocity_pid, ctl.depth_pid, ctl.yaw_pid):
        assert pid.state[pd.PID_KP] < pid.gains.kp
    scheduled, unscheduled = step(5.9, None)
    assert np.all(np.abs(unscheduled) > 1e-3)
    assert scheduled == pytest.approx(unscheduled, abs=1e-9)
    scheduled, unscheduled = step(6.5, None)
    assert not np.allclose(scheduled, unscheduled, atol=1e-4)
