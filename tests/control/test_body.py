"""The body-frame layer: the paper's loops (signs, data handling, the compiled functions
against the reference), the designed loops (references, feed-forward, heading hold, the
allocation's cut fed back), and the gains' design."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ucat_console.control import body as bd
from ucat_console.control.allocation import BodySetpoints
from ucat_console.control.body import BodyController
from ucat_console.control.body_design import HullModel, designed_gains, position_gains, velocity_gains
from ucat_console.control.params import PAPER_BODY, BodyConfig, MpcConfig, PidGains
from ucat_console.robot.fins import PAPER_SIDES as FIN_SIDES
from ucat_console.robot.readings import DepthReading, DvlVelocity, ImuReading

B = 0.2981


def yaw_moment(per_fin) -> float:
    return sum(-(side * B) * (-fx) for side, (fx, _fy) in zip(FIN_SIDES, per_fin))


def dvl(t, vx, valid=True):
    return DvlVelocity(t=t, vx=vx, vy=0.0, vz=0.0, valid=valid, altitude=1.0, fom=0.01)


def imu(t, r, yaw=None):
    q = None if yaw is None else (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
    return ImuReading(t=t, accel=(0.0, 0.0, 9.80665), gyro=(0.0, 0.0, r), quaternion=q)


def paper_cfg(**kw) -> BodyConfig:
    base = dict(
        velocity=PidGains(kp=2.0, limit=2.5),
        depth=PidGains(kp=5.0, limit=0.5),
        yaw_rate=PidGains(kp=3.0, limit=0.5),
        median_window=3,
    )
    base.update(kw)
    return PAPER_BODY.replace(**base)


# ------------------------------------------------------------------ the paper's layer
def test_velocity_error_gives_forward_thrust_negative_fx():
    ctl = BodyController(paper_cfg())
    ctl.on_dvl(dvl(0.0, 0.1))
    cmd = ctl.update(0.0, BodySetpoints(velocity=0.3))
    # F_x* = -kp (0.3 - 0.1) = -0.4
    assert cmd.outputs[0] == pytest.approx(-0.4)
    assert cmd.velocity_updated
    assert all(fx == pytest.approx(-0.1) for fx, _ in cmd.allocation.per_fin())


def test_missing_dvl_holds_output_and_is_not_zero_velocity():
    ctl = BodyController(paper_cfg())
    ctl.on_dvl(dvl(0.0, 0.1))
    first = ctl.update(0.0, BodySetpoints(velocity=0.3))
    for k in range(1, 6):
        ctl.on_dvl(dvl(0.1 * k, 0.0, valid=False))
        cmd = ctl.update(0.1 * k, BodySetpoints(velocity=0.3))
        assert cmd.outputs[0] == first.outputs[0]  # held; zero velocity would give -0.6
        assert not cmd.velocity_updated
        assert cmd.velocity == pytest.approx(0.1)
    assert ctl.dvl_missing == 5


def test_no_dvl_yet_gives_no_thrust_and_no_velocity():
    for cfg in (paper_cfg(), BodyConfig()):
        ctl = BodyController(cfg)
        cmd = ctl.update(0.0, BodySetpoints(velocity=0.3))
        assert cmd.velocity is None
        assert cmd.outputs[0] == 0.0
        assert all(fx == 0.0 for fx, _ in cmd.allocation.per_fin())


def test_median_filter_removes_dvl_spike():
    ctl = BodyController(paper_cfg())
    for t, v in ((0.0, 0.2), (0.1, 0.2), (0.2, 3.0)):
        ctl.on_dvl(dvl(t, v))
    cmd = ctl.update(0.2, BodySetpoints(velocity=0.2))
    assert cmd.velocity == pytest.approx(0.2)
    assert cmd.outputs[0] == pytest.approx(0.0)


def test_depth_sign_and_front_lift():
    ctl = BodyController(paper_cfg())
    ctl.on_depth(DepthReading(t=0.0, depth_m=1.95, pressure_pa=0.0))
    cmd = ctl.update(0.0, BodySetpoints(depth=2.0))
    # too shallow by 0.05 m: the default asks for a downward force (f_y > 0 lifts):
    # F_y* = -5 * 0.05 = -0.25, half on each front fin
    assert cmd.outputs[1] == pytest.approx(-0.25)
    fins = cmd.allocation.per_fin()
    assert fins[0][1] == fins[1][1] == pytest.approx(-0.125)
    flipped = BodyController(paper_cfg(depth_sign=1.0))
    flipped.on_depth(DepthReading(t=0.0, depth_m=1.95, pressure_pa=0.0))
    assert flipped.update(0.0, BodySetpoints(depth=2.0)).outputs[1] == pytest.approx(0.25)


def test_yaw_rate_command_turns_to_starboard():
    ctl = BodyController(paper_cfg())
    ctl.on_imu(imu(0.0, 0.0))
    ctl.on_dvl(dvl(0.0, 0.2))
    cmd = ctl.update(0.0, BodySetpoints(velocity=0.2, yaw_rate=0.1))
    assert cmd.outputs[2] == pytest.approx(0.3)  # 3 * 0.1
    fins = cmd.allocation.per_fin()
    assert fins[1][0] < fins[0][0]  # port front fin pushes forward harder (more negative f_x)
    assert yaw_moment(fins) > 0.0


def test_bad_readings_and_setpoints():
    ctl = BodyController(paper_cfg())
    with pytest.raises(ValueError, match="dvl.vx"):
        ctl.on_dvl(dvl(0.0, math.nan))
    with pytest.raises(ValueError, match="depth"):
        BodySetpoints(depth=-1.0)
    with pytest.raises(ValueError, match="velocity"):
        BodySetpoints(velocity=math.inf)


def test_the_compiled_body_layer_is_the_reference_on_random_readings():
    """The paper layer's functions compiled (as the loop's core runs them) against the
    Python controller the loop ran before: random DVL (with dropouts), depth and gyro
    readings in random order between control steps, three setpoints; the same outputs and
    filtered values at every step, bit for bit."""
    from numba import njit

    from control.reference_kernels import ReferenceBody

    on_dvl = njit(lambda b, valid, v, t: bd.body_on_dvl(b, valid, v, t))
    on_depth = njit(lambda b, z, t: bd.body_on_depth(b, z, t))
    on_imu = njit(lambda b, r, t: bd.body_on_imu(b, r, t))
    update = njit(lambda b, t, v, z, r: bd.body_update(b, t, v, z, r, False))
    rng = np.random.default_rng(11)
    for window in (1, 4, 5):
        cfg = PAPER_BODY.replace(median_window=window)
        b = BodyController(cfg).state
        ref = ReferenceBody(cfg)
        t = 0.0
        sp = (0.2, 1.0, 0.05)
        for _ in range(400):
            t += 0.005
            kind = rng.integers(0, 5)
            if kind == 0:
                valid = bool(rng.random() > 0.1)
                v = float(rng.normal(0.2, 0.05))
                assert on_dvl(b, valid, v, t) == bd.BODY_OK
                ref.on_dvl(valid, v)
            elif kind == 1:
                z = float(rng.normal(1.0, 0.1))
                assert on_depth(b, z, t) == bd.BODY_OK
                ref.on_depth(z)
            elif kind == 2:
                r = float(rng.normal(0.0, 0.1))
                assert on_imu(b, r, t) == bd.BODY_OK
                ref.on_imu(r)
            else:
                status, v, z = update(b, t, *sp)
                rv, rz = ref.update(t, sp)
                assert status == bd.BODY_OK
                assert (math.isnan(v) and rv is None) or v == rv
                assert (math.isnan(z) and rz is None) or z == rz
                assert (b[bd.B_FX], b[bd.B_FY], b[bd.B_YAW]) == (ref.fx, ref.fy, ref.yaw)
        assert b[bd.B_DVL_MISSING] == ref.dvl_missing


def test_the_compiled_body_layer_names_a_bad_reading():
    from numba import njit

    b = BodyController(BodyConfig()).state
    on_depth = njit(lambda b, z, t: bd.body_on_depth(b, z, t))
    assert bd.BODY_FIELDS[on_depth(b, math.nan, 0.0)] == "depth.depth_m"
    assert bd.BODY_FIELDS[on_depth(b, 1.0, math.inf)] == "depth.t"
    assert np.isnan(b[bd.B_LAST_DEPTH_T])  # nothing was taken


# ------------------------------------------------------------------ the designed layer
def designed(**kw) -> BodyController:
    """The designed layer on its configured gains (not scheduled on the fins' cycles: no fin
    runs here; ``test_body_schedule.py``)."""
    return BodyController(BodyConfig(**{"schedule": False, **kw}), MpcConfig())


def test_the_depth_reference_ramps_at_the_dive_rate_with_the_hull_drag_as_feed_forward():
    ctl = designed(median_window=1)
    cfg = ctl.cfg
    hull = cfg.hull
    ctl.on_depth(DepthReading(t=0.0, depth_m=0.5, pressure_pa=0.0))
    first = ctl.update(0.0, BodySetpoints(depth=1.5))
    # the reference starts where the robot is (no error) and sets off at the largest dive
    # rate: the heave is the hull's drag at that rate
    assert first.demand[1] == pytest.approx(hull.heave_drag(cfg.max_dive_rate))
    t = 0.0
    for _ in range(50):
        t += 0.02
        ctl.on_depth(DepthReading(t=t, depth_m=0.5, pressure_pa=0.0))
        step = ctl.update(t, BodySetpoints(depth=1.5))
    ref = ctl.state[bd.B_Z_REF]
    assert ref == pytest.approx(0.5 + cfg.max_dive_rate * 1.0)  # 1 s at the largest dive rate
    # Z = D_z(w_ref) + kp (z_ref - z) + integral: the robot still at 0.5 m
    w = cfg.max_dive_rate
    p = cfg.depth.kp * (ref - 0.5)
    assert step.demand[1] == pytest.approx(hull.heave_drag(w) + p + ctl.depth_pid.integral, rel=1e-9)
    assert step.demand[1] > hull.heave_drag(w) + p > 0.0  # downwards


def test_a_zero_yaw_rate_setpoint_holds_the_heading_it_started_with():
    ctl = designed()
    ctl.on_imu(imu(0.0, 0.0, yaw=0.3))
    ctl.update(0.0, BodySetpoints())
    assert ctl.heading_ref == pytest.approx(0.3)
    # turned off course to starboard (0.4 rad), not turning: a moment to port, N < 0
    ctl.on_imu(imu(0.02, 0.0, yaw=0.4))
    step = ctl.update(0.02, BodySetpoints())
    kp = ctl.cfg.yaw_rate.kp
    assert step.demand[2] == pytest.approx(-kp * 0.1 + ctl.yaw_pid.integral, rel=1e-9)
    assert step.demand[2] < 0.0
    assert ctl.heading_ref == pytest.approx(0.3)
    # and across the wrap at pi: held heading pi - 0.05, robot at -pi + 0.05 (0.1 rad to starboard)
    ctl = designed()
    ctl.on_imu(imu(0.0, 0.0, yaw=math.pi - 0.05))
    ctl.update(0.0, BodySetpoints())
    ctl.on_imu(imu(0.02, 0.0, yaw=-math.pi + 0.05))
    assert ctl.update(0.02, BodySetpoints()).demand[2] < 0.0


def test_a_yaw_rate_setpoint_turns_the_held_heading_and_never_leads_too_far():
    ctl = designed(max_heading_lead=0.2)
    ctl.on_imu(imu(0.0, 0.0, yaw=0.0))
    ctl.update(0.0, BodySetpoints(yaw_rate=0.1))
    t = 0.0
    for _ in range(500):  # 10 s, the robot not turning at all
        t += 0.02
        ctl.on_imu(imu(t, 0.0, yaw=0.0))
        step = ctl.update(t, BodySetpoints(yaw_rate=0.1))
    assert ctl.heading_ref == pytest.approx(0.2)  # clamped at the lead
    k = ctl.cfg.reference_rate  # the rate reference closes on 0.1 rad/s at k per second
    assert ctl.state[bd.B_R_REF] == pytest.approx(0.1 * (1.0 - math.exp(-10.0 * k)), rel=1e-2)
    assert step.demand[2] > 0.0  # clockwise, to starboard


def test_overspeed_coasts_and_the_integral_does_not_wind_against_the_cut():
    ctl = designed(median_window=1)
    t = 0.0
    ctl.on_dvl(dvl(t, 0.3))
    ctl.update(t, BodySetpoints(velocity=0.3))
    held = None
    for _ in range(1000):  # the speed setpoint drops to 0.1 while the robot keeps 0.3 m/s
        t += 0.02
        ctl.on_dvl(dvl(t, 0.3))
        step = ctl.update(t, BodySetpoints(velocity=0.1))
        if held is None and "coast" in step.cut:
            held = ctl.velocity_pid.integral
    assert "coast" in step.cut
    assert step.applied[0] == 0.0
    assert all(fx == 0.0 for fx, _ in step.allocation.per_fin())
    # from the first coasting step on, every step's integration was undone
    assert held is not None and ctl.velocity_pid.integral == pytest.approx(held, abs=1e-12)


def test_heave_beyond_the_fins_is_cut_and_reported_to_the_depth_loop():
    ctl = designed(median_window=1, max_dive_rate=2.0)
    t = 0.0
    for _ in range(300):
        ctl.on_depth(DepthReading(t=t, depth_m=0.5, pressure_pa=0.0))
        step = ctl.update(t, BodySetpoints(depth=20.0))
        t += 0.02
    assert "heave" in step.cut or ctl.depth_pid.saturated
    assert step.applied[1] <= 4 * ctl.fin_force + 1e-9
    # the integral stays within what the loop may give: it does not run away
    assert ctl.depth_pid.integral <= ctl.depth_pid.limit + 1e-9


def test_the_loops_limits_are_what_the_fins_deliver():
    ctl = designed(thrust_gain=2.0)
    f = ctl.fin_force
    assert f == pytest.approx(1.177, abs=2e-3)  # q |C| (64 * 1.2 / 4) cos 0.6
    assert ctl.depth_pid.limit == pytest.approx(4 * f)
    assert ctl.velocity_pid.limit == pytest.approx(4 * math.cos(math.radians(30)) * 2.0 * f)
    assert ctl.yaw_pid.limit == pytest.approx(4 * B * 1.5 * f)


def test_bad_gains_are_refused_naming_the_key():
    with pytest.raises(ValueError, match="depth.kp"):
        BodyConfig(depth=PidGains(kp=0.0, limit=5.0))
    with pytest.raises(ValueError, match="ki"):
        BodyConfig(depth=PidGains(kp=1.0, ki=-1.0))
    with pytest.raises(ValueError, match="thrust_gain"):
        BodyConfig(thrust_gain=0.0)
    from ucat_console.config import AppConfig
    with pytest.raises(ValueError, match=r"body\.yaw_rate\.kp"):
        AppConfig.from_dict({"body": {"yaw_rate": {"kp": 0.0}}})
    with pytest.raises(ValueError, match=r"body\.max_dive_rate"):
        AppConfig.from_dict({"body": {"max_dive_rate": -0.1}})


# ------------------------------------------------------------------ the design
def test_the_designed_position_loops_put_their_poles_where_the_design_says():
    hull = HullModel()
    w = 0.2
    heave = position_gains(hull.heave_mass, hull.heave_damping, w)
    # the hull damps heave by itself: a P loop, its slower pole at the bandwidth
    assert heave.kd == 0.0
    poles = np.roots([hull.heave_mass, hull.heave_damping + heave.kd, heave.kp])
    assert max(poles.real) == pytest.approx(-w)
    assert np.all(np.abs(poles.imag) < 1e-12)
    yaw = position_gains(hull.yaw_inertia, hull.yaw_damping, w)
    poles = np.roots([hull.yaw_inertia, hull.yaw_damping + yaw.kd, yaw.kp])
    assert poles == pytest.approx([-w, -w], abs=1e-6)  # critically damped at the bandwidth
    surge = velocity_gains(hull.surge_mass, hull.surge_damping, w)
    poles = np.roots([hull.surge_mass, hull.surge_damping + surge.kp, surge.ki])
    assert poles == pytest.approx([-w, -w], abs=1e-6)


def test_the_shipped_gains_are_the_designed_ones():
    from ucat_console.control.params import DESIGN_DELAY, DESIGN_FACTOR

    g = designed_gains(HullModel(), DESIGN_DELAY, DESIGN_FACTOR)
    cfg = BodyConfig()
    assert cfg.depth.kp == pytest.approx(g["depth"].kp, abs=1e-4)
    assert cfg.yaw_rate.kd == pytest.approx(g["heading"].kd, abs=1e-4)
    assert cfg.velocity.ki == pytest.approx(g["velocity"].ki, abs=1e-4)
    assert cfg.reference_rate == pytest.approx(1.0 / (DESIGN_DELAY * DESIGN_FACTOR), abs=1e-4)
    assert cfg.speed_filter == pytest.approx(DESIGN_DELAY * DESIGN_FACTOR / 5.0, abs=1e-4)


def test_the_velocity_loop_closes_on_the_low_passed_dvl_speed():
    """A DVL step from 0.2 to 0.3 m/s (median window 1): the speed the loop uses moves by
    1 - exp(-dt / tau) of the way at each report; the paper's layer keeps the median alone."""
    tau = 1.0
    ctl = designed(median_window=1, speed_filter=tau)
    ctl.on_dvl(dvl(0.0, 0.2))
    assert ctl.update(0.0, BodySetpoints(velocity=0.2)).velocity == pytest.approx(0.2)
    expected = 0.2
    for k in range(1, 9):  # 8 Hz for 1 s
        t = k / 8.0
        ctl.on_dvl(dvl(t, 0.3))
        expected += (1.0 - math.exp(-0.125 / tau)) * (0.3 - expected)
        assert ctl.update(t, BodySetpoints(velocity=0.2)).velocity == pytest.approx(expected, rel=1e-12)
    assert expected == pytest.approx(0.3 - 0.1 * math.exp(-1.0))
    off = designed(median_window=1, speed_filter=0.0)
    paper = BodyController(paper_cfg(median_window=1, speed_filter=tau))
    for c in (off, paper):
        c.on_dvl(dvl(0.0, 0.2))
        c.on_dvl(dvl(0.125, 0.3))
        assert c.update(0.125, BodySetpoints(velocity=0.2)).velocity == 0.3


