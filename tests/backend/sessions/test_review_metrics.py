"""The efficiency figures against values computed by hand on a synthetic run."""

from __future__ import annotations

import math

import pytest
from session_helpers import record
from synthetic_run import BATTERY, MASS, PER_FIN, run_items

from ucat_console.backend.review.compare import load_run
from ucat_console.backend.review.metrics import (
    ELECTRICAL,
    MECHANICAL,
    MetricsConfig,
    RunData,
    fins_now,
    robot_now,
    table_row,
    window_figures,
)
from ucat_console.telemetry import channels as C

CFG = MetricsConfig(mass=MASS, resamples=400)


def _data(**kw) -> RunData:
    d = RunData()
    for channel, m in run_items(**kw):
        d.feed(channel, m)
    return d


def test_table_row_of_a_recorded_run_matches_the_hand_computed_figures(sessions):
    [path] = record(sessions, run_items(), label="hand")
    run = load_run(path, sessions)
    row = table_row(run.data, run.start, run.end, CFG)
    f = {k: e.value for k, e in row.figures.items()}
    # 4 W at 0.2 m/s: 20 J per metre, 20 / 22 J/(kg m)
    assert f["power"] == pytest.approx(4.0)
    assert f["energy_per_metre"] == pytest.approx(20.0)
    assert f["cost_of_transport"] == pytest.approx(20.0 / 22.0)
    assert f["speed"] == pytest.approx(0.2)
    assert f["speed_mae"] == pytest.approx(0.02)
    assert f["depth_mae"] == pytest.approx(0.05)
    assert f["heading_mae"] == pytest.approx(0.1)
    # strokes 0.30 and 0.40 in turn: |St - 0.30| is 0 and 0.1, half in the corridor
    assert f["st_mae"] == pytest.approx(0.05)
    assert f["st_in"] == pytest.approx(50.0)
    for i, p in enumerate(PER_FIN):
        assert f[f"power_{i}"] == pytest.approx(p)
        assert f[f"st_mae_{i}"] == pytest.approx(0.05)
        assert f[f"st_in_{i}"] == pytest.approx(50.0)
    assert row.cycles == 18  # fin 0's cycle ends at 1..19 s cut 0..19.9 s into 18 whole cycles


def test_a_window_adds_up_and_a_part_of_it_has_its_own_figures():
    d = _data(speed=0.25, scale=2.0)
    row = table_row(d, 5.0, 15.0, CFG)
    assert row.figures["power"].value == pytest.approx(8.0)
    assert row.figures["energy_per_metre"].value == pytest.approx(32.0)  # 8 W / 0.25 m/s
    assert row.figures["cost_of_transport"].value == pytest.approx(32.0 / MASS)


def test_a_restarted_distance_count_is_not_negative_distance():
    d = RunData()
    for channel, m in run_items():
        if channel == "power" and m.t >= 10.0:  # the loop restarted its count at 10 s
            m = type(m)(m.t, m.per_fin, m.total, m.mean_total, 0.0, 0.2 * (m.t - 10.0), m.energy_per_metre)
        d.feed(channel, m)
    row = table_row(d, 0.0, 19.9, CFG)
    # 9.9 m... : 0.2 m/s up to 9.9 s, then the count restarts at 0 (the 0.1 s between the
    # last sample before and the first after is lost, not counted negative)
    assert row.figures["speed"].value == pytest.approx(0.2 * 19.8 / 19.9)


def test_bootstrap_intervals_hold_the_figure_and_are_repeatable():
    wobble = lambda k: 1.0 + 0.5 * ((k * 7) % 5 - 2) / 2  # cycle k's power: 0.5x .. 1.5x
    d = _data(cycle_scale=wobble)
    a = table_row(d, 0.0, 19.9, CFG)
    b = table_row(d, 0.0, 19.9, CFG)
    p = a.figures["power"]
    assert p.lo < p.value < p.hi
    assert (p.lo, p.hi) == (b.figures["power"].lo, b.figures["power"].hi)
    # the powers of the cycles vary, the strokes do not: a zero-width St interval
    st = a.figures["st_mae"]
    assert st.lo == pytest.approx(0.05) and st.hi == pytest.approx(0.05)
    # a confidence of 0.5 gives a narrower interval than 0.95
    narrow = table_row(d, 0.0, 19.9, MetricsConfig(mass=MASS, resamples=400, confidence=0.5)).figures["power"]
    assert p.lo < narrow.lo < narrow.hi < p.hi


def test_fewer_than_two_cycles_give_no_interval_and_no_power_is_refused():
    d = _data(duration=1.5)
    row = table_row(d, 0.0, 1.4, CFG)
    assert math.isnan(row.figures["power"].lo) and row.figures["power"].value == pytest.approx(4.0)
    with pytest.raises(ValueError, match="no power messages"):
        table_row(RunData(), 0.0, 1.0, CFG)
    with pytest.raises(ValueError, match="empty time window"):
        table_row(d, 1.0, 1.0, CFG)


