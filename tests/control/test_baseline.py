"""Baseline inverse model (control.md section 6): eq 19, saturation, centre direction."""

from __future__ import annotations

import math

import pytest

from ucat_console.control.baseline import (
    BaselinePlanner,
    baseline_amplitude,
    baseline_gain,
    wrap_angle,
)
from ucat_console.control.params import BaselineConfig, MpcConfig

CFG = MpcConfig()
BCFG = BaselineConfig()


def cycle_mean_force(theta0: float, commands, cfg: MpcConfig) -> tuple[float, float]:
    """Duration-weighted mean body force of a command sequence, eqs 2-8 and 13-14 of the spec,
    written out here independently of the package."""
    theta = theta0
    sx = sy = total = 0.0
    for k in range(0, len(commands), 2):
        target, w = commands[k], commands[k + 1]
        d = target - theta
        v = cfg.r_c * w
        drag = 0.5 * cfg.rho * cfg.c_d * cfg.fin_area * v * v
        lift = 0.5 * cfg.rho * cfg.c_l * cfg.fin_area * v * v
        thr = d / 2.0
        fxl = -lift * math.cos(thr) - drag * math.sin(thr)
        fyl = -lift * math.sin(thr) - drag * math.cos(thr)
        thm = theta + d / 2.0
        fx = math.cos(thm) * fxl - math.sin(thm) * fyl
        fy = math.sin(thm) * fxl + math.cos(thm) * fyl
        dt = abs(d) / w
        sx += fx * dt
        sy += fy * dt
        total += dt
        theta = target
    return sx / total, sy / total


def test_gain_matches_hand_value():
    # 8 * 0.7 * 1000 * 0.02 * (0.1 * pi * 2)^2 = 112 * 0.394784 = 44.2158 N
    assert baseline_gain(CFG, BCFG) == pytest.approx(44.2158, abs=1e-3)


def test_amplitude_of_one_newton():
    # arccos(1 - 1 / 44.2158) = arccos(0.977384)
    assert baseline_amplitude(1.0, CFG, BCFG) == pytest.approx(math.acos(0.977384), abs=1e-5)
    # small-angle series: sqrt(2x) (1 + x/12) with x = 0.0226163 -> 0.21308
    assert baseline_amplitude(1.0, CFG, BCFG) == pytest.approx(0.21308, abs=1e-5)


def test_zero_force_gives_zero_amplitude():
    assert baseline_amplitude(0.0, CFG, BCFG) == 0.0


def test_large_force_saturates_at_d_max():
    # 30 N: arccos(1 - 30/44.2158) = arccos(0.32150) = 1.2435 rad > d_max = 1.2
    assert baseline_amplitude(30.0, CFG, BCFG) == CFG.d_max
    # 1000 N: argument below -1 is clipped (arccos(-1) = pi), then the amplitude to d_max
    assert baseline_amplitude(1000.0, CFG, BCFG) == CFG.d_max
    # 28 N: arccos(0.36674) = 1.1953 rad, just below the limit
    assert baseline_amplitude(28.0, CFG, BCFG) == pytest.approx(1.1953, abs=1e-4)
    wide = CFG.replace(d_max=3.14159)  # arccos(-1) = pi, then clipped to 3.14159
    assert baseline_amplitude(1000.0, wide, BCFG) == 3.14159


@pytest.mark.parametrize("bad", [-0.1, math.nan, math.inf])
def test_amplitude_rejects_bad_force(bad):
    with pytest.raises(ValueError, match="force_magnitude"):
        baseline_amplitude(bad, CFG, BCFG)


def test_centre_by_hand():
    planner = BaselinePlanner(CFG, BCFG)
    # zero direction = atan2(-0.7, -0.25) = -pi + atan(2.8); forward request (-1, 0) points at
    # pi, so the centre is pi - (-pi + atan(2.8)) = 2 pi - atan(2.8) -> -atan(2.8) = -1.22777
    assert planner.centre(-1.0, 0.0, 0.2) == pytest.approx(-1.2277724, abs=1e-6)
    # (0, 1): pi/2 + pi - atan(2.8) = 3.48461 -> -2.79857 after wrapping
    assert planner.centre(0.0, 1.0, 0.2) == pytest.approx(-2.7985687, abs=1e-6)
    # above pi/2 the mean force flips (cos A < 0), so the centre turns by pi
    flipped = planner.centre(-1.0, 0.0, 2.0)
    assert wrap_angle(flipped - math.pi) == pytest.approx(-1.2277724, abs=1e-6)


