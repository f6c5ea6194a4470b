"""Tables III and V metrics on small hand-made arrays."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ucat_console.control import metrics as m


def test_force_error_is_the_mean_c_force():
    assert m.force_error([0.1, 0.3, 0.2]) == pytest.approx(0.2)


def test_st_deviation_and_mae():
    st = [0.30, 0.25, 0.40, 0.20]
    # |0| + 0.05 + 0.10 + 0.10 = 0.25 over 4
    assert m.st_deviation(st) == pytest.approx(0.0625)
    assert m.st_mae(st, st_opt=0.3) == pytest.approx(0.0625)
    assert m.st_deviation([0.5], st_opt=0.4) == pytest.approx(0.1)


def test_in_range_rate_counts_corridor_inclusively():
    st = [0.25, 0.30, 0.35, 0.36, 0.10]
    assert m.in_range_rate(st) == pytest.approx(3 / 5)
    assert m.in_range_rate(st, 0.0, 1.0) == 1.0


def test_command_stability():
    u = np.array(
        [
            [0.5, -0.5, 2.0, 2.0],
            [0.6, -0.5, 2.0, 1.0],  # |du|_1 = 0.1 + 1.0 = 1.1
            [0.6, -0.3, 2.5, 1.0],  # |du|_1 = 0.2 + 0.5 = 0.7
        ]
    )
    assert m.command_stability(u) == pytest.approx(0.9)


def test_velocity_mae_scalar_and_array_reference():
    assert m.velocity_mae([0.28, 0.31, 0.30], 0.3) == pytest.approx(0.01)
    assert m.velocity_mae([0.1, 0.2], [0.2, 0.2]) == pytest.approx(0.05)


def test_mean_power_and_saving():
    assert m.mean_power([1.0, 3.0]) == pytest.approx(2.0)
    # time average: 1 W for 1 s then ramp to 3 W over 1 s -> (1 + 2) / 2 s = 1.5 W
    assert m.mean_power([1.0, 1.0, 3.0], t=[0.0, 1.0, 2.0]) == pytest.approx(1.5)
    assert m.power_saving(6.8, 10.0) == pytest.approx(32.0)
    assert m.power_saving(11.0, 10.0) == pytest.approx(-10.0)


@pytest.mark.parametrize(
    "call, name",
    [
        (lambda: m.force_error([]), "force_errors"),
        (lambda: m.st_deviation([]), "st"),
        (lambda: m.in_range_rate(np.array([])), "st"),
        (lambda: m.command_stability(np.zeros((0, 4))), "u"),
        (lambda: m.velocity_mae([], 0.3), "v"),
        (lambda: m.mean_power([]), "p"),
    ],
)
def test_empty_input_names_the_argument(call, name):
    with pytest.raises(ValueError, match=rf"^{name}:"):
        call()


def test_other_bad_input():
    with pytest.raises(ValueError, match="u"):
        m.command_stability([[0.5, -0.5, 2.0, 2.0]])
    with pytest.raises(ValueError, match="force_errors"):
        m.force_error([0.1, -0.2])
    with pytest.raises(ValueError, match="st"):
        m.st_deviation([0.3, math.nan])
    with pytest.raises(ValueError, match="p_baseline"):
        m.power_saving(1.0, 0.0)
    with pytest.raises(ValueError, match="st_high"):
        m.in_range_rate([0.3], 0.35, 0.25)
    with pytest.raises(ValueError, match="v_ref"):
        m.velocity_mae([0.1, 0.2, 0.3], [0.2, 0.2])
