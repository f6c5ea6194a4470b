"""Running median and first-order low-pass."""

from __future__ import annotations

import math

import pytest

from ucat_console.control.filters import LowPass, MedianFilter


def test_median_rejects_outlier_and_slides():
    m = MedianFilter(3)
    assert m.value is None
    assert m.push(1.0) == 1.0
    assert m.push(5.0) == 3.0  # two samples: mean of the middle pair
    assert m.push(2.0) == 2.0
    assert m.push(100.0) == 5.0  # window (5, 2, 100)
    assert m.push(3.0) == 3.0  # window (2, 100, 3)
    assert len(m) == 3


def test_median_window_five_removes_a_spike():
    m = MedianFilter(5)
    for x in (0.1, 0.1, 5.0, 0.1, 0.1):
        out = m.push(x)
    assert out == 0.1


def test_median_bad_input():
    with pytest.raises(ValueError, match="window"):
        MedianFilter(0)
    with pytest.raises(ValueError, match="x"):
        MedianFilter(3).push(math.nan)


def test_lowpass_step_is_exact_for_piecewise_constant_input():
    lp = LowPass(1.0)
    lp.update(0.0, 0.0)
    assert lp.update(1.0, 1.0) == pytest.approx(1.0 - math.exp(-1.0))
    lp2 = LowPass(1.0)
    lp2.update(0.0, 0.0)
    lp2.update(1.0, 0.5)
    assert lp2.update(1.0, 1.0) == pytest.approx(1.0 - math.exp(-1.0))


def test_lowpass_zero_tau_passes_through():
    lp = LowPass(0.0)
    lp.update(3.0, 0.0)
    assert lp.update(-2.0, 0.1) == -2.0


def test_lowpass_bad_input():
    with pytest.raises(ValueError, match="tau"):
        LowPass(-1.0)
    lp = LowPass(0.1)
    lp.update(0.0, 1.0)
    with pytest.raises(ValueError, match="t"):
        lp.update(0.0, 0.5)


def test_the_compiled_median_is_the_reference_on_random_streams():
    """The median's functions compiled (as the loop's core runs them) against the deque
    median the loop ran before, for every window from 1 to 9 and odd and even counts."""
    import numpy as np
    from numba import njit

    from control.reference_kernels import ReferenceMedian
    from ucat_console.control.filters import median_clear, median_push, median_size, median_value

    push = njit(lambda b, w, x: median_push(b, 0, w, x))
    value = njit(lambda b, w: median_value(b, 0, w))
    rng = np.random.default_rng(7)
    for window in range(1, 10):
        buf = np.zeros(median_size(window))
        median_clear(buf, 0)
        ref = ReferenceMedian(window)
        assert math.isnan(value(buf, window)) and ref.value is None
        for x in rng.normal(0, 1, 60).round(2):  # rounded: ties
            push(buf, window, float(x))
            ref.push(float(x))
            assert value(buf, window) == ref.value
