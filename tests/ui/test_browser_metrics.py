"""The live efficiency figures in headless Chromium at 1280x800: in view without scrolling
with the power chart, each stroke's St coloured by its corridor, the power the battery's
(the simulated drives' electrical input) with the mechanical estimate below it; no St value
while the robot is disarmed or still, nor after a disarm."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Iterator

import pytest
from support import wait_for

pytest.importorskip("playwright.sync_api")
from playwright.sync_api import Browser, expect  # noqa: E402
from browser_harness import ARTIFACTS, browser_console  # noqa: E402
from support import Console  # noqa: E402
from test_browser_console import open_page  # noqa: E402

from ucat_console.backend.access import LOCAL  # noqa: E402
from ucat_console.ui.metrics_panel import IN_COLOUR, OUT_COLOUR  # noqa: E402

pytestmark = [pytest.mark.browser, pytest.mark.slow]


@pytest.fixture
def console(tmp_path: Path) -> Iterator[Console]:
    """A console whose robot swims (the shipped ``sim-tuned``): St is measured only then."""
    c = browser_console(tmp_path, base="sim-tuned")
    yield c
    c.stop()


#: whether every element the selector finds is inside the window, measured in one script
#: (the panel's elements are replaced a few times a second)
IN_VIEW = """sel => { const els = [...document.querySelectorAll(sel)];
    return els.length > 0 && els.every(e => { const r = e.getBoundingClientRect();
        return r.width > 0 && r.left >= 0 && r.top >= 0 && r.right <= innerWidth && r.bottom <= innerHeight; }); }"""


def _rgb(hex_colour: str) -> str:
    r, g, b = (int(hex_colour[i:i + 2], 16) for i in (1, 3, 5))
    return f"rgb({r}, {g}, {b})"


def test_live_figures_are_in_view_and_coloured_by_the_corridor(browser: Browser, console: Console) -> None:
    page = open_page(browser, console, 1280, 800)
    console.sup.set_setpoints(LOCAL, velocity=0.2)  # St is measured only while the robot swims
    console.sup.arm(LOCAL)
    # every fin has had two strokes
    expect(page.locator(".ucat-st.in, .ucat-st.out")).to_have_count(8, timeout=60_000)
    # the panel is re-rendered a few times a second: measure it whole, in one script
    wait_for(lambda: page.evaluate(IN_VIEW, ".ucat-metrics, .ucat-robot"), what="the figures in view")
    title = page.get_by_text("Power (W) and energy per metre (J/m)")
    box = title.bounding_box()
    assert box is not None and box["y"] + box["height"] <= 800
    wait_for(lambda: page.locator(".ucat-power").inner_text() not in ("", "–"), what="a power figure")
    used = page.locator("tr.ucat-used")
    assert used.get_attribute("data-source") == "electrical"
    assert used.inner_text().startswith("▸ electrical (battery)")
    assert "mechanical (shaft estimate)" in page.locator('tr.ucat-source[data-source="mechanical"]').inner_text()
    wait_for(lambda: page.evaluate(IN_VIEW, ".ucat-robot-power"), what="both powers in view")
    strokes = page.evaluate("""() => [...document.querySelectorAll('.ucat-st.in, .ucat-st.out')].map(e => ({
        text: e.innerText, title: e.title, cls: e.className, colour: getComputedStyle(e).backgroundColor}))""")
    assert len(strokes) == 8
    for s in strokes:
        value = float(s["text"])
        lo, hi = (float(x) for x in re.findall(r"[\d.]+", s["title"]))
        inside = lo <= value <= hi
        assert ("in" if inside else "out") in s["cls"].split()
        assert s["colour"] == _rgb(IN_COLOUR if inside else OUT_COLOUR), s
    # a mode change is marked on the charts (their legend names the marks)
    console.sup.set_mode(LOCAL, "baseline")
    expect(page.get_by_text("changes", exact=True)).to_be_visible()
    wait_for(lambda: any(e.code == "mode" for e in console.app.recent_events()), what="the mode event")
    wait_for(lambda: len(console.app.view.feeder.changes) >= 1, what="the change noted for the plots")
    ARTIFACTS.mkdir(exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / "metrics-1280x800.png"))
    page.close()


#: each fin's St tiles as the page shows them: (fin, text, class, opacity)
ST_TILES = """() => [...document.querySelectorAll('.ucat-metrics tr[data-fin]')].map(r =>
    [...r.querySelectorAll('.ucat-st')].map(e => [r.dataset.fin, e.innerText, e.className,
        Number(getComputedStyle(e).opacity)]))"""


def _no_st_shown(page) -> bool:
    """Whether every fin's St cell shows one greyed dash and no value."""
    fins = page.evaluate(ST_TILES)
    return len(fins) == 4 and all(len(t) == 1 and t[0][1] == "–" and "none" in t[0][2].split()
                                  and t[0][3] < 0.8 for t in fins)


def test_st_tiles_show_no_value_while_disarmed_or_after_a_disarm(browser: Browser, console: Console) -> None:
    page = open_page(browser, console, 1280, 800)
    sup = console.sup
    # disarmed from the start: the fins' strokes are no measurement of St
    wait_for(lambda: all(len(s) for s in console.app.metrics._data.strokes), timeout=30,
             what="every fin's strokes in the panel's figures")
    console.app.metrics._dirty = True  # rendered again from them
    wait_for(lambda: len(page.evaluate(ST_TILES)) == 4, timeout=30, what="the fins' rows")
    assert _no_st_shown(page), page.evaluate(ST_TILES)
    sup.set_setpoints(LOCAL, velocity=0.2)
    sup.arm(LOCAL)
    expect(page.locator(".ucat-st.in, .ucat-st.out")).to_have_count(8, timeout=60_000)
    sup.disarm(LOCAL, "test")
    # the last values do not stay: no measurement while disarmed
    wait_for(lambda: _no_st_shown(page), timeout=30, what="greyed dashes after the disarm")
    assert page.locator(".ucat-st.in, .ucat-st.out").count() == 0
    ARTIFACTS.mkdir(exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / "metrics-disarmed-1280x800.png"))
    page.close()
