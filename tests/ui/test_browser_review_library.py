"""The Review tab's run list in headless Chromium: a search narrows the list and the Session
chooser to the runs it finds, and the run chosen opens. A screenshot goes to ``test-artifacts/``."""

from __future__ import annotations

from pathlib import Path
from typing import Iterator

import pytest
from support import Console, wait_for

pytest.importorskip("playwright.sync_api")
from browser_harness import ARTIFACTS, browser_console, gui_input, open_page  # noqa: E402
from playwright.sync_api import Browser, expect  # noqa: E402
from test_review_library import recorded  # noqa: E402

pytestmark = [pytest.mark.browser, pytest.mark.slow]


@pytest.fixture
def runs(tmp_path: Path) -> Iterator[tuple[Console, str, str]]:
    a, b = recorded(tmp_path, "calm", "calm water"), recorded(tmp_path, "weak", "weak fin 2")
    c = browser_console(tmp_path)
    yield c, a, b
    c.stop()


def test_the_review_tab_filters_the_runs_and_opens_the_one_chosen(browser: Browser,
                                                                   runs: tuple[Console, str, str]) -> None:
    console, a, b = runs
    page = open_page(browser, console.url, 1280, 800)
    page.get_by_role("tab", name="Review", exact=True).click()
    expect(page.get_by_text(a).first).to_be_visible(timeout=30_000)
    search = gui_input(page, "Search")
    search.fill("notes~weak")
    search.press("Enter")
    head = page.get_by_text("1 run match")
    expect(head).to_be_visible(timeout=30_000)
    listed = head.locator("xpath=..")  # the Runs list (the files table below lists every part)
    expect(listed).to_contain_text(b)
    expect(listed).not_to_contain_text(a)
    chooser = gui_input(page, "Session")
    expect(chooser).to_have_value(b)
    chooser.click()
    expect(page.get_by_role("option")).to_have_count(1)  # the runs found, no other
    page.get_by_role("option", name=b).click()
    page.get_by_role("button", name="Open", exact=True).click()
    review = next(iter(console.app.reviews.values()))
    wait_for(lambda: review.reviewing == b, what="the run open", timeout=30.0)
    expect(page.get_by_text("paused at")).to_be_visible(timeout=30_000)
    ARTIFACTS.mkdir(exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / "review-runs-1280x800.png"))
    page.close()