def test_dvl_noise_barely_reaches_the_fins_surge_targets():
    """8 Hz DVL reports with 5 mm/s of noise about a held speed: what the fins are asked
    for forwards varies less than half as much with the shipped low-pass as without it (each fin
    samples its target once a cycle, so the noise would reach the four fins differently)."""
    rng = np.random.default_rng(3)
    noise = rng.normal(0.0, 0.005, 8 * 120)
    spread = {}
    for tau in (0.0, BodyConfig().speed_filter):
        ctl = designed(speed_filter=tau)
        fx = []
        for k, e in enumerate(noise):
            t = k / 8.0
            ctl.on_dvl(dvl(t, 0.2 + e))
            step = ctl.update(t, BodySetpoints(velocity=0.2))
            if t >= 60.0:
                fx.append(step.allocation.per_fin()[0][0])
        spread[tau] = float(np.std(fx))
    assert spread[BodyConfig().speed_filter] < spread[0.0] / 2.0


def _cruising(**kw) -> tuple[BodyController, BodySetpoints]:
    """A designed layer at 1 m and 0.2 m/s, on course, its loops run once."""
    ctl = designed(median_window=1, shortfall_limit=1.0, shortfall_filter=0.0, **kw)
    sp = BodySetpoints(0.2, 1.0, 0.0)
    ctl.on_dvl(dvl(0.0, 0.2))
    ctl.on_depth(DepthReading(t=0.0, depth_m=1.0, pressure_pa=0.0))
    ctl.on_imu(imu(0.0, 0.0, yaw=0.0))
    ctl.update(0.0, sp)
    return ctl, sp