@pytest.mark.parametrize(
    "target", [(-0.5, 0.5), (-1.0, 0.0), (0.0, 1.0), (-0.2, 0.9), (0.3, -0.2), (-0.2, -0.7)]
)
def test_mean_force_points_along_request(target):
    planner = BaselinePlanner(CFG, BCFG)
    first = planner.plan(*target, theta_now=0.3)
    # steady state: the second cycle starts where the first ended
    steady = planner.plan(*target, theta_now=first.commands[2])
    c, a = steady.centre, steady.amplitude
    ended_high = first.commands[2] == pytest.approx(c + a)
    assert ended_high or first.commands[2] == pytest.approx(c - a)
    # the next cycle sweeps the full 2A from the extreme it starts at to the other and back
    assert steady.commands[0] == pytest.approx(c - a if ended_high else c + a)
    assert steady.commands[2] == pytest.approx(first.commands[2])
    fx, fy = cycle_mean_force(first.commands[2], steady.commands, CFG)
    want = math.atan2(target[1], target[0])
    got = math.atan2(fy, fx)
    assert abs(wrap_angle(got - want)) < 1e-9
    assert math.hypot(fx, fy) > 0.0


def test_plan_rate_and_format():
    eq19 = BCFG.replace(inverse_model="eq19")
    planner = BaselinePlanner(CFG, eq19)
    plan = planner.plan(-0.5, 0.5, theta_now=0.0)
    a = plan.amplitude
    assert a == pytest.approx(baseline_amplitude(math.hypot(0.5, 0.5), CFG, eq19))
    # a full stroke of 2A in half a period of 2 Hz: w = 2A / 0.25 s = 8A
    assert plan.u[2] == plan.u[3] == pytest.approx(8.0 * a)
    assert plan.commands[1] == plan.commands[3] == plan.u[2]
    # strokes join: theta_now + d_1 = theta_1, theta_1 + d_2 = theta_2
    assert 0.0 + plan.u[0] == pytest.approx(plan.commands[0])
    assert plan.commands[0] + plan.u[1] == pytest.approx(plan.commands[2])
    assert {plan.commands[0], plan.commands[2]} == {plan.centre + a, plan.centre - a}
    assert plan.frequency == 2.0


@pytest.mark.parametrize("force", [0.05, 0.3, 0.7, 1.1])
def test_the_fin_model_inverse_makes_the_requested_force(force):
    """The default inverse: the plan's strokes, through the fin model written out here, make
    the requested mean force in the requested direction."""
    planner = BaselinePlanner(CFG, BCFG)
    target = (-force * 0.6, force * 0.8)
    first = planner.plan(*target, theta_now=0.0)
    steady = planner.plan(*target, theta_now=first.commands[2])
    fx, fy = cycle_mean_force(first.commands[2], steady.commands, CFG)
    assert math.hypot(fx, fy) == pytest.approx(force, rel=1e-6)
    assert abs(wrap_angle(math.atan2(fy, fx) - math.atan2(*target[::-1]))) < 1e-9
    # the drive can make the strokes: a stroke of 2A from rest to rest at 64 rad/s2 has a mean
    # rate of at most sqrt(64 * 2A) / 2
    a = steady.amplitude
    assert steady.u[2] <= math.sqrt(64.0 * 2.0 * a) / 2.0 + 1e-9


def test_eq19_asks_for_about_a_fifth_of_the_force_the_fin_model_gives():
    """Eq 19 expects pi^2 C_D / (2 sqrt(C_L^2 + C_D^2)) = 4.65 times the fin model's force
    of a small beat: its amplitude for 0.2 N makes 0.2 / 4.65 N by the model."""
    eq19 = BaselinePlanner(CFG, BCFG.replace(inverse_model="eq19"))
    ratio = math.pi ** 2 * CFG.c_d / (2.0 * math.hypot(CFG.c_l, CFG.c_d))
    assert ratio == pytest.approx(4.648, abs=1e-3)
    first = eq19.plan(-0.2, 0.0, theta_now=0.0)
    steady = eq19.plan(-0.2, 0.0, theta_now=first.commands[2])
    assert steady.u[2] > CFG.w_min  # not floored
    fx, fy = cycle_mean_force(first.commands[2], steady.commands, CFG)
    assert math.hypot(fx, fy) == pytest.approx(0.2 / ratio, rel=5e-3)


