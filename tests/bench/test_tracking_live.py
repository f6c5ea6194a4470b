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


def _start(seed: int, heading: float, depth: float, band: float, alarms: int, failsafes: list[str],
           fault: str = "") -> dict:
    return {"mode": "mpc", "formulation": "paper", "seed": seed, "samples": 10, "fault": fault,
            "heading_max_deg": heading, "depth_dev_m": depth, "speed_in_band": band,
            "tracking_alarms": alarms, "failsafes": failsafes, "max_lag_s": 0.01 * (seed + 1),
            "stalls": seed, "load_average": 2.0 + seed}


def test_a_modes_starts_are_reported_by_their_worst() -> None:
    starts = [_start(0, 2.0, 0.03, 0.9, 0, []), _start(1, 4.5, math.nan, 0.6, 1, ["tracking"]),
              _start(2, 3.0, 0.05, math.nan, 0, ["depth_limit"], fault="stopped")]
    r = tracking_live.worst(starts)
    assert r["heading_max_deg"] == 4.5 and r["depth_dev_m"] == 0.05  # a start without the window is skipped
    assert r["speed_in_band"] == 0.6  # the least share in band
    assert r["tracking_alarms"] == 1 and r["failsafes"] == ["depth_limit", "tracking"]
    assert r["stalls"] == 3 and r["samples"] == 30 and r["max_lag_s"] == 0.03 and r["load_average"] == 4.0
    assert r["fault"] == "seed 2: stopped" and r["starts"] == starts
    text = tracking_live.format_mode("mpc", r)
    assert "3 starts" in text and "tracking alarms 1" in text and "STOPPED: seed 2" in text


def test_no_start_is_refused() -> None:
    with pytest.raises(ValueError, match="--starts"):
        tracking_live.measure(("mpc",), 0, seconds=10.0, step_at=5.0, depth_step=0.5, velocity=0.2, starts=0)
