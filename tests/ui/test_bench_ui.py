"""``ucat-console bench ui`` in headless Chromium: its page instrumentation sees the pose
updates arrive and appear, and the figures it reports hang together."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

pytest.importorskip("playwright.sync_api")

from ucat_console.bench.ui import format_result, measure_ui, summary  # noqa: E402

pytestmark = [pytest.mark.browser, pytest.mark.slow]

CHROMIUM = os.environ.get("UCAT_CHROMIUM", "/usr/bin/chromium")


def test_bench_counts_pose_updates_delivered_and_displayed_on_every_page() -> None:
    if not Path(CHROMIUM).exists() and shutil.which("chromium") is None:
        pytest.skip(f"no Chromium at {CHROMIUM}")
    r = measure_ui(duration=3.0, pages=2, warmup=1.0, chromium=CHROMIUM)

    assert r["server_scene_updates_per_s"] > 0.5 * r["configured_scene_rate"]
    assert len(r["pages"]) == 2
    for page in r["pages"]:
        # every page hears about the pose updates the server pushes, and shows a part of them
        assert page["pose_updates_delivered_per_s"] > 0.5 * r["server_scene_updates_per_s"]
        assert 0 < page["pose_updates_per_s"] <= page["pose_updates_delivered_per_s"] + 1.0
        assert page["plot_refresh_per_s"] > 0
        # latency: publication to display, on one clock, so positive and below a second
        assert page["samples"] > 0
        assert 0 < page["latency_ms_p50"] <= page["latency_ms_p95"] <= page["latency_ms_max"] < 1000
    assert 0 < r["supervisor_cpu_percent"] < 200
    assert r["recording"]  # as at the pool, arming started a recording
    # the browser's own processes are found and measured (the pages draw, so both work)
    assert r["browser_cpu_percent"]["gpu"] > 0 and r["browser_cpu_percent"]["renderer"] > 0

    s = summary(r)
    assert s["pose_updates_per_s"] <= s["pose_updates_delivered_per_s"] + 1.0
    text = format_result(r)
    assert "delivered to the page / displayed" in text and text.count("\n") >= 5
