"""The status bar at 1280x800 while armed and recording, in headless Chromium: the armed
state, the link, every light and DISARM are whole on screen (nothing of them clipped)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

pytest.importorskip("playwright.sync_api")
from browser_harness import ARTIFACTS, become_pilot, browser_console, open_page  # noqa: E402
from playwright.sync_api import Browser, expect  # noqa: E402

from ucat_console.backend.access import LOCAL  # noqa: E402

pytestmark = [pytest.mark.browser, pytest.mark.slow]

#: for each element: whether its text is cut (its content wider than its box) or it reaches
#: past the window's right edge
CLIPPED = """ids => ids.map(id => { const e = document.getElementById(id); const r = e.getBoundingClientRect();
    return [id, e.scrollWidth > e.clientWidth + 1 || r.right > innerWidth || r.width === 0]; })"""


def test_the_bar_keeps_the_armed_state_link_lights_and_disarm_whole_at_1280(browser: Browser,
                                                                             tmp_path: Path) -> None:
    console = browser_console(tmp_path)
    try:
        page = open_page(browser, console.url, 1280, 800)
        become_pilot(page)
        console.sup.arm(LOCAL)
        console.sup.start_recording(LOCAL)
        expect(page.locator("#ucat-armed")).to_have_text("ARMED")
        expect(page.locator("#ucat-rec")).to_contain_text("REC")
        expect(page.locator("#ucat-lights")).to_contain_text("Recording")
        clipped = dict(page.evaluate(CLIPPED, ["ucat-armed", "ucat-link", "ucat-rec", "ucat-lights", "ucat-disarm"]))
        page.screenshot(path=str(ARTIFACTS / "bar-recording-1280x800.png"), clip={"x": 0, "y": 0, "width": 1280, "height": 46})
        assert not any(clipped.values()), clipped
    finally:
        console.stop()


def test_a_viewer_page_shows_the_viewer_badge_and_its_greyed_disarm_says_only_the_pilot_disarms(
        browser: Browser, tmp_path: Path) -> None:
    console = browser_console(tmp_path, pilot_gone=30.0)  # a pilot page slow to answer on a loaded machine
    try:
        pilot = open_page(browser, console.url, 1280, 800)
        become_pilot(pilot)
        console.sup.arm(LOCAL)
        viewer = open_page(browser, console.url, 1280, 800)
        expect(viewer.locator("#ucat-armed")).to_have_text("ARMED")
        badge = viewer.locator("#ucat-viewer")
        expect(badge).to_be_visible()
        expect(badge).to_have_text("VIEWER")
        disarm = viewer.locator("#ucat-disarm")
        expect(disarm).to_be_disabled()
        expect(disarm).to_have_attribute("title", re.compile("^only the pilot can disarm"))
        assert not dict(viewer.evaluate(CLIPPED, ["ucat-armed", "ucat-viewer", "ucat-disarm"]))["ucat-viewer"]
        viewer.screenshot(path=str(ARTIFACTS / "bar-viewer-1280x800.png"), clip={"x": 0, "y": 0, "width": 1280, "height": 46})
        # the pilot's own page has no badge, and its DISARM acts
        expect(pilot.locator("#ucat-armed")).to_have_text("ARMED")
        expect(pilot.locator("#ucat-viewer")).to_be_hidden()
        expect(pilot.locator("#ucat-disarm")).to_have_attribute("title", "motors off now (key: Esc)")
        pilot.close()
        viewer.close()
    finally:
        console.stop()


def test_the_bar_shows_the_cost_formulation_beside_an_mpc_mode_as_the_readme_names_it(
        browser: Browser, tmp_path: Path) -> None:
    from ucat_console.ui.status_bar import FORMULATIONS

    console = browser_console(tmp_path)
    sup = console.sup
    try:
        page = open_page(browser, console.url, 1280, 800)
        info = page.locator("#ucat-info")
        sup.set_mode(LOCAL, "mpc")
        expect(info).to_contain_text("mode MPC · paper's cost")
        sup.set_params(LOCAL, {"mpc.formulation": "closed_stroke"})
        expect(info).to_contain_text("mode MPC · closed-stroke cost")
        page.screenshot(path=str(ARTIFACTS / "bar-formulation-1280x800.png"),
                        clip={"x": 0, "y": 0, "width": 1280, "height": 46})
        sup.set_mode(LOCAL, "baseline")  # no MPC: no cost beside the mode
        expect(info).to_contain_text("mode baseline  ·")
        expect(info).not_to_contain_text("cost")
        page.close()
    finally:
        console.stop()
    # the README's tracking table names each controller as the bar shows it
    readme = (Path(__file__).parents[2] / "README.md").read_text()
    rows = [line.split("|")[1].strip() for line in readme.splitlines()
            if line.startswith("| ") and "16 / 16" in line]
    assert rows == ["baseline", f"MPC · {FORMULATIONS['paper']}", f"MPC sync · {FORMULATIONS['paper']}",
                    f"MPC · {FORMULATIONS['closed_stroke']}"], rows
