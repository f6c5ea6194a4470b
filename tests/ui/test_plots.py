"""Plot buffers: fixed size whatever the session length; windows decimated to a bound."""

from __future__ import annotations

import math
import types

import numpy as np
import pytest

from hypothesis import given, settings
from hypothesis import strategies as st
from plots_reference import chart_data, filled, span_pins, st_shown

from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.messages import BodyState, ElectricalPower, Power, Setpoints, Status
from ucat_console.ui.plots import COL, MIN_SPAN, ST_HIDDEN, LivePlots, PlotFeeder, RingBuffer
from ucat_console.ui import viser_compat


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
        ([math.nan, math.nan], [math.nan, math.nan]),  # never known: drawn as nothing, not 0
    ],
)
def test_filled_replaces_nan_by_the_last_value(a: list, expected: list) -> None:
    np.testing.assert_array_equal(filled(np.array(a)), expected)


def _filled_reference(column: list[float]) -> list[float]:
    finite = [x for x in column if math.isfinite(x)]
    last, out = (finite[0] if finite else math.nan), []
    for x in column:
        last = x if math.isfinite(x) else last
        out.append(last)
    return out


def test_filled_fills_every_column_of_a_table_on_its_own() -> None:
    rng = np.random.default_rng(5)
    for _ in range(30):
        a = rng.normal(size=(int(rng.integers(1, 12)), 6))
        a[rng.random(a.shape) < 0.4] = math.nan
        a[rng.random(a.shape) < 0.05] = math.inf
        a[:, int(rng.integers(6))] = math.nan  # a column with nothing yet
        got = filled(a.copy())
        assert got.shape == a.shape
        for j in range(a.shape[1]):
            np.testing.assert_array_equal(got[:, j], _filled_reference(list(a[:, j])))


def test_st_is_hidden_while_disarmed_or_still_and_clipped_above_one() -> None:
    st = np.array([0.3, 0.3, 6.0, 0.3, np.nan, 2.7])
    armed = np.array([1.0, 1.0, 1.0, 0.0, 1.0, 1.0])
    speed = np.array([0.2, 0.01, 0.2, 0.2, 0.2, -0.2])
    shown, above = st_shown(st, armed, speed)
    np.testing.assert_array_equal(shown, [0.3, ST_HIDDEN, 1.0, ST_HIDDEN, ST_HIDDEN, 1.0])
    np.testing.assert_array_equal(above, [ST_HIDDEN, ST_HIDDEN, 1.0, ST_HIDDEN, ST_HIDDEN, 1.0])
    assert ST_HIDDEN < 0.0  # below the fixed 0-1 axis
    # every fin at once: each row as the fin's own
    fins = np.stack([st, st[::-1], np.full_like(st, 0.5)])
    shown2, above2 = st_shown(fins, armed, speed)
    for k in range(3):
        one = st_shown(fins[k], armed, speed)
        np.testing.assert_array_equal(shown2[k], one[0])
        np.testing.assert_array_equal(above2[k], one[1])


def test_span_pins_keep_a_minimum_axis_span_around_the_data() -> None:
    depth = np.array([1.000, 1.002, 0.999])
    target = np.array([1.0, 1.0, 1.0])
    nothing = np.array([np.nan, np.inf, -np.inf])
    some = np.array([np.nan, 0.5, 0.25])
    pins = span_pins(np.array([[depth, target], [nothing, nothing], [some, nothing]]), [0.2, 0.1, 0.4])
    assert pins.shape == (3, 2, 3) and pins.dtype == np.float64
    lo, hi = pins[0]
    assert np.allclose(hi - lo, 0.2) and lo[0] < 0.999 and hi[0] > 1.002
    np.testing.assert_allclose(pins[0].mean(axis=0), 0.5 * (0.999 + 1.002))
    np.testing.assert_allclose(pins[1], [[-0.05] * 3, [0.05] * 3])  # no finite value: around 0
    np.testing.assert_allclose(pins[2], [[0.375 - 0.2] * 3, [0.375 + 0.2] * 3])  # finite ones only
    big = np.finfo(np.float32).max
    huge = span_pins(np.array([[[big, big], [big, big]]], np.float32), [0.1])
    assert huge.dtype == np.float32 and np.isfinite(huge).all()  # the middle is taken in float64


