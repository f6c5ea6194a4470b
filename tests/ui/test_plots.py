"""Plot buffers: fixed size whatever the session length; windows decimated to a bound."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.messages import BodyState, Power, Setpoints
from ucat_console.ui.plots import COL, PlotFeeder, RingBuffer, filled


def test_ring_buffer_keeps_the_newest_rows_in_order() -> None:
    rb = RingBuffer(4, 2)
    for k in range(10):
        rb.append((k, 10 * k))
    assert len(rb) == 4
    np.testing.assert_array_equal(rb.last(10), [[6, 60], [7, 70], [8, 80], [9, 90]])
    np.testing.assert_array_equal(rb.last(2), [[8, 80], [9, 90]])


def test_decimation_bounds_the_points_and_keeps_the_newest() -> None:
    rb = RingBuffer(1000, 1)
    for k in range(5000):
        rb.append((k,))
    rows = rb.last(1000, max_points=100)
    assert len(rows) == 100
    assert rows[-1, 0] == 4999  # the newest row is always shown
    assert np.all(np.diff(rows[:, 0]) == 10)  # every 10th row


def test_a_long_session_does_not_grow_what_a_refresh_sends() -> None:
    feeder = PlotFeeder(capacity=300)
    sizes = []
    for k in range(20_000):
        t = 0.1 * k
        feeder.on_message(ch.BODY_STATE, BodyState(t, (0, 0, 1), (1, 0, 0, 0), (0.2, 0, 0), (0, 0, 0.01), 1.0))
        feeder.sample()
        if k in (100, 1000, 19_999):
            sizes.append(feeder.buffer.last(10_000, max_points=120).nbytes)
    assert len(feeder.buffer) == 300
    assert sizes[1] == sizes[2] <= 120 * len(COL) * 8


def test_feeder_rows_hold_the_latest_values() -> None:
    f = PlotFeeder(capacity=10)
    assert f.sample() is False  # nothing yet
    f.on_message(ch.SETPOINTS, Setpoints(0.0, 0.25, 1.5, 0.0))
    f.on_message(ch.BODY_STATE, BodyState(1.0, (0, 0, 1.4), (1, 0, 0, 0), (0.2, 0, 0), (0, 0, 0.05), 1.4))
    f.on_message(ch.POWER, Power(1.0, (1.0, 2.0, 3.0, 4.0), 10.0, 9.0, 50.0, 2.0, 25.0))
    assert f.sample() is True
    assert f.sample() is False  # time has not advanced
    row = f.buffer.last(1)[0]
    assert row[COL["t"]] == 1.0
    assert (row[COL["depth"]], row[COL["depth_sp"]]) == (1.4, 1.5)
    assert (row[COL["velocity"]], row[COL["velocity_sp"]]) == (0.2, 0.25)
    assert row[COL["p2"]] == 3.0 and row[COL["p_total"]] == 10.0 and row[COL["energy_per_metre"]] == 25.0
    assert math.isnan(row[COL["st0"]])  # no plan yet


@pytest.mark.parametrize(
    "a, expected",
    [
        ([1.0, 2.0], [1.0, 2.0]),
        ([math.nan, math.nan, 3.0, math.nan, 5.0], [3.0, 3.0, 3.0, 3.0, 5.0]),
        ([math.nan, math.nan], [0.0, 0.0]),
    ],
)
def test_filled_replaces_nan_by_the_last_value(a: list, expected: list) -> None:
    np.testing.assert_array_equal(filled(np.array(a)), expected)


def test_st_is_hidden_while_disarmed_or_still_and_clipped_above_one() -> None:
    from ucat_console.ui.plots import ST_HIDDEN, st_shown

    st = np.array([0.3, 0.3, 6.0, 0.3, np.nan, 2.7])
    armed = np.array([1.0, 1.0, 1.0, 0.0, 1.0, 1.0])
    speed = np.array([0.2, 0.01, 0.2, 0.2, 0.2, -0.2])
    shown, above = st_shown(st, armed, speed)
    np.testing.assert_array_equal(shown, [0.3, ST_HIDDEN, 1.0, ST_HIDDEN, ST_HIDDEN, 1.0])
    np.testing.assert_array_equal(above, [ST_HIDDEN, ST_HIDDEN, 1.0, ST_HIDDEN, ST_HIDDEN, 1.0])
    assert ST_HIDDEN < 0.0  # below the fixed 0-1 axis


def test_span_pins_keep_a_minimum_axis_span_around_the_data() -> None:
    from ucat_console.ui.plots import span_pins

    depth = np.array([1.000, 1.002, 0.999])
    target = np.array([1.0, 1.0, 1.0])
    lo, hi = span_pins(depth, target, span=0.2)
    assert np.allclose(hi - lo, 0.2) and lo[0] < 0.999 and hi[0] > 1.002
    lo, hi = span_pins(np.array([np.nan, np.nan]), np.array([np.nan, np.nan]), span=0.1)
    assert np.allclose(hi - lo, 0.1)