def test_a_force_beyond_the_fin_gets_the_largest_beat():
    planner = BaselinePlanner(CFG, BCFG)
    big = planner.plan(-50.0, 0.0, theta_now=0.0)
    bigger = planner.plan(-500.0, 0.0, theta_now=0.0)
    assert big.amplitude == pytest.approx(bigger.amplitude)
    slightly_less = planner.plan(-1.0, 0.0, theta_now=0.0)
    assert slightly_less.amplitude < big.amplitude


def test_first_stroke_goes_to_the_far_extreme():
    planner = BaselinePlanner(CFG, BCFG)
    ref = planner.plan(-1.0, 0.0, theta_now=0.0)
    c, a = ref.centre, ref.amplitude  # c = -1.2278, a = 0.2132
    below = planner.plan(-1.0, 0.0, theta_now=c - a)
    assert below.commands[0] == pytest.approx(c + a)
    above = planner.plan(-1.0, 0.0, theta_now=c + a + 0.01)
    assert above.commands[0] == pytest.approx(c - a)
    assert above.commands[2] == pytest.approx(c + a)


def test_zero_request_holds_the_fin():
    planner = BaselinePlanner(CFG, BCFG)
    plan = planner.plan(0.0, 0.0, theta_now=0.7)
    assert plan.amplitude == 0.0
    assert plan.commands == (0.7, CFG.w_min, 0.7, CFG.w_min)
    assert plan.u == (0.0, 0.0, CFG.w_min, CFG.w_min)


def test_plan_rejects_non_finite():
    planner = BaselinePlanner(CFG, BCFG)
    with pytest.raises(ValueError, match="fy"):
        planner.plan(0.0, math.nan, 0.0)
    with pytest.raises(ValueError, match="theta_now"):
        planner.plan(0.0, 0.1, math.inf)


def test_zero_drag_coefficient_rejected():
    with pytest.raises(ValueError, match="c_d"):
        BaselinePlanner(CFG.replace(c_d=0.0), BCFG)


def test_a_fin_behind_the_others_beat_shortens_its_next_cycle_by_a_share_of_its_lag() -> None:
    from ucat_console.control.baseline import PHASE_STEP

    planner = BaselinePlanner(MpcConfig(), BaselineConfig(frequency=1.25, phase_gain=0.25))
    free = planner.plan(-0.5, 0.2, -1.0)
    sweep = abs(free.u[0]) + abs(free.u[1])
    length = sweep / free.u[2]
    for lag in (0.1 * length, -0.1 * length, 0.15 * length):  # inside the step's bound
        p = planner.plan(-0.5, 0.2, -1.0, lag)
        assert p.u[:2] == free.u[:2] and p.commands[0::2] == free.commands[0::2]  # the same strokes
        assert p.u[2] == p.u[3] == p.commands[1] == p.commands[3]
        assert sweep / p.u[2] == pytest.approx(length - 0.25 * lag)  # behind: shorter; ahead: longer
    # at most PHASE_STEP of the cycle either way; without a gain, or holding still, no change
    assert sweep / planner.plan(-0.5, 0.2, -1.0, 10.0).u[2] == pytest.approx(length * (1 - PHASE_STEP))
    assert sweep / planner.plan(-0.5, 0.2, -1.0, -10.0).u[2] == pytest.approx(length * (1 + PHASE_STEP))
    unlocked = BaselinePlanner(MpcConfig(), BaselineConfig(frequency=1.25, phase_gain=0.0))
    assert unlocked.plan(-0.5, 0.2, -1.0, 0.3).u == free.u
    assert planner.plan(0.0, 0.0, -1.0, 0.3).u == planner.plan(0.0, 0.0, -1.0).u
    with pytest.raises(ValueError, match="lag"):
        planner.plan(-0.5, 0.2, -1.0, math.nan)