def test_a_page_receives_the_plots_and_the_pose_the_view_sends() -> None:
    """The live view's plots (their values as float32: ``ui.viser_compat.set_plot_data``) and
    robot pose reach a page (a raw websocket client) as the values the view computed."""
    import viser

    from support import wait_for
    from ucat_console.bench.raw_page import RawPage
    from ucat_console.robot.geometry import Geometry
    from ucat_console.telemetry.messages import BodyState, Setpoints, Status
    from ucat_console.ui.view import StreamView

    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        view = StreamView(server.scene, server.gui, Geometry(), plot_rate=10.0, scene_rate=40.0, max_plot_points=200,
                          history=lambda: 10.0, max_history=30.0, corridor=lambda: (0.25, 0.35), trail_points=50,
                          trail_spacing=0.05)
        view.show()
        page = RawPage(f"http://127.0.0.1:{server.get_port()}")
        for k in range(5):
            t = 0.1 * k
            view.feeder.on_message(ch.BODY_STATE, BodyState(t, (0.1 * k, 0.0, 1.0 + 0.01 * k), (1.0, 0.0, 0.0, 0.0),
                                                            (0.2, 0.0, 0.0), (0.0, 0.0, 0.05), 1.0 + 0.01 * k))
            view.feeder.on_message(ch.SETPOINTS, Setpoints(t, 0.2, 1.2, 0.0))
            view.feeder.on_message(ch.STATUS, Status(t, True, "mpc", "", (), 0, "sim"))
            for fin in range(4):  # fin 3's St above 1: drawn at 1, and marked
                view.feeder.on_message(ch.fin_plan(fin), types.SimpleNamespace(t=t, st=0.3 + 0.1 * fin + (fin == 3)))
            view.feeder.sample()
        view.refresh_plots()
        view.on_message(ch.BODY_STATE, BodyState(0.4, (0.4, -0.1, 1.04), (0.9, 0.1, 0.0, 0.4243),
                                                 (0.2, 0.0, 0.0), (0.0, 0.0, 0.05), 1.04))
        view.tick_scene()
        depth_uuid = viser_compat.handle_uuid(view.plots.depth)
        data = wait_for(lambda: (d := page.elements.get(depth_uuid, {}).get("data")) is not None and len(d[0]) == 5
                        and d, what="the depth plot's five rows")
        t, depth, target = (np.asarray(a) for a in data[:3])
        np.testing.assert_allclose(t, [0.0, 0.1, 0.2, 0.3, 0.4])
        np.testing.assert_allclose(depth, [1.0, 1.01, 1.02, 1.03, 1.04])
        np.testing.assert_allclose(target, 1.2)
        assert t.dtype == np.float64  # the time axis keeps its resolution; the values are float32
        assert depth.dtype == target.dtype == np.float32
        st = wait_for(lambda: (d := page.elements.get(viser_compat.handle_uuid(view.plots.st), {}).get("data")) is not None
                      and len(d[0]) == 5 and d, what="the St plot's five rows")
        assert len(st) == 1 + 2 + 4 + 1 + 1  # t, the corridor's two edges, four fins, St above 1, changes
        np.testing.assert_allclose(np.asarray(st[1]), 0.35)
        np.testing.assert_allclose(np.asarray(st[2]), 0.25)
        for fin, want in enumerate((0.3, 0.4, 0.5, 1.0)):
            np.testing.assert_allclose(np.asarray(st[3 + fin]), want)
        np.testing.assert_allclose(np.asarray(st[7]), 1.0)
        node = wait_for(lambda: page.nodes.get("/ned/ucat") if "wxyz" in page.nodes.get("/ned/ucat", {}) else None,
                        what="the robot's pose")
        assert node["position"] == (0.4, -0.1, 1.04)
        assert node["wxyz"] == (0.9, 0.1, 0.0, 0.4243)
        np.testing.assert_array_equal(view.scene.body.position, (0.4, -0.1, 1.04))  # the handle holds it too
        assert view.tick_errors == 0
        page.close()
    finally:
        server.stop()


