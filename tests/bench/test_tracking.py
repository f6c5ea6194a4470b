"""``bench tracking``'s figures from a run's log (synthetic logs: no simulation)."""

import numpy as np
import pytest

from ucat_console.bench.tracking import GOALS, STEP_AT, _figures, _Log, manoeuvres


def _log(t, depth, yaw):
    lg = _Log()
    lg.t, lg.depth, lg.yaw = list(t), list(depth), list(yaw)
    lg.yaw_rate = [0.0] * len(lg.t)
    lg.x = lg.y = lg.energy = [0.0] * len(lg.t)
    return lg


def test_a_2_m_depth_step_is_judged_like_the_1_m_one():
    """The 2-m step (0.5 -> 2.5 m) gets its time to 90 %, overshoot and heading from its
    start; its t90 goal is the dive-rate limit's time for 90 % of 2 m plus 10 s."""
    m = next(m for m in manoeuvres(quick=True) if m.name == "depth_step_2m")
    assert (m.depth, m.step_to) == (0.5, 2.5)
    t = np.arange(0.0, m.duration, 0.1)
    depth = np.where(t < STEP_AT, 0.5, np.minimum(2.5, 0.5 + 0.06 * (t - STEP_AT)))
    yaw = np.radians(np.where(t < 40.0, 0.0, 4.0))
    f = _figures(m, _log(t, depth, yaw))
    assert f["t90"] == pytest.approx(1.8 / 0.06, abs=0.2)
    assert f["overshoot"] == 0.0
    assert f["heading_all_deg"] == pytest.approx(4.0)
    assert GOALS["depth_step_2m/t90"] == ("<=", pytest.approx(40.0))


def test_the_speed_step_steps_the_speed_and_judges_the_heading():
    m = next(m for m in manoeuvres(quick=True) if m.name == "speed_step")
    assert (m.velocity, m.speed_to, m.step_to) == (0.1, 0.35, None)
    t = np.arange(0.0, m.duration, 0.1)
    f = _figures(m, _log(t, np.ones_like(t), np.radians(np.where(t < 30.0, 0.0, -6.0))))
    assert f["heading_all_deg"] == pytest.approx(6.0)
    assert "t90" not in f


def test_the_gait_change_is_the_baselines_and_judged_on_its_heading():
    from ucat_console.bench.tracking import GAIT_FROM, GAIT_TO, verdicts

    m = next(m for m in manoeuvres(quick=True) if m.name == "gait_change")
    assert (m.velocity, m.gait_to, GAIT_FROM, GAIT_TO) == (0.1, 0.5, 2.0, 0.5)
    t = np.arange(0.0, m.duration, 0.1)
    f = _figures(m, _log(t, np.ones_like(t), np.radians(np.where(t < 30.0, 0.0, 6.0))))
    assert f["heading_all_deg"] == pytest.approx(6.0)
    v = verdicts({"gait_change": f})
    assert v["gait_change/heading_all_deg"]["met"] is False
    assert "gait_change/heading_all_deg" not in verdicts({"straight": {"heading_all_deg": 1.0}})


def test_a_cruise_is_costed_per_metre_from_when_its_speed_is_judged():
    """``j_per_m``: the energy the fins drew over the path travelled from SPEED_FROM on (a
    sideways weave counts as distance), not over the start from rest."""
    from ucat_console.bench.tracking import SPEED_FROM

    m = next(m for m in manoeuvres(quick=True) if m.name == "speed_0.2")
    t = np.arange(0.0, m.duration, 0.1)
    lg = _log(t, np.ones_like(t), np.zeros_like(t))
    lg.x = list(0.2 * t)
    lg.y = [0.0] * len(t)
    # 100 W before SPEED_FROM (the start), 10 W after: 50 J/m at 0.2 m/s
    lg.energy = list(np.where(t < SPEED_FROM, 100.0 * t, 100.0 * SPEED_FROM + 10.0 * (t - SPEED_FROM)))
    lg.dvl_t, lg.dvl_v = list(t), [0.2] * len(t)
    f = _figures(m, lg)
    assert f["j_per_m"] == pytest.approx(50.0, rel=1e-3)
    assert f["within"] == 1.0