def _fin_yaw(fx: float, k: int) -> float:
    from ucat_console.robot.geometry import ARM_YAW

    return FIN_SIDES[k] * ARM_YAW * fx


def test_a_fin_whose_plan_makes_less_than_it_was_asked_is_fed_forward_to_the_others():
    ctl, sp = _cruising()
    for k in range(4):
        ctl.on_cycle(k, (-0.1, 0.0), (-0.1, 0.0), 0.0)
    ctl.update(0.1, sp)
    assert ctl.shortfall == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)
    # fin 0's plan makes half the forward force it was asked: the yaw it misses is added
    ctl.on_cycle(0, (-0.1, 0.0), (-0.05, 0.0), 0.0)
    step = ctl.update(0.2, sp)
    missed = _fin_yaw(-0.1, 0) - _fin_yaw(-0.05, 0)
    assert ctl.shortfall[2] == pytest.approx(missed)
    assert ctl.shortfall[0] > 0.0  # and the surge it misses
    assert step.demand[2] == pytest.approx(step.outputs[2] + missed)
    off, sp = _cruising(feed_shortfall=False)
    off.on_cycle(0, (-0.1, 0.0), (-0.05, 0.0), 0.0)
    off.update(0.2, sp)
    assert off.shortfall == (0.0, 0.0, 0.0)


