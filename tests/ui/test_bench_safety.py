"""``ucat-console bench safety``: the link-loss measure in headless Chromium (the page's own
record of its banner is found after the console stops), the disarm under a viewer's spam
and the pilot on a slow link, each on a small scale: the figures they report hang together
(how fast is the benchmark's to report, not a test's to judge)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from ucat_console.bench.safety import disarm_under_spam, format_result, slow_link

pytestmark = [pytest.mark.slow]


def test_the_disarm_under_spam_measure_disarms_each_trial_while_the_spam_is_rationed() -> None:
    r = disarm_under_spam(2, copies=3, session_seconds=1.0, spammers=1, rate=20.0, before=1.0)
    assert r["trials"] == 2 and len(r["delays_s"]) == 2
    assert all(math.isfinite(t) and t >= 0 for t in r["delays_s"])
    assert r["delay_max_s"] == max(r["delays_s"])
    assert r["folder"]["copies"] == 3 and r["folder"]["file_bytes"] > 0
    assert r["jobs_run"] >= 1 and r["jobs_refused"] >= 1  # the viewer's clicks went to the page jobs
    text = format_result({"disarm_under_spam": r, "load_before": 1.0, "load_after": 1.0})
    assert f"median {r['delay_median_s'] * 1e3:.0f} ms" in text


def test_the_slow_link_measure_watches_a_pilot_reading_50_kb_s() -> None:
    r = slow_link(50_000.0, 3.0)
    assert r["stayed_pilot"] and r["pilot_for_s"] >= 3.0 and not r["gone_events"]
    assert 0 < r["read_bytes_s"] < 2 * 50_000.0
    assert r["rtt_max_s"] is not None and r["rtt_median_s"] <= r["rtt_max_s"]
    text = format_result({"slow_link": r, "load_before": 1.0, "load_after": 1.0})
    assert "stayed the pilot" in text


@pytest.mark.browser
def test_the_link_loss_measure_sees_the_pages_banner_after_the_console_stops() -> None:
    pytest.importorskip("playwright.sync_api")
    from ucat_console.bench.safety_browser import link_loss
    from ucat_console.bench.ui import CHROMIUM

    if not Path(CHROMIUM).exists():
        pytest.skip(f"no Chromium at {CHROMIUM}")
    r = link_loss(2)
    assert r["trials"] == 2 and len(r["banner_s"]) == 2
    # the banner comes after the stop: the page waits for its silence first
    assert all(math.isfinite(t) and t > 0 for t in r["banner_s"])
    assert r["banner_median_s"] <= r["banner_max_s"] == max(r["banner_s"])
    text = format_result({"frozen_pilot": {"trials": 1, "pilot_gone_timeout_s": 2.0, "detection_median_s": 2.1,
                                           "detection_max_s": 2.2},
                          "takeover_under_spam": {"trials": 1, "takeover_median_s": 0.006, "takeover_max_s": 0.008,
                                                  "wrong_tokens_refused": 3},
                          "crowd": {"broken_total": 0, "rounds": 1, "pages": 2},
                          "link_loss": r, "load_before": 1.0, "load_after": 1.0})
    assert f"banner after median {r['banner_median_s']:.2f} s" in text


@pytest.mark.browser
def test_the_slow_link_and_restart_measures_report_what_they_measured() -> None:
    pytest.importorskip("playwright.sync_api")
    from ucat_console.bench.safety_browser import restarts, slow_connect, slow_disarm

    c = slow_connect(0.3, 1)
    assert 0 < c["loaded_median_s"] <= c["connect_median_s"] and c["socket_median_s"] <= c["connect_median_s"], c
    d = slow_disarm(0.3, 2)
    assert d["applied"] + d["not_applied"] + len(d["disarmed_otherwise"]) == 2, d
    assert len(d["disarm_s"]) == d["applied"], d
    assert all(t >= 0.3 for t in d["disarm_s"]), d  # at least the link's delay
    r = restarts(2, 0)
    assert r["back"] == 2 and r["from_up_max_s"] <= r["from_stop_max_s"], r
    text = format_result({"slow_connect": c, "slow_disarm": d, "restart": r, "load_before": 1.0,
                          "load_after": 1.0})
    assert "the pilot's page the pilot again 2 of 2 times" in text and "DISARM through 0.3 s" in text
