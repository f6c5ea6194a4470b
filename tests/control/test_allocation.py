"""Fin force allocation, sync mode, and the body-frame controller's signs and data handling."""

from __future__ import annotations

import math

import pytest

from ucat_console.control.allocation import BodyController, BodySetpoints, allocate
from ucat_console.control.params import BodyConfig, PidGains
from ucat_console.robot.fins import PAPER_SIDES as FIN_SIDES
from ucat_console.robot.readings import DepthReading, DvlVelocity, ImuReading

B = 0.2981  # lateral fin distance used to turn differentials into moments (m)


def yaw_moment(per_fin) -> float:
    """N_z = x F_y - y F_x per fin with body forward force -f_x at y = side * B (z down)."""
    return sum(-(side * B) * (-fx) for side, (fx, _fy) in zip(FIN_SIDES, per_fin))


def test_sums_without_yaw():
    a = allocate(-1.2, 0.4, 0.0)
    fins = a.per_fin()
    assert sum(fx for fx, _ in fins) == pytest.approx(-1.2)
    assert all(fx == pytest.approx(-0.3) for fx, _ in fins)
    assert fins[0][1] + fins[1][1] == pytest.approx(0.4)
    assert fins[0][1] == fins[1][1] == pytest.approx(0.2)
    assert fins[2][1] == fins[3][1] == 0.0
    assert yaw_moment(fins) == pytest.approx(0.0)


def test_yaw_differential_is_a_pure_moment():
    plain = allocate(-1.0, 0.4, 0.0).per_fin()
    turned = allocate(-1.0, 0.4, 0.2).per_fin()
    delta = [t[0] - p[0] for t, p in zip(turned, plain)]
    # +m/2 on the front starboard fin, -m/2 on the front port fin, rear unchanged
    assert delta == pytest.approx([0.1, -0.1, 0.0, 0.0])
    assert sum(delta) == pytest.approx(0.0)
    assert sum(fx for fx, _ in turned) == pytest.approx(-1.0)
    assert [t[1] for t in turned] == [p[1] for p in plain]
    # positive yaw command: port pushes forward harder -> clockwise from above (N > 0, z down)
    assert yaw_moment(turned) == pytest.approx(0.2 * B)


def test_sync_mode_three_logical_fins():
    a = allocate(-0.8, 0.3, 0.1, sync=True)
    assert a.sync
    assert len(a.targets) == 3
    assert a.fins == ((0,), (1,), (2, 3))
    physical = sorted(i for fins in a.fins for i in fins)
    assert physical == [0, 1, 2, 3]
    # each physical fin gets the same target as without sync
    assert a.per_fin() == allocate(-0.8, 0.3, 0.1).per_fin()
    assert a.targets[2] == (pytest.approx(-0.2), 0.0)


def test_allocate_rejects_nan():
    with pytest.raises(ValueError, match="yaw"):
        allocate(0.0, 0.0, math.nan)


def dvl(t, vx, valid=True):
    return DvlVelocity(t=t, vx=vx, vy=0.0, vz=0.0, valid=valid, altitude=1.0, fom=0.01)


def body_cfg(**kw) -> BodyConfig:
    base = dict(
        velocity=PidGains(kp=2.0, limit=2.5),
        depth=PidGains(kp=5.0, limit=0.5),
        yaw_rate=PidGains(kp=3.0, limit=0.5),
        median_window=3,
    )
    base.update(kw)
    return BodyConfig(**base)


def test_velocity_error_gives_forward_thrust_negative_fx():
    ctl = BodyController(body_cfg())
    ctl.on_dvl(dvl(0.0, 0.1))
    cmd = ctl.update(0.0, BodySetpoints(velocity=0.3))
    # F_x* = -kp (0.3 - 0.1) = -0.4
    assert cmd.fx == pytest.approx(-0.4)
    assert cmd.velocity_updated
    assert all(fx == pytest.approx(-0.1) for fx, _ in cmd.allocation.per_fin())


def test_missing_dvl_holds_output_and_is_not_zero_velocity():
    ctl = BodyController(body_cfg())
    ctl.on_dvl(dvl(0.0, 0.1))
    first = ctl.update(0.0, BodySetpoints(velocity=0.3))
    for k in range(1, 6):
        ctl.on_dvl(dvl(0.1 * k, 0.0, valid=False))
        cmd = ctl.update(0.1 * k, BodySetpoints(velocity=0.3))
        assert cmd.fx == first.fx  # held; zero velocity would give -0.6
        assert not cmd.velocity_updated
        assert cmd.velocity == pytest.approx(0.1)
    assert ctl.dvl_missing == 5


def test_no_dvl_yet_gives_no_thrust_and_no_velocity():
    ctl = BodyController(body_cfg())
    cmd = ctl.update(0.0, BodySetpoints(velocity=0.3))
    assert cmd.velocity is None
    assert cmd.fx == 0.0