def test_live_figures_per_fin_and_of_the_robot():
    d = _data()
    cfg = MetricsConfig(window=10.0, mass=MASS)
    fins = fins_now(d, 19.9, cfg)
    for f in fins:
        # the latest two strokes: 0.30 at 19.0 s (inside) then 0.40 at 19.5 s (outside)
        assert [s.st for s in f.strokes] == [0.30, 0.40]
        assert [s.in_corridor for s in f.strokes] == [True, False]
        assert f.power == pytest.approx(PER_FIN[f.fin])
        assert f.opening == pytest.approx(0.1)
        assert f.winding == pytest.approx(0.6)  # 0.01 rad/s
    r = robot_now(d, 19.9, cfg)
    assert (r.power, r.energy_per_metre, r.cost_of_transport) == pytest.approx((4.0, 20.0, 20.0 / MASS))
    # the closed window 9.9..19.9 s holds 101 tracking samples: 50 of +0.01, 51 of -0.03
    assert (r.speed_mae, r.depth_mae, r.heading_mae) == pytest.approx(((50 * 0.01 + 51 * 0.03) / 101, 0.05, 0.1))
    d.drop_before(15.0)  # a live view keeps its window only
    assert robot_now(d, 19.9, MetricsConfig(window=4.0, mass=MASS)).power == pytest.approx(4.0)


def test_the_battery_power_is_the_default_and_the_encoders_estimate_is_beside_it(sessions):
    [path] = record(sessions, run_items(battery_from=0.0), label="battery")
    run = load_run(path, sessions)
    row = table_row(run.data, run.start, run.end, CFG)
    f = {k: e.value for k, e in row.figures.items()}
    assert (row.source, row.source_label) == (ELECTRICAL, "electrical (battery)")
    # the drives draw 12 W at 0.2 m/s: 60 J per metre; the encoders' estimate 4 W beside it
    assert (f["power"], f["energy_per_metre"], f["cost_of_transport"]) == pytest.approx((12.0, 60.0, 60.0 / MASS))
    assert (f["mech_power"], f["mech_energy_per_metre"], f["mech_cost_of_transport"]) == pytest.approx(
        (4.0, 20.0, 20.0 / MASS))
    for i in range(4):
        assert (f[f"power_{i}"], f[f"mech_power_{i}"]) == pytest.approx((BATTERY[i], PER_FIN[i]))
    assert f["speed"] == pytest.approx(0.2)  # the distance is the same whichever power
    r = robot_now(run.data, run.end, MetricsConfig(window=10.0, mass=MASS))
    assert r.source_label == "electrical (battery)"
    assert (r.power, r.energy_per_metre, r.mech_power, r.mech_energy_per_metre) == pytest.approx(
        (12.0, 60.0, 4.0, 20.0))
    assert [fin.power for fin in fins_now(run.data, run.end, CFG)] == pytest.approx(list(BATTERY))


def test_without_electrical_readings_the_figures_are_the_estimate_labelled_so():
    d = _data()
    row = table_row(d, 0.0, 19.9, CFG)
    assert row.source == MECHANICAL
    assert row.source_label == "mechanical (shaft estimate): no electrical readings"
    assert row.figures["power"].value == pytest.approx(4.0) == row.figures["mech_power"].value
    r = robot_now(d, 19.9, CFG)
    assert r.source_label == row.source_label and r.power == pytest.approx(4.0)
    # asked for the battery's figures where there are none: NaN, never zero
    f = window_figures(d, 0.0, 19.9, MASS, source=ELECTRICAL)
    assert math.isnan(f["power"]) and math.isnan(f["energy_per_metre"]) and math.isnan(f["power_0"])
    assert f["mech_power"] == pytest.approx(4.0)


def test_electrical_readings_from_partway_count_over_the_stretch_they_cover():
    d = _data(battery_from=10.0)  # the drives report from 10 s (the real robot's start)
    row = table_row(d, 0.0, 19.9, CFG)
    assert row.source == ELECTRICAL
    # over 10..19.9 s: 12 W and the 0.2 m/s of that stretch, not diluted by the 10 s before it
    assert (row.figures["power"].value, row.figures["energy_per_metre"].value) == pytest.approx((12.0, 60.0))
    assert row.figures["mech_energy_per_metre"].value == pytest.approx(20.0)
    before = table_row(d, 0.0, 9.5, CFG)
    assert before.source == MECHANICAL and before.figures["power"].value == pytest.approx(4.0)


def test_a_drive_that_did_not_answer_is_skipped_not_counted_zero():
    d = RunData()
    for channel, m in run_items(battery_from=0.0):
        if channel == C.POWER_ELECTRICAL and 5.0 <= m.t < 10.0:  # fin 2's drive silent for 5 s
            per = (m.per_fin[0], m.per_fin[1], math.nan, m.per_fin[3])
            m = type(m)(m.t, m.current, m.voltage, per, math.nan)
        d.feed(channel, m)
    f = window_figures(d, 0.0, 19.9, MASS)
    assert f["power"] == pytest.approx(12.0) and f["power_2"] == pytest.approx(BATTERY[2])