def test_a_fin_whose_executed_cycle_fell_short_of_its_plan_has_its_next_plans_corrected():
    ctl, sp = _cruising()
    for k in range(4):
        ctl.on_cycle(k, (-0.1, 0.0), (-0.1, 0.0), 0.0)
    # fin 2's strokes ran slow: its last cycle made (by the fin model) 60 % of its plan
    ctl.on_executed(2, (-0.1, 0.0), (-0.06, 0.0))
    ctl.update(0.1, sp)
    assert ctl.shortfall[2] == pytest.approx(_fin_yaw(-0.1, 2) - _fin_yaw(-0.06, 2))
    off, sp = _cruising(feed_executed=False)
    for k in range(4):
        off.on_cycle(k, (-0.1, 0.0), (-0.1, 0.0), 0.0)
    off.on_executed(2, (-0.1, 0.0), (-0.06, 0.0))
    off.update(0.1, sp)
    assert off.shortfall == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)


def _target_now(ctl: BodyController, k: int, target: tuple[float, float]) -> tuple[float, float]:
    """What paper fin ``k`` is given when the allocation asks it for ``target``."""
    ctl.state[bd.B_OUT + bd.W_TARGETS + 2 * k:bd.B_OUT + bd.W_TARGETS + 2 * k + 2] = target
    return bd.body_targets(ctl.state, k)


