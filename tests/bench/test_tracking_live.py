"""``bench tracking-live``: the console's loop at real time, judged on the simulator's truth."""

from __future__ import annotations

import math

import pytest

from ucat_console.bench import tracking_live


@pytest.mark.slow
def test_a_short_live_run_is_judged_from_arming_on_the_truth() -> None:
    r = tracking_live.run_mode("baseline", "paper", seconds=8.0, step_at=4.0, depth_step=0.3, velocity=0.2)
    assert r["fault"] == "" and r["samples"] > 10
    # judged from arming: a few degrees at most on a nominal start, never NaN
    assert 0.0 <= r["heading_max_deg"] < 30.0
    # the windows for depth (45 s after the step) and speed (from 30 s) are not reached
    assert math.isnan(r["depth_dev_m"]) and math.isnan(r["speed_in_band"])
    assert r["tracking_alarms"] == 0 and "tracking" not in r["failsafes"]
    text = tracking_live.format_mode("baseline", {**r, "load_average": 1.0})
    assert "tracking alarms 0" in text and "STOPPED" not in text


def test_a_step_outside_the_run_is_refused() -> None:
    with pytest.raises(ValueError, match="--step-at"):
        tracking_live.measure(("mpc",), 0, seconds=10.0, step_at=10.0, depth_step=0.5, velocity=0.2)