def test_a_value_beyond_float32_reaches_the_page_as_the_largest_finite_one() -> None:
    import viser

    from support import wait_for
    from ucat_console.bench.raw_page import RawPage
    from ucat_console.robot.geometry import Geometry
    from ucat_console.telemetry.messages import BodyState
    from ucat_console.ui.view import StreamView

    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        view = StreamView(server.scene, server.gui, Geometry(), plot_rate=10.0, scene_rate=40.0, max_plot_points=200,
                          history=lambda: 10.0, max_history=30.0, corridor=lambda: (0.25, 0.35), trail_points=50,
                          trail_spacing=0.05)
        page = RawPage(f"http://127.0.0.1:{server.get_port()}")
        for k, u in enumerate((0.2, 1e300, 2e300)):
            view.feeder.on_message(ch.BODY_STATE, BodyState(0.1 * k, (0.0, 0.0, 1.0), (1.0, 0.0, 0.0, 0.0),
                                                            (u, 0.0, 0.0), (0.0, 0.0, 0.0), 1.0))
            view.feeder.sample()
        view.refresh_plots()
        uuid = viser_compat.handle_uuid(view.plots.velocity)
        data = wait_for(lambda: (d := page.elements.get(uuid, {}).get("data")) is not None and len(d[0]) == 3
                        and d, what="the velocity plot's three rows")
        u = np.asarray(data[1])
        big = np.finfo(np.float32).max
        np.testing.assert_array_equal(u, np.array([0.2, big, big], np.float32))
        assert np.isfinite(np.asarray(data[3])).all() and np.isfinite(np.asarray(data[4])).all()  # the pins
        page.close()
    finally:
        server.stop()


class _Chart:
    """A uPlot handle as ``ui.viser_compat.set_plot_data`` uses it; keeps the data it was sent."""

    def __init__(self) -> None:
        self._impl = types.SimpleNamespace(props=types.SimpleNamespace(data=None))
        self.sent = 0
        self.order = 0.0

    def _queue_update(self, name: str, value: object) -> None:
        self.sent += 1


class _Gui:
    def add_uplot(self, *args: object, **kwargs: object) -> _Chart:
        chart = _Chart()
        chart.title = kwargs.get("title")
        return chart


_cell = st.one_of(st.floats(-5.0, 5.0), st.floats(-5.0, 5.0), st.floats(-5.0, 5.0),
                  st.sampled_from([math.nan, math.inf, -math.inf, 1e300, -1e300, 0.0, 1.0, 2.5, 0.015]))


@settings(max_examples=200, deadline=None)
@given(capacity=st.integers(1, 40), rows=st.integers(0, 90), window=st.floats(0.05, 5.0),
       max_points=st.integers(1, 50), corridor=st.tuples(st.floats(0.0, 1.0), st.floats(0.0, 1.0)),
       seed=st.integers(0, 2**32 - 1), cells=st.lists(_cell, min_size=1, max_size=60))
