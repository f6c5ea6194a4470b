"""Fin force allocation: the paper's (sums, yaw differential, sync mode) and the designed
layer's (sums, saturation, priority, coasting, the cut reported) on hand-computed cases."""

from __future__ import annotations

import math

import pytest

from ucat_console.control.allocation import allocate, allocate_body_wrench, wrench_params
from ucat_console.robot.fins import PAPER_SIDES as FIN_SIDES

B = 0.2981  # lateral fin distance used to turn differentials into moments (m)
COS30 = math.cos(math.radians(30.0))


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


# ------------------------------------------------------------------ the designed allocation
def params(fmax=1.0, gain=2.0, rear=0.5, yaw_on_rear=True):
    return wrench_params(fmax, gain, 30.0, B, rear, yaw_on_rear)


def physical(per_fin, gain):
    """The fins' physical x-forces: forward (negative) ones ``gain`` times the model's."""
    return [(fx * gain if fx < 0.0 else fx, fy) for fx, fy in per_fin]


def wrench(per_fin, gain):
    """(surge N forward, heave N down, yaw N m) the fins' model targets make, by hand."""
    ph = physical(per_fin, gain)
    x = sum(-fx * COS30 for fx, _ in ph)
    z = sum(-fy for _, fy in ph)
    n = sum(side * B * fx for side, (fx, _) in zip(FIN_SIDES, ph))
    return x, z, n


def test_within_the_limits_every_axis_is_given_and_the_fins_sum_to_it():
    r = allocate_body_wrench(1.0, 0.8, 0.1, params())
    assert r.cut == ()
    assert r.applied == pytest.approx((1.0, 0.8, 0.1))
    fins = r.allocation.per_fin()
    # heave: -Z/4 on each fin (f_y > 0 lifts, Z > 0 is down)
    assert [fy for _, fy in fins] == pytest.approx([-0.2] * 4)
    # yaw: y = N / (4 B) = 0.08386 N on each fin, starboard backwards; surge a = -X / (4 cos 30) = -0.28868
    y, a = 0.1 / (4 * B), -1.0 / (4 * COS30)
    assert [fx for fx, _ in physical(fins, 2.0)] == pytest.approx([a + y, a - y, a + y, a - y])
    assert wrench(fins, 2.0) == pytest.approx((1.0, 0.8, 0.1))


def test_heave_beyond_the_fins_is_cut_to_what_they_make():
    r = allocate_body_wrench(0.0, 10.0, 0.0, params(fmax=1.0))
    assert r.cut == ("heave",)
    assert r.applied[1] == pytest.approx(4.0)  # four fins of 1 N
    assert [fy for _, fy in r.allocation.per_fin()] == pytest.approx([-1.0] * 4)


def test_front_pair_heave_share():
    r = allocate_body_wrench(0.0, 1.0, 0.0, params(rear=0.0))
    assert [fy for _, fy in r.allocation.per_fin()] == pytest.approx([-0.5, -0.5, 0.0, 0.0])
    cut = allocate_body_wrench(0.0, 3.0, 0.0, params(fmax=1.0, rear=0.0))
    assert cut.applied[1] == pytest.approx(2.0) and cut.cut == ("heave",)


def test_yaw_comes_before_surge_and_is_cut_to_what_heave_leaves():
    # heave 3.2 N: f_y = -0.8 on each fin, leaving c = 0.6 N of x-force; forward counts
    # twice (gain 2): the largest y with a common surge share is (c + 2 c) / 2 = 0.9 N
    r = allocate_body_wrench(2.0, 3.2, 2.0, params(fmax=1.0, gain=2.0))
    assert set(r.cut) == {"yaw", "surge"}
    assert r.applied[1] == pytest.approx(3.2)
    assert r.applied[2] == pytest.approx(0.9 * 4 * B)
    # with y at its largest the surge share is forced to (c - 2 c) / 2 = -0.3 N
    assert r.applied[0] == pytest.approx(0.3 * 4 * COS30)
    for fx, fy in r.allocation.per_fin():
        phys = fx * 2.0 if fx < 0.0 else fx
        assert math.hypot(fx, fy) <= 1.0 + 1e-9  # every fin within its deliverable force
        assert abs(phys) == pytest.approx(0.6 * (2.0 if phys < 0 else 1.0))
    assert wrench(r.allocation.per_fin(), 2.0) == pytest.approx(r.applied)


def test_surge_is_clipped_to_what_yaw_and_heave_leave():
    r = allocate_body_wrench(50.0, 0.0, 0.0, params(fmax=1.0, gain=2.0))
    assert r.cut == ("surge",)
    assert r.applied[0] == pytest.approx(4 * COS30 * 2.0)  # every fin forward at 1 N, times the gain
    assert all(fx == pytest.approx(-1.0) for fx, _ in r.allocation.per_fin())


def test_the_fins_coast_rather_than_push_against_the_travel():
    r = allocate_body_wrench(-1.0, 0.0, 0.0, params())
    assert r.cut == ("coast",)
    assert r.applied[0] == 0.0
    assert all(fx == 0.0 for fx, _ in r.allocation.per_fin())
    # a reverse setpoint mirrors it: backward force is given, forward is not
    back = allocate_body_wrench(-1.0, 0.0, 0.0, params(), direction=-1.0)
    assert back.cut == () and back.applied[0] == pytest.approx(-1.0)
    assert allocate_body_wrench(1.0, 0.0, 0.0, params(), direction=-1.0).cut == ("coast",)


def test_sync_mode_puts_yaw_on_the_front_pair_and_the_rear_fins_alike():
    r = allocate_body_wrench(1.0, 0.4, 0.1, params(), sync=True)
    assert r.allocation.fins == ((0,), (1,), (2, 3))
    fins = r.allocation.per_fin()
    assert fins[2] == fins[3]
    y = 0.1 / (2 * B)
    a = -1.0 / (4 * COS30)
    assert [fx for fx, _ in physical(fins, 2.0)] == pytest.approx([a + y, a - y, a, a])
    assert wrench(fins, 2.0) == pytest.approx((1.0, 0.4, 0.1))


def test_bad_wrench_is_refused_naming_it():
    with pytest.raises(ValueError, match="n"):
        allocate_body_wrench(0.0, 0.0, math.nan, params())
