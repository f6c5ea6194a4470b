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

    # what the benchmark reports is there and counted something; how fast depends on the
    # machine and its load, which is the benchmark's to report, not a test's to judge
    assert r["server_scene_updates_per_s"] > 0
    assert len(r["pages"]) == 2
    for page in r["pages"]:
        assert page["pose_updates_delivered_per_s"] > 0
        assert 0 < page["pose_updates_per_s"]
        assert page["plot_refresh_per_s"] > 0
        assert page["samples"] > 0
        assert 0 < page["latency_ms_p50"] <= page["latency_ms_p95"] <= page["latency_ms_max"]
    assert r["supervisor_cpu_percent"] > 0
    # measured again with the probe off: it was off (no page saw a probe sent after that)
    assert r["supervisor_cpu_percent_without_probe"] > 0
    assert all(0 <= seq <= r["probe_last_seq_when_off"] for seq in r["probe_last_seq_seen"]), r
    assert r["supervisor_threads_cpu_percent_without_probe"]
    assert r["recording"]  # as at the pool, arming started a recording
    # the browser's own processes are found and measured (the pages draw, so both work)
    assert r["browser_cpu_percent"]["gpu"] > 0 and r["browser_cpu_percent"]["renderer"] > 0

    # the plots' series timed after the run, over the live plots' window as the run left it
    parts = r["page_parts"]
    assert parts["plot_series_points"] >= 2 and parts["plot_series_us"] > 0

    s = summary(r)
    assert set(s) >= {"pose_updates_per_s", "pose_updates_delivered_per_s"}
    text = format_result(r)
    assert "delivered to the page / displayed" in text and text.count("\n") >= 5