def test_the_compiled_series_are_the_numpy_ones(capacity, rows, window, max_points, corridor, seed, cells) -> None:
    """Rows with gaps (NaN, infinities, a column never known), values beyond float32,
    disarmed and slow rows, St above 1, a ring wrapped any number of times, any window and
    decimation: each chart gets the same arrays, bit for bit, as the numpy refresh sent
    (``plots_reference``), and nothing where it sent nothing."""
    rng = np.random.default_rng(seed)
    feeder = PlotFeeder(capacity)
    for k in range(rows):
        row = [cells[int(i)] for i in rng.integers(0, len(cells), len(COL))]
        row[COL["t"]] = 0.1 * k if rng.random() > 0.05 else 0.1 * (k - 1)  # now and then no time passed
        row[COL["armed"]] = float(rng.integers(0, 2)) if rng.random() > 0.1 else math.nan
        feeder.buffer.append(row)
    plots = LivePlots(_Gui(), feeder, rate=10.0, max_points=max_points, corridor=lambda: corridor)
    plots.refresh(window)
    want = chart_data(feeder.buffer, int(math.ceil(window * 10.0)) + 1, max_points, corridor,
                      [MIN_SPAN[name] for name in ("depth", "velocity", "yaw_rate")])
    charts = {"st": plots.st, "depth": plots.depth, "velocity": plots.velocity, "yaw_rate": plots.yaw_rate,
              "power": plots.power}
    if want is None:
        assert all(c.sent == 0 for c in charts.values()) and plots.updates == 0
        return
    assert plots.updates == 1
    for name, chart in charts.items():
        *got, marks = chart._impl.props.data
        assert (marks == -1.0).all()  # no change to mark
        assert len(got) == len(want[name]), name
        for a, b in zip(got, want[name]):
            assert a.dtype == b.dtype and a.flags.c_contiguous, name
            np.testing.assert_array_equal(a.view(np.uint8), np.ascontiguousarray(b).view(np.uint8), err_msg=name)


def test_changes_are_marked_on_every_chart_at_their_rows_and_go_with_a_reset() -> None:
    from ucat_console.telemetry.events import Event
    from ucat_console.ui.plots import change_marks

    t = np.array([0.0, 0.5, 1.0, 1.5, 2.0])
    np.testing.assert_array_equal(change_marks(t, [0.7, 2.0, 3.0, -1.0]), [-1, -1, 1, -1, 1])
    feeder = PlotFeeder(50)
    for k in range(20):
        feeder.on_message(ch.SETPOINTS, Setpoints(0.1 * k, 0.1, 1.0, 0.0))
        if k == 10:
            feeder.on_message(ch.EVENTS, Event(1.0, "loop", "mode", "controller mpc -> baseline", "info"))
            feeder.on_message(ch.EVENTS, Event(1.0, "loop", "plan_overrun", "late", "warning"))  # not a change
        feeder.sample()
    assert list(feeder.changes) == [1.0]
    plots = LivePlots(_Gui(), feeder, rate=10.0, max_points=100, corridor=lambda: (0.25, 0.35))
    plots.refresh(5.0)
    for chart in (plots.st, plots.depth, plots.velocity, plots.yaw_rate, plots.power):
        t, *_, marks = chart._impl.props.data
        assert t[marks == 1.0].tolist() == [1.0]
    feeder.reset()
    assert not feeder.changes


NAN = math.nan


def _power(t: float, per_fin: tuple, distance: float = 0.0, mean: float = NAN, epm: float = NAN) -> Power:
    return Power(t, per_fin, sum(per_fin), mean, NAN, distance, epm)


def _electrical(t: float, per_fin: tuple) -> ElectricalPower:
    return ElectricalPower(t, (1.0,) * 4, (24.0,) * 4, per_fin, sum(per_fin))


def _status(t: float, armed: bool) -> Status:
    return Status(t, armed, "mpc", "", (), 0, "sim")


def _power_chart(feeder: PlotFeeder) -> tuple[LivePlots, list[np.ndarray]]:
    """The live plots of ``feeder``'s rows, refreshed once, and the power chart's series
    (the time axis and the change marks left out)."""
    plots = LivePlots(_Gui(), feeder, rate=10.0, max_points=100, corridor=lambda: (0.25, 0.35))
    plots.refresh(10.0)
    _, *series, _ = plots.power._impl.props.data
    return plots, [np.asarray(s, dtype=np.float64) for s in series]