def test_median_filter_removes_dvl_spike():
    ctl = BodyController(body_cfg())
    for t, v in ((0.0, 0.2), (0.1, 0.2), (0.2, 3.0)):
        ctl.on_dvl(dvl(t, v))
    cmd = ctl.update(0.2, BodySetpoints(velocity=0.2))
    assert cmd.velocity == pytest.approx(0.2)
    assert cmd.fx == pytest.approx(0.0)


def test_depth_sign_and_front_lift():
    ctl = BodyController(body_cfg())
    ctl.on_depth(DepthReading(t=0.0, depth_m=1.95, pressure_pa=0.0))
    cmd = ctl.update(0.0, BodySetpoints(depth=2.0))
    # too shallow by 0.05 m: the default asks for a downward force (f_y > 0 lifts):
    # F_y* = -5 * 0.05 = -0.25, half on each front fin
    assert cmd.fy == pytest.approx(-0.25)
    fins = cmd.allocation.per_fin()
    assert fins[0][1] == fins[1][1] == pytest.approx(-0.125)
    flipped = BodyController(body_cfg(depth_sign=1.0))
    flipped.on_depth(DepthReading(t=0.0, depth_m=1.95, pressure_pa=0.0))
    assert flipped.update(0.0, BodySetpoints(depth=2.0)).fy == pytest.approx(0.25)


def test_yaw_rate_command_turns_to_starboard():
    ctl = BodyController(body_cfg())
    ctl.on_imu(ImuReading(t=0.0, accel_g=(0.0, 0.0, 1.0), gyro=(0.0, 0.0, 0.0)))
    ctl.on_dvl(dvl(0.0, 0.2))
    cmd = ctl.update(0.0, BodySetpoints(velocity=0.2, yaw_rate=0.1))
    assert cmd.yaw == pytest.approx(0.3)  # 3 * 0.1
    fins = cmd.allocation.per_fin()
    assert fins[1][0] < fins[0][0]  # port front fin pushes forward harder (more negative f_x)
    assert yaw_moment(fins) > 0.0


def test_bad_readings_and_setpoints():
    ctl = BodyController(body_cfg())
    with pytest.raises(ValueError, match="dvl.vx"):
        ctl.on_dvl(dvl(0.0, math.nan))
    with pytest.raises(ValueError, match="depth"):
        BodySetpoints(depth=-1.0)
    with pytest.raises(ValueError, match="velocity"):
        BodySetpoints(velocity=math.inf)


def test_the_compiled_body_layer_is_the_reference_on_random_readings():
    """The body-frame layer's functions compiled (as the loop's core runs them) against the
    Python controller the loop ran before: random DVL (with dropouts), depth and gyro
    readings in random order between control steps, three setpoints; the same outputs and
    filtered values at every step, bit for bit."""
    import numpy as np
    from numba import njit

    from control.reference_kernels import ReferenceBody
    from ucat_console.control import allocation as al

    on_dvl = njit(lambda b, valid, v, t: al.body_on_dvl(b, valid, v, t))
    on_depth = njit(lambda b, z, t: al.body_on_depth(b, z, t))
    on_imu = njit(lambda b, r, t: al.body_on_imu(b, r, t))
    update = njit(lambda b, t, v, z, r: al.body_update(b, t, v, z, r))
    rng = np.random.default_rng(11)
    for window in (1, 4, 5):
        cfg = BodyConfig(median_window=window)
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
                assert on_dvl(b, valid, v, t) == al.BODY_OK
                ref.on_dvl(valid, v)
            elif kind == 1:
                z = float(rng.normal(1.0, 0.1))
                assert on_depth(b, z, t) == al.BODY_OK
                ref.on_depth(z)
            elif kind == 2:
                r = float(rng.normal(0.0, 0.1))
                assert on_imu(b, r, t) == al.BODY_OK
                ref.on_imu(r)
            else:
                status, v, z = update(b, t, *sp)
                rv, rz = ref.update(t, sp)
                assert status == al.BODY_OK
                assert (math.isnan(v) and rv is None) or v == rv
                assert (math.isnan(z) and rz is None) or z == rz
                assert (b[al.B_FX], b[al.B_FY], b[al.B_YAW]) == (ref.fx, ref.fy, ref.yaw)
        assert b[al.B_DVL_MISSING] == ref.dvl_missing


def test_the_compiled_body_layer_names_a_bad_reading():
    import numpy as np
    from numba import njit

    from ucat_console.control import allocation as al

    b = BodyController(BodyConfig()).state
    on_depth = njit(lambda b, z, t: al.body_on_depth(b, z, t))
    assert al.BODY_FIELDS[on_depth(b, math.nan, 0.0)] == "depth.depth_m"
    assert al.BODY_FIELDS[on_depth(b, 1.0, math.inf)] == "depth.t"
    assert np.isnan(b[al.B_LAST_DEPTH_T])  # nothing was taken