def test_a_fin_asked_for_almost_nothing_keeps_the_direction_of_its_cycle():
    ctl, _ = _cruising()
    hold = ctl.cfg.direction_hold
    assert hold > 0.0
    ctl.on_cycle(0, (-0.5, 0.1), (-0.5, 0.1), 0.0)  # fin 0 runs a cycle asked forward and up
    u = np.array([-0.5, 0.1]) / math.hypot(-0.5, 0.1)
    # a little lift: the part of it along the running cycle, in that cycle's direction
    little = 0.5 * hold
    got = np.array(_target_now(ctl, 0, (0.0, little)))
    assert got == pytest.approx(float(np.dot((0.0, little), u)) * u, rel=1e-12)
    # a little sink, against the cycle: next to nothing, still in the cycle's direction
    got = np.array(_target_now(ctl, 0, (0.0, -little)))
    assert got == pytest.approx(1e-3 * hold * u, rel=1e-12)
    # a force above the hold is given as asked, whatever the cycle's direction
    assert _target_now(ctl, 0, (0.0, 1.2 * hold)) == (0.0, 1.2 * hold)
    # the hold is by the fin model (it is the strokes' rate): fins measured stronger alike
    ctl.state[bd.B_SCALE] = 4.0
    assert _target_now(ctl, 0, (0.0, 1.2 * hold)) == (0.0, 1.2 * hold)
    assert _target_now(ctl, 0, (0.0, 0.8 * hold)) != (0.0, 0.8 * hold)
    # a fin with no cycle yet is given its target
    assert _target_now(ctl, 1, (0.0, little)) == (0.0, little)
    # off: every target as asked
    off, _ = _cruising(direction_hold=0.0)
    off.on_cycle(0, (-0.5, 0.1), (-0.5, 0.1), 0.0)
    assert _target_now(off, 0, (0.0, little)) == (0.0, little)