def test_the_power_chart_draws_the_battery_with_the_estimates_total_beside_it() -> None:
    f = PlotFeeder(capacity=50)
    f.on_message(ch.STATUS, _status(0.0, True))
    for k in range(5):
        t = 0.1 * k
        f.on_message(ch.POWER, _power(t, (0.5, 0.5, 0.5, 0.5), distance=0.01 * k, mean=2.0, epm=7.0))
        f.on_message(ch.POWER_ELECTRICAL, _electrical(t, (3.0, 4.0, 5.0, 6.0 + k)))
        f.sample()
    plots, (*fins, total, mean, epm, shaft) = _power_chart(f)
    for i, want in enumerate((3.0, 4.0, 5.0)):
        np.testing.assert_array_equal(fins[i], want)  # each drive's battery power
    np.testing.assert_array_equal(fins[3], [6.0, 7.0, 8.0, 9.0, 10.0])
    np.testing.assert_array_equal(total, [18.0, 19.0, 20.0, 21.0, 22.0])  # the battery's total
    np.testing.assert_array_equal(shaft, 2.0)  # the estimate's total, beside it
    # the battery's running mean and energy per metre (0.01 m each 0.1 s), not the loop's 2 W and 7 J/m;
    # before the first (two readings) as the first
    np.testing.assert_allclose(mean, [18.5, 18.5, 19.0, 19.5, 20.0], rtol=1e-6)
    np.testing.assert_allclose(epm, [185.0, 185.0, 190.0, 195.0, 200.0], rtol=1e-6)
    assert plots.source == "electrical"
    assert plots.power.title == "Power (W) and energy per metre (J/m): electrical (battery); " \
                                "total of the mechanical (shaft estimate) dotted"


def test_without_electrical_readings_the_estimate_is_drawn_and_labelled_so() -> None:
    f = PlotFeeder(capacity=50)
    f.on_message(ch.STATUS, _status(0.0, True))
    for k in range(5):
        t = 0.1 * k
        f.on_message(ch.POWER, _power(t, (0.5, 0.5, 0.5, 0.5 + k), distance=0.01 * k, mean=2.5, epm=7.0))
        # a drive that does not answer: its reading and the total are NaN
        f.on_message(ch.POWER_ELECTRICAL, _electrical(t, (3.0, NAN, 5.0, 6.0)))
        f.sample()
    plots, (*fins, total, mean, epm, shaft) = _power_chart(f)
    np.testing.assert_array_equal(fins[0], 0.5)  # the estimate's, not the battery's 3 W
    np.testing.assert_array_equal(total, [2.0, 3.0, 4.0, 5.0, 6.0])
    np.testing.assert_array_equal(mean, 2.5)  # the loop's running mean and energy per metre
    np.testing.assert_array_equal(epm, 7.0)
    assert np.isnan(shaft).all()  # nothing beside it
    assert plots.source == "mechanical"
    assert plots.power.title == ("Power (W) and energy per metre (J/m): "
                                 "mechanical (shaft estimate): no electrical readings")
    # the drives answer: the battery's again, and the title says so
    f.on_message(ch.POWER_ELECTRICAL, _electrical(0.5, (3.0, 4.0, 5.0, 6.0)))
    f.on_message(ch.POWER, _power(0.5, (0.5,) * 4))
    f.sample()
    plots.refresh(10.0)
    assert plots.source == "electrical" and plots.power.title.endswith("electrical (battery); "
                                                                      "total of the mechanical (shaft estimate) dotted")


