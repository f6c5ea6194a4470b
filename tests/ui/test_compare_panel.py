"""The page's comparison of runs: two recordings made here compared and overlaid, every
value a page could send checked (sessions not in the listing, unknown codes), and in
headless Chromium the Review tab's Compare folder used as an operator would."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parents[1] / "backend" / "sessions"))
from session_helpers import record  # noqa: E402
from synthetic_run import run_items  # noqa: E402

from ucat_console.backend.review.metrics import MetricsConfig  # noqa: E402
from ucat_console.telemetry.events import Event  # noqa: E402
from ucat_console.ui.compare_panel import NONE, ComparePanel, page_table  # noqa: E402
from ucat_console.ui.markdown import esc  # noqa: E402
from ucat_console.ui.session_list import SessionList  # noqa: E402

SLOW, FAST = "20231114-221320-slow", "20231114-221500-fast"


def _record_two(directory: Path) -> None:
    marker = (Event(5.0, "operator", "marker", "go", "info"),)
    record(directory, run_items(events=marker), label="slow", wall_time=1_700_000_000.0)
    record(directory, run_items(scale=2.0, speed=0.25, events=marker), label="fast", wall_time=1_700_000_100.0)


@pytest.fixture
def panel(tmp_path: Path):
    import viser

    _record_two(tmp_path)
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        yield ComparePanel(server.gui, None, tmp_path, cfg=MetricsConfig(resamples=200),
                           sessions=SessionList(tmp_path).sessions)
    finally:
        server.stop()


def test_two_sessions_compared_with_the_table_the_overlay_and_the_downloads(panel):
    assert panel.runs[0].options == (NONE, SLOW, FAST)
    rows = panel.run([SLOW, FAST, NONE, NONE], NONE, "marker")
    assert [r.label for r in rows] == [SLOW, FAST]
    assert rows[1].figures["energy_per_metre"].value == pytest.approx(32.0)
    assert "**not comparable**" in panel.table.content and "| 20 \\[" in panel.table.content
    # recordings without electrical readings: the estimate's figures, labelled so
    assert panel.table.content.startswith(esc("Power: mechanical (shaft estimate): no electrical readings"))
    assert panel.image.visible and panel.image.image.shape[2] == 3
    name, data = panel._downloads["CSV"]
    assert name == f"compare-{SLOW}-vs-{FAST}.csv" and b"energy_per_metre" in data  # named after the runs
    assert panel._downloads["PNG"][1][:4] == b"\x89PNG"
    [w] = [w for w in panel.result[1] if w.run.name == FAST]
    assert w.zero == pytest.approx(w.run.origin + 5.0)  # aligned at the marker


@pytest.mark.parametrize("chosen, segments, align, match", [
    (["../etc/passwd", NONE, NONE, NONE], NONE, "start", "is not a session"),
    ([SLOW, 3, NONE, NONE], NONE, "start", "run 2"),
    ([SLOW, FAST, NONE, NONE], "everything", "start", "segments"),
    ([SLOW, FAST, NONE, NONE], NONE, {"x": 1}, "align"),
    ([NONE] * 4, NONE, "start", "choose the sessions"),
    ([SLOW, NONE, NONE, NONE], NONE, "start", "Segments at"),
])
def test_what_a_page_sends_is_checked_and_refused_naming_it(panel, chosen, segments, align, match):
    with pytest.raises(ValueError, match=match):
        panel.run(chosen, segments, align)
    assert panel.result is None


def test_one_session_cut_into_segments(panel):
    rows = panel.run([SLOW, NONE, NONE, NONE], "marker", "start")
    assert len(rows) == 2 and rows[1].label.endswith("(marker: go)")
    assert panel._downloads["Markdown"][0] == f"compare-{SLOW}-at-marker.md"


def test_the_table_says_its_power_is_the_batterys(tmp_path: Path):
    from ucat_console.backend.review import compare

    record(tmp_path, run_items(battery_from=0.0), label="a", wall_time=1_700_000_000.0)
    run = compare.load_run("20231114-221320-a", tmp_path)
    rows = compare.table(compare.windows(run), MetricsConfig(resamples=50))
    text = page_table(rows)
    assert text.startswith(esc("Power: electrical (battery)")) and "| 60 " in text  # 12 W at 0.2 m/s


def test_the_table_names_each_runs_modes_and_weights(tmp_path: Path):
    import viser

    _record_two(tmp_path)
    about = {SLOW: "mpc; lam_st=2", FAST: "baseline"}
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        p = ComparePanel(server.gui, None, tmp_path, cfg=MetricsConfig(resamples=200),
                         sessions=SessionList(tmp_path).sessions, describe=lambda sid: about[sid])
        p.run([SLOW, FAST, NONE, NONE], NONE, "start")
    finally:
        server.stop()
    assert f"- #1: {esc(SLOW)} ({esc(about[SLOW])})" in p.table.content
    assert f"- #2: {esc(FAST)} ({esc(about[FAST])})" in p.table.content
