"""``ucat-console bench safety``'s link-loss measure in headless Chromium: the page's own
record of its banner is found after the console stops, and the figure it reports hangs
together (how fast is the benchmark's to report, not a test's to judge)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

pytest.importorskip("playwright.sync_api")

from ucat_console.bench.safety import format_result, link_loss  # noqa: E402
from ucat_console.bench.ui import CHROMIUM  # noqa: E402

pytestmark = [pytest.mark.browser, pytest.mark.slow]


def test_the_link_loss_measure_sees_the_pages_banner_after_the_console_stops() -> None:
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