def test_a_power_figure_never_known_in_the_window_is_drawn_as_nothing_not_zero() -> None:
    f = PlotFeeder(capacity=50)
    f.on_message(ch.STATUS, _status(0.0, False))  # disarmed: no running mean, no energy per metre
    for k in range(4):
        t = 0.1 * k
        f.on_message(ch.POWER, _power(t, (0.5,) * 4))
        f.on_message(ch.POWER_ELECTRICAL, _electrical(t, (3.0, 4.0, 5.0, 6.0)))
        f.sample()
    _, (*fins, total, mean, epm, shaft) = _power_chart(f)
    np.testing.assert_array_equal(total, 18.0)
    np.testing.assert_array_equal(shaft, 2.0)
    assert np.isnan(mean).all() and np.isnan(epm).all()  # never known: nothing drawn
    # no electrical reading and no estimate either (a recording without power): nothing at all
    f = PlotFeeder(capacity=50)
    for k in range(4):
        f.on_message(ch.SETPOINTS, Setpoints(0.1 * k, 0.2, 1.0, 0.0))
        f.sample()
    plots, power = _power_chart(f)
    assert all(np.isnan(s).all() for s in power)
    assert plots.source == "mechanical"


def test_the_battery_running_mean_and_energy_per_metre_by_hand() -> None:
    """Trapezoids between finite readings of one armed stretch: a NaN reading skipped (not
    counted 0), a drop of the loop's distance count a new start, a disarm between two
    readings (a NaN one in between) not counted; energy per metre over the distance."""
    f = PlotFeeder(capacity=50)
    f.on_message(ch.STATUS, _status(0.0, True))
    steps = [  # t, the battery's total (W), the loop's distance count (m), a Status before (armed)
        (0.0, 10.0, 0.0, None),
        (1.0, 20.0, 0.5, None),  # 15 J over 1 s and 0.5 m
        (2.0, NAN, 1.0, None),  # a drive did not answer: skipped
        (3.0, 30.0, 1.5, None),  # 50 J over 2 s and 1.0 m
        (4.0, 30.0, 0.25, None),  # the loop counts again from 0: 30 J over 1 s and 0.25 m
        (5.0, NAN, 0.25, False),  # disarmed at 4.5 s ...
        (6.0, 40.0, 0.75, True),  # ... armed again at 5.5 s: 4 to 6 s not counted
        (7.0, 60.0, 1.25, None),  # 50 J over 1 s and 0.5 m
    ]
    for t, total, distance, armed in steps:
        if armed is not None:
            f.on_message(ch.STATUS, _status(t - 0.5, armed))
        f.on_message(ch.POWER, _power(t, (0.5,) * 4, distance=distance))
        f.on_message(ch.POWER_ELECTRICAL, _electrical(t, (total / 4,) * 4))
        f.sample()
    rows = f.buffer.last(50)
    assert list(rows[:, COL["t"]]) == [s[0] for s in steps]
    energy = np.array([NAN, 15.0, 15.0, 65.0, 95.0, 95.0, 95.0, 145.0])
    time = np.array([NAN, 1.0, 1.0, 3.0, 4.0, 4.0, 4.0, 5.0])
    distance = np.array([NAN, 0.5, 0.5, 1.5, 1.75, 1.75, 1.75, 2.25])
    np.testing.assert_allclose(rows[:, COL["e_mean"]], energy / time)
    np.testing.assert_allclose(rows[:, COL["e_energy_per_metre"]], energy / distance)
    assert f.battery.mean == pytest.approx(29.0) and f.battery.energy_per_metre == pytest.approx(145.0 / 2.25)
    # drawn as computed (float32), the NaN reading as the reading before it
    _, (*_, total, mean, epm, _) = _power_chart(f)
    np.testing.assert_array_equal(total, np.float32([10.0, 20.0, 20.0, 30.0, 30.0, 30.0, 40.0, 60.0]))
    np.testing.assert_array_equal(mean[1:], (energy / time)[1:].astype(np.float32))
    assert mean[0] == mean[1]  # before the first known value: the first one
    f.reset()
    assert math.isnan(f.battery.mean) and math.isnan(f.battery.energy_per_metre)