def test_the_speed_references_acceleration_rises_to_its_limit_over_the_configured_time():
    """A speed step: the reference's acceleration grows by max_acceleration over
    acceleration_rise (the fins take a new demand each at its own cycle), none at once."""
    rates = {}
    for rise in (0.0, 2.5):
        ctl = designed(median_window=1, speed_filter=0.0, acceleration_rise=rise)
        t, seen = 0.0, []
        for _ in range(400):  # 8 s at 0.1 m/s, the setpoint 0.35 from 2 s on
            ctl.on_dvl(dvl(t, 0.1))
            ctl.update(t, BodySetpoints(0.35 if t >= 2.0 else 0.1, 0.0, 0.0))
            seen.append((t, ctl.state[bd.B_V_REF_RATE]))
            t += 0.02
        rates[rise] = seen
    a = designed().cfg.max_acceleration
    at_once, rising = dict(rates[0.0]), dict(rates[2.5])
    t_step = min(t for t, _ in rates[0.0] if t >= 2.0)
    assert at_once[t_step] == pytest.approx(a)  # the whole limit in the step's first update
    for t, r in rates[2.5]:
        if t < t_step:
            assert r == pytest.approx(0.0, abs=1e-12)
        else:  # linear rise to the limit: a / 2.5 per second, the first update already one step on it
            assert r == pytest.approx(min(a, a * (t - t_step + 0.02) / 2.5), rel=1e-9, abs=1e-12)
    assert max(rising.values()) == pytest.approx(a)
    # from rest, where the reference starts, the fins all start together: the limit at once
    ctl = designed(median_window=1, speed_filter=0.0, acceleration_rise=2.5)
    for t in (0.0, 0.02):
        ctl.on_dvl(dvl(t, 0.0))
        ctl.update(t, BodySetpoints(0.2, 0.0, 0.0))
    assert ctl.state[bd.B_V_REF_RATE] == pytest.approx(a)


