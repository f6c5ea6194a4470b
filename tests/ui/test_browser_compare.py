"""Two recorded sessions compared in the Review tab in headless Chromium at 1280x800: chosen,
overlaid and tabled with the not-comparable flag."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

pytest.importorskip("playwright.sync_api")
from playwright.sync_api import Browser, expect  # noqa: E402
from browser_harness import ARTIFACTS, browser_console, gui_input  # noqa: E402
from support import Console, wait_for  # noqa: E402
from test_browser_console import open_page  # noqa: E402

from ucat_console.backend.access import LOCAL  # noqa: E402

sys.path.insert(0, str(Path(__file__).parents[1] / "backend" / "sessions"))
from session_helpers import record  # noqa: E402
from synthetic_run import run_items  # noqa: E402

pytestmark = [pytest.mark.browser, pytest.mark.slow]
SLOW, FAST = "20231114-221320-slow", "20231114-221500-fast"


@pytest.fixture
def console(tmp_path: Path):
    record(tmp_path, run_items(), label="slow", wall_time=1_700_000_000.0)
    record(tmp_path, run_items(scale=2.0, speed=0.25), label="fast", wall_time=1_700_000_100.0)
    c = browser_console(tmp_path)
    yield c
    c.stop()


def test_two_sessions_compared_in_the_review_tab(browser: Browser, console: Console) -> None:
    page = open_page(browser, console, 1280, 800)
    page.get_by_role("tab", name="Review", exact=True).click()
    page.get_by_text("Compare runs").click()  # the folder opens
    for k, name in ((1, SLOW), (2, FAST)):
        box = gui_input(page, f"Run {k}")
        expect(box).to_be_visible()
        box.click()
        page.get_by_role("option", name=name).click()
        expect(box).to_have_value(name)
    page.get_by_role("button", name="Compare", exact=True).click()
    expect(page.get_by_text("not comparable").first).to_be_visible(timeout=60_000)
    expect(page.get_by_text(f"#1: {SLOW}")).to_be_visible()
    table = page.locator("table", has_text="J/m").last
    expect(table).to_contain_text("32 [32, 32]")  # 8 W at 0.25 m/s
    # the table whole inside the controls' panel at 1280 px, its last column too, and every
    # figure on one line (not broken into a column of fragments)
    table.scroll_into_view_if_needed()
    fits = table.evaluate("""t => { const r = t.getBoundingClientRect(), box = t.closest('fieldset') || t.parentElement;
        const lines = [...t.querySelectorAll('td, th')].filter(c => c.innerText.trim()).map(c => {
            const g = document.createRange(); g.selectNodeContents(c);
            return [c.innerText, new Set([...g.getClientRects()].map(x => Math.round(x.top))).size]; });
        return {right: r.right, box: box.getBoundingClientRect().right, wrapped: lines.filter(l => l[1] > 1)}; }""")
    assert fits["right"] <= fits["box"] and not fits["wrapped"], fits
    expect(page.get_by_role("button", name="Download CSV")).to_be_enabled()
    for kind, suffix in (("CSV", "csv"), ("Markdown", "md"), ("PNG", "png")):  # the page offers each by name
        page.get_by_role("button", name=f"Download {kind}").click()
        expect(page.get_by_text(f"compare-{SLOW}-vs-{FAST}.{suffix}").first).to_be_visible(timeout=30_000)
    expect(page.locator("img").last).to_be_visible()
    ARTIFACTS.mkdir(exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / "compare-1280x800.png"))
    page.close()


def test_a_recording_that_ends_shows_in_the_review_and_compare_lists_by_itself(browser: Browser,
                                                                                console: Console) -> None:
    sup = console.sup
    page = open_page(browser, console, 1280, 800)
    page.get_by_role("tab", name="Review", exact=True).click()
    page.get_by_text("Compare runs").click()  # the folder opens
    expect(gui_input(page, "Run 1")).to_be_visible()
    sup.start_recording(LOCAL)
    sid = sup.recorder.session_id
    t0 = sup.loop.time
    wait_for(lambda: sup.loop.time > t0 + 1.0, what="a second recorded")
    sup.stop_recording(LOCAL)
    # no Refresh: the Review tab's chooser and the comparison's runs list it
    for label in ("Session", "Run 1"):
        box = gui_input(page, label)
        box.click()
        expect(page.get_by_role("option", name=sid)).to_be_visible(timeout=30_000)
        page.keyboard.press("Escape")
    expect(page.get_by_text("Refused")).to_have_count(0)
    page.close()
