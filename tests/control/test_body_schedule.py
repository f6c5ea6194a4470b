"""The designed body layer scheduled on the fins' executed cycle period: the gains follow the
period (bounded, low-passed, so they move smoothly); cycles of the design delay or shorter
keep the configured gains; the speed low-pass stays as configured."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ucat_console.control import body as bd
from ucat_console.control import pid as pd
from ucat_console.control.body import BodyController
from ucat_console.control.body_design import HullModel, designed_gains, gain_schedule
from ucat_console.control.params import DESIGN_DELAY, DESIGN_FACTOR, BodyConfig, PidGains
from ucat_console.control.pid import Pid


def scheduled(**kw) -> BodyConfig:
    """The designed layer scheduled on the fins' cycles (off by default)."""
    return BodyConfig(**{"schedule": True, **kw})


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
    cfg = scheduled()
    ctl = BodyController(cfg)
    assert ctl.delay == cfg.schedule_max_delay  # before the fins' cycles are known: the longest
    assert gains_run(ctl, "depth")[0] < cfg.depth.kp
    cycles(ctl, 0.5, 2000)  # the baseline's 2 Hz
    cycles(ctl, DESIGN_DELAY, 40, 1000.0)
    assert ctl.delay == DESIGN_DELAY
    for loop, _ in LOOPS:
        g = getattr(cfg, loop)
        assert gains_run(ctl, loop) == (g.kp, g.ki, g.kd)
    assert ctl.state[bd.B_SPEED_TAU] == cfg.speed_filter


def test_long_cycles_run_the_gains_designed_for_their_period_within_the_bound():
    cfg = scheduled(schedule_max_delay=2.5)
    ctl = BodyController(cfg)
    cycles(ctl, 1.8, 200)  # 360 s: the low-passed estimate has come down from the longest delay
    assert ctl.delay == pytest.approx(1.8, rel=1e-3)
    scale = gain_schedule(cfg.hull, ctl.delay, DESIGN_DELAY, DESIGN_FACTOR)
    for loop, name in LOOPS:
        g, k = getattr(cfg, loop), scale[name]
        assert gains_run(ctl, loop) == pytest.approx((g.kp * k.kp, g.ki * k.ki, g.kd * k.kd))
    assert ctl.state[bd.B_SPEED_TAU] == cfg.speed_filter  # the speed low-pass is not scheduled
    cycles(ctl, 6.0, 30, 400.0)  # beyond the bound
    assert ctl.delay == pytest.approx(2.5)
    cycles(ctl, 1.0, 1000, 1000.0)
    assert ctl.delay == DESIGN_DELAY
    ctl.reset()
    assert ctl.delay == cfg.schedule_max_delay


def test_the_delay_follows_longer_cycles_quickly_and_shorter_ones_slowly():
    cfg = scheduled(schedule_rise=2.0, schedule_filter=20.0)
    ctl = BodyController(cfg)
    cycles(ctl, 1.0, 1000)
    assert ctl.delay == DESIGN_DELAY
    t = cycles(ctl, 2.0, 2, 1000.0)  # one long cycle of each fin: the first fin moves the delay most
    assert ctl.delay == pytest.approx(2.0 - 0.75 * math.exp(-2.0 / 2.0), abs=0.02)
    t = cycles(ctl, 2.0, 5, t + 2.0)
    high = ctl.delay
    assert high == pytest.approx(2.0, abs=0.01)
    t = cycles(ctl, 1.0, 6, t + 1.0)  # 6 s of short cycles
    assert high - 0.75 * (1.0 - math.exp(-6.0 / 20.0)) - 0.02 < ctl.delay < high - 0.1
    cycles(ctl, 1.0, 200, t + 1.0)
    assert ctl.delay == pytest.approx(DESIGN_DELAY, abs=1e-3)


def test_the_gains_move_smoothly():
    """Each cycle moves the gains by a fraction of the way only: no fin's single long cycle
    changes a gain by more than schedule_rise allows."""
    ctl = BodyController(scheduled())
    cycles(ctl, 1.0, 1000)
    kp = [gains_run(ctl, "yaw_rate")[0]]
    t = 1000.0
    for _ in range(12):
        t += 0.5
        for k in range(4):
            ctl.on_cycle(k, (-0.1, 0.0), (-0.1, 0.0), t + 0.1 * k)
            kp.append(gains_run(ctl, "yaw_rate")[0])
    steps = np.abs(np.diff(kp)) / kp[0]
    assert steps.max() < 0.2
    cycles(ctl, 2.0, 20, t + 2.0)
    assert gains_run(ctl, "yaw_rate")[0] < 0.5 * kp[0]


def test_unscheduled_or_paper_layers_keep_their_gains():
    paper = scheduled(layer="paper", yaw_rate=PidGains(kp=3.0, limit=0.5))
    for cfg in (BodyConfig(), scheduled(schedule=False), paper):
        ctl = BodyController(cfg)
        before = gains_run(ctl, "velocity")
        cycles(ctl, 3.0, 30)
        assert gains_run(ctl, "velocity") == before


def test_the_bounds_are_checked():
    with pytest.raises(ValueError, match="schedule_min_delay"):
        scheduled(schedule_min_delay=2.0, schedule_max_delay=1.5)
    with pytest.raises(ValueError, match="t"):
        BodyController(scheduled()).on_cycle(0, (-0.1, 0.0), (-0.1, 0.0), math.nan)


def test_a_scheduled_pid_runs_its_gains_scaled_and_keeps_its_integral():
    p = Pid(PidGains(kp=2.0, ki=0.5, kd=1.0, limit=100.0))
    p.update((1.0, 0.0), 0.0)
    p.update((1.0, 0.3), 0.5)
    integral = p.integral
    p.schedule((0.5, 0.25, 0.4))
    s = p.state
    assert (s[pd.PID_KP], s[pd.PID_KI], s[pd.PID_KD]) == pytest.approx((1.0, 0.125, 0.4))
    assert p.integral == integral
    p.set_gains(PidGains(kp=4.0, ki=0.5, kd=1.0, limit=100.0))  # new gains keep the schedule
    assert s[pd.PID_KP] == pytest.approx(2.0)
    with pytest.raises(ValueError, match="scale.kd"):
        p.schedule((1.0, 1.0, -1.0))