def _surge_run(true_scale: float, seconds: float = 30.0, **kw) -> tuple[BodyController, list[tuple]]:
    """The designed layer holding 0.2 m/s on a hull that moves as its own model says,
    ``M u' + D(u) = s X``, ``X`` the surge the fins were given by the fin model arriving half
    a second later (a 2-Hz beat's cycle), the fins making ``true_scale`` times it; DVL at
    8 Hz, the layer at 50 Hz. The layer and, per step, (t, speed, the surge applied, the
    scale followed, the scale measured)."""
    ctl = designed(median_window=1, speed_filter=0.0, **kw)
    hull = ctl.cfg.hull
    dt, lag = 0.02, 25
    given = [0.0] * lag
    u, sp, out = 0.2, BodySetpoints(0.2, 0.0, 0.0), []
    for i in range(int(seconds / dt)):
        t = i * dt
        if i % 6 == 0:  # 8.3 Hz
            ctl.on_dvl(dvl(t, u))
        step = ctl.update(t, sp)
        scale, measured = ctl.force_scale
        given.append(step.applied[0] / scale)
        u += dt * (true_scale * given.pop(0) - hull.surge_drag(u)) / hull.surge_mass
        out.append((t, u, step.applied[0], scale, measured))
    return ctl, out


def test_fins_stronger_than_their_model_are_measured_and_asked_for_less():
    ctl, run = _surge_run(4.0, seconds=45.0)
    engaged = [r for r in run if r[3] > 1.0]
    assert engaged and engaged[0][0] < 5.0  # followed within seconds, from twice the model on
    assert all(r[3] == pytest.approx(min(max(r[4], 1.0), 8.0)) for r in engaged)
    late = [r for r in run if r[0] >= 30.0]
    assert all(r[4] == pytest.approx(4.0, rel=0.05) for r in late)  # measured within 5 %
    assert all(abs(r[1] - 0.2) < 0.01 for r in late)  # the speed held
    # the surge applied is the demand; the fins are asked for a quarter of it by the model
    x = ctl.state[bd.B_OUT + bd.W_X]
    assert ctl.state[bd.B_APPLIED] == pytest.approx(ctl.force_scale[0] * x)
    # a reset (a mode switch, a new arming) keeps what was found
    ctl.reset()
    assert ctl.force_scale[0] == pytest.approx(late[-1][3])


def test_fins_that_make_their_models_force_leave_the_layer_as_it_was():
    _, run = _surge_run(1.15)  # the default plant's plate makes 1.15 times the model's thrust
    _, off = _surge_run(1.15, force_scale_from=0.0)
    assert all(r[3] == 1.0 for r in run)
    assert all(r[4] == pytest.approx(1.15, rel=0.2) for r in run if r[0] >= 5.0)
    assert [r[2] for r in run] == [r[2] for r in off]  # the same surge, to the last bit
    _, never = _surge_run(4.0, force_scale_from=0.0)
    assert all(r[3] == 1.0 and r[4] == 1.0 for r in never)
