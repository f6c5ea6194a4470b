"""The Review tab's Trends folder from a raw websocket page: a choice among the page's options
draws the figure of the runs found (the intervals with it), and any other value a raw client
sends for the figure or the axis is refused with a message naming it while the choice in force,
the dropdowns and the chart stay as they were. The run table's pages, from its own function."""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pytest
from support import Console, console_config, wait_for

sys.path.insert(0, str(Path(__file__).parents[1] / "backend" / "sessions"))
from test_library import _folder  # noqa: E402
from test_review_library import SETTINGS, Review  # noqa: E402

from ucat_console.backend.review import trend  # noqa: E402
from ucat_console.ui import run_list  # noqa: E402
from ucat_console.ui.markdown import esc  # noqa: E402


def _data(chart: Any) -> tuple[np.ndarray, ...]:
    return tuple(np.asarray(a) for a in chart._impl.props.data)


def test_a_trend_choice_draws_the_runs_found_and_a_raw_clients_other_value_changes_nothing(
        make_console: Callable[..., Console], tmp_path: Path) -> None:
    ids = _folder(tmp_path)
    review = Review(make_console(console_config(**SETTINGS), serve=True))
    panel = review.runs.trend
    assert panel is not None
    wait_for(lambda: set(review.options()) == set(ids.values()), what="the four runs listed")

    review.send(panel.axis, "loop.mpc.lam_st")
    wait_for(lambda: panel.chosen == ("epm", "loop.mpc.lam_st") and panel.drawn, what="the trend drawn")
    x, value, lo, hi, mean = _data(panel.by_value)
    assert list(x) == [0.5, 2.0, 2.0]  # slow (closed_stroke, lam_st 0.5); fast and plain (2.0)
    assert value[0] == pytest.approx(40.0, rel=1e-5)  # 4 W at 0.1 m/s
    assert np.all(np.isfinite(lo)) and np.all(lo <= value) and np.all(value <= hi)  # the intervals drawn
    assert mean[1] == mean[2] == pytest.approx((20.0 + 4.0 / 0.15) / 2, rel=1e-5)
    assert panel.by_value.visible and not panel.by_date.visible
    uuid = review.uuid(panel.by_value)
    wait_for(lambda: review.page.element(uuid).get("title") == "energy per metre (J/m) by loop.mpc.lam_st",
             what="the page's chart titled with the choice")
    assert "3 runs of every run" in panel.about.content and "2 groups" in panel.about.content

    # the search narrows the runs: the trend follows it
    review.send(review.runs.search, "mode=baseline")
    # the chart's data is set before the text about it: wait for both
    wait_for(lambda: len(_data(panel.by_value)[0]) == 2 and esc("mode=baseline") in panel.about.content,
             what="the trend of the runs found, and its text")

    before = _data(panel.by_value)
    guard = review.console.app.guard
    for handle, sent in ((panel.axis, "plant.hydro.c_d0"), (panel.figure, "password"), (panel.figure, 3)):
        seen = len(guard.refusals)
        review.send(handle, sent)  # the page's guard refuses a value not among the options
        wait_for(lambda: any(c == review.cid and ("not one of the options" in why or "expected one of" in why)
                             for c, why in list(guard.refusals)[seen:]), what=f"{sent!r} refused")
        u = review.uuid(handle)
        wait_for(lambda: review.page.element(u).get("value") == handle.value,
                 what="the page showing the value in force")
        assert (panel.figure.value, panel.axis.value) == (trend.FIGURES["epm"], "loop.mpc.lam_st")
    # past the guard (an option it would let through), the panel's own check refuses by name
    for figure, by, words in (("password", "date", "trend figure 'password'"),
                              ("epm_lo", "date", "trend figure 'epm_lo'"),
                              (trend.FIGURES["cot"], "plant.hydro.c_d0", "trend axis 'plant.hydro.c_d0'")):
        assert not review.panel.act(lambda: panel.draw(figure, by))
        assert words in review.panel.messages[-1] and "not one of" in review.panel.messages[-1]
        assert panel.chosen == ("epm", "loop.mpc.lam_st")
        assert (panel.figure.value, panel.axis.value) == (trend.FIGURES["epm"], "loop.mpc.lam_st")
    assert all(np.array_equal(a, b, equal_nan=True) for a, b in zip(before, _data(panel.by_value)))

    # a figure by date: the time axis chart
    review.send(panel.figure, trend.FIGURES["speed_mae"])
    wait_for(lambda: panel.chosen == ("speed_mae", "loop.mpc.lam_st"), what="the figure changed")
    review.send(panel.axis, "date")
    wait_for(lambda: panel.chosen == ("speed_mae", "date") and panel.by_date.visible
             and "no interval for this figure" in panel.about.content, what="by date, and its text")
    x, value, lo, hi, _ = _data(panel.by_date)
    assert len(x) == 2 and np.all(np.diff(x) > 0) and np.all(np.isnan(lo)) and np.all(np.isnan(hi))


@dataclass(frozen=True)
class _Row:
    id: str
    status: str = "ok"
    start: float | None = 1.8e9
    duration: float | None = 60.0
    modes: tuple[str, ...] = ("mpc",)
    config: str = "sim-tuned"
    config_hash: str = ""
    manoeuvre: str = ""
    tags: tuple[str, ...] = ()
    notes: str = ""
    figures: dict | None = None


@dataclass(frozen=True)
class _View:
    row: Any

    @property
    def id(self) -> str:
        return self.row.id

    def weights_text(self) -> str:
        return "lam_st=2"


def test_the_table_shows_one_page_of_runs_and_says_which() -> None:
    views = [_View(_Row(f"run-{k:02d}", figures={"epm": 20.0 + k, "epm_lo": 19.0, "epm_hi": 30.0},
                        tags=("pool-3",), notes="a | b\nc")) for k in range(45)]
    first = run_list.runs_markdown(views, "", 0, "epm", True).splitlines()
    rows = [line for line in first if line.startswith("| **run-")]
    assert len(rows) == run_list.PAGE_ROWS == 20 and rows[0].startswith("| **run-00** |")
    assert "runs 1–20 of 45 (page 1 of 3" in first[0]
    assert "| J/m [lo, hi] ▼ |" in first[2] and "▲" not in first[2]  # the column sorted by, its direction
    assert "| 20.0 \\[19.0, 30.0\\] |" in rows[0] and "| a \\| b c |" in rows[0]  # one line, its | escaped
    last = run_list.runs_markdown(views, "mode=mpc", 7, "start", False).splitlines()  # past the end: the last
    rows = [line for line in last if line.startswith("| **run-")]
    assert [r.split(" |")[0] for r in rows] == [f"| **run-{k}**" for k in range(40, 45)]
    assert last[0].startswith("45 runs match mode=mpc: runs 41–45 of 45 (page 3 of 3")
    assert "start (UTC) ▲" in last[2]
    assert run_list.runs_markdown([], "x") == "No run matches."
