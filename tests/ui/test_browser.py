"""End to end in headless Chromium: the live page, the pilot, a viewer, hand-over, failsafe.

One console (supervisor on the simulated robot in real time, web page on a free loopback
port) serves the whole module; the tests run in order and share it. A screenshot of the
live page is saved under ``test-artifacts/``.
"""

from __future__ import annotations

import re
import zipfile
from typing import Iterator

import pytest
from support import Console, wait_for

playwright_api = pytest.importorskip("playwright.sync_api")
from browser_harness import ARTIFACTS, browser_console, gui_input, take_control  # noqa: E402
from browser_harness import open_page as open_url  # noqa: E402
from playwright.sync_api import Browser, Page, expect  # noqa: E402

pytestmark = [pytest.mark.browser, pytest.mark.slow]

PILOT_GONE_TIMEOUT = 4.0  # the pilot page's allowed silence: a busy machine slows its answers


@pytest.fixture(scope="module")
def console(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Console]:
    c = browser_console(tmp_path_factory.mktemp("sessions"), PILOT_GONE_TIMEOUT)
    yield c
    c.stop()


PAGES: dict[str, tuple[Page, int]] = {}


def open_page(browser: Browser, console: Console, width: int = 1400, height: int = 900) -> tuple[Page, int]:
    """A page on the console and the client id the console gave it."""
    before = set(console.sup.access.clients)
    page = open_url(browser, console.url, width, height)
    wait_for(lambda: set(console.sup.access.clients) - before, what="the page's connection")
    (cid,) = set(console.sup.access.clients) - before
    expect(page.get_by_role("button", name="Take control")).to_be_visible()
    return page, cid


def test_the_page_loads_and_shows_the_robot(browser: Browser, console: Console) -> None:
    page, cid = open_page(browser, console)
    PAGES["a"] = (page, cid)
    page.wait_for_function(
        "() => { const t = window.__viserSceneTree; return t && t.getState()['/ned/ucat/hull'] !== undefined; }",
        timeout=15_000,
    )
    for name in ("/ned/ucat/blades", "/ned/ucat/ghosts", "/ned/ucat/heading", "/surface",
                 "/floor", "/ned/trail"):
        assert page.evaluate(f"() => window.__viserSceneTree.getState()['{name}'] !== undefined"), name
    expect(page.get_by_text("St per fin 0-3")).to_be_visible()
    # the power chart names the power it draws: the simulated drives report the battery's
    expect(page.get_by_text("Power (W) and energy per metre (J/m): electrical (battery)")).to_be_visible()
    wait_for(lambda: page.locator(".uplot").count() >= 5, what="five plots")
    expect(page.get_by_text("disarmed", exact=False).first).to_be_visible()
    t0 = console.sup.loop.time
    wait_for(lambda: console.sup.loop.time >= t0 + 2.5, what="a few seconds of plot history")
    close = page.get_by_role("alert").get_by_role("button")  # the software-WebGL notice
    if close.count():
        close.first.click()
        expect(close.first).to_be_hidden()
    ARTIFACTS.mkdir(exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / "console-live.png"))


def test_the_pilot_arms_switches_mode_and_tunes(console: Console) -> None:
    page, cid = PAGES["a"]
    sup = console.sup
    take_control(page)
    expect(page.get_by_text("You are the pilot")).to_be_visible()
    assert sup.access.pilot == cid
    page.get_by_role("button", name="Arm motors").click()
    confirm = page.get_by_role("button", name="Confirm arm")
    expect(confirm).to_be_visible()
    assert not sup.armed  # asking is not arming
    confirm.click()
    wait_for(lambda: sup.armed, what="arming")
    gui_input(page, "Mode").click()
    page.get_by_role("option", name="baseline").click()
    wait_for(lambda: sup.loop.mode == "baseline", what="the loop's mode")
    gui_input(page, "lam_st [").fill("2.5")
    page.get_by_role("button", name="Apply tuning").click()
    wait_for(lambda: sup.loop.mpc_config.lam_st == 2.5, what="lam_st in the loop")
    assert sup.journal()[-1].key == "mpc.lam_st" and sup.journal()[-1].who == f"client {cid}"


def test_a_second_page_cannot_arm_or_tune(browser: Browser, console: Console) -> None:
    page, cid = open_page(browser, console, 1100, 800)
    PAGES["b"] = (page, cid)
    expect(page.get_by_text("Read-only")).to_be_visible()
    for name in ("Arm motors", "DISARM", "Apply tuning", "Apply setpoints"):
        expect(page.get_by_role("button", name=name)).to_be_disabled()
    expect(gui_input(page, "lam_st [")).to_be_disabled()
    expect(gui_input(page, "lam_st [")).to_have_value("2.5")  # it sees the pilot's change
    assert console.sup.access.pilot == PAGES["a"][1]


def test_an_out_of_range_value_typed_in_the_page_is_refused(console: Console) -> None:
    page, _ = PAGES["a"]
    box = gui_input(page, "lam_st [")
    box.fill("500")
    page.get_by_role("button", name="Apply tuning").click()
    expect(page.get_by_text("out of range").first).to_be_visible()
    expect(box).to_have_value("2.5")
    assert console.sup.tuning()["mpc"].lam_st == 2.5
    assert console.sup.loop.mpc_config.lam_st == 2.5  # refused before anything reached the loop


def test_the_token_hands_control_over(console: Console) -> None:
    (a, a_id), (b, b_id) = PAGES["a"], PAGES["b"]
    take_control(b)
    expect(b.get_by_text("Waiting for the pilot's hand-over")).to_be_visible()
    assert console.sup.access.pilot == a_id
    handover = a.get_by_role("button", name=f"Hand over to client {b_id}")
    expect(handover).to_be_visible()
    handover.click()
    wait_for(lambda: console.sup.access.pilot == b_id, what="the hand-over")
    expect(b.get_by_text("You are the pilot")).to_be_visible()
    expect(a.get_by_role("button", name="DISARM")).to_be_disabled()
    expect(b.get_by_role("button", name="DISARM")).to_be_enabled()


def test_closing_the_pilot_page_triggers_the_failsafe(console: Console) -> None:
    (a, _), (b, b_id) = PAGES["a"], PAGES["b"]
    sup = console.sup
    assert sup.access.pilot == b_id and sup.armed
    b.close()
    fired = wait_for(lambda: next((e for e in console.events
                                   if e.source == "failsafe" and e.code == "pilot_gone"), None),
                     timeout=PILOT_GONE_TIMEOUT + 5.0, what="the pilot_gone failsafe event")
    assert "pilot_gone" in sup.safety.active()
    left = next(e for e in console.events if e.source == "access" and e.code == "pilot_left")
    assert fired.t - left.t >= PILOT_GONE_TIMEOUT - sup.cfg.console.supervise_period
    assert fired.data["action"] == "hold"
    assert sup.setpoints.velocity == 0.0 and sup.setpoints.yaw_rate == 0.0
    expect(a.locator("#ucat-failsafes")).to_contain_text("FAILSAFE pilot_gone")  # in the fixed status bar
    a.screenshot(path=str(ARTIFACTS / "console-failsafe.png"))


def test_a_recorded_session_is_reviewed_in_the_page(console: Console) -> None:
    from ucat_console.backend.access import LOCAL

    a, a_id = PAGES["a"]
    sup = console.sup
    sup.start_recording(LOCAL, "browser review")
    t0 = sup.loop.time
    wait_for(lambda: sup.loop.time >= t0 + 2.0, what="two seconds recorded")
    [path] = sup.stop_recording(LOCAL)
    panel = console.app.reviews[a_id]  # this page's own review
    panel.refresh_sessions()
    a.get_by_role("tab", name="Review", exact=True).click()
    expect(a.get_by_text("browser review").first).to_be_visible()  # listed, with notes
    session_id = path.name.rsplit("_", 1)[0]  # <session id>_001.mcap
    assert session_id in panel.choice.options  # the chooser lists sessions, not part files
    panel.choice.value = session_id
    a.get_by_role("button", name="Open", exact=True).click()
    wait_for(lambda: panel.player is not None, what="the session opening")
    expect(a.get_by_text(f"opened {session_id}").first).to_be_visible()
    a.wait_for_function(  # the review vehicle is drawn by the live scene code
        "() => window.__viserSceneTree.getState()['/review/ucat/hull'] !== undefined", timeout=15_000
    )
    start = panel.player.position
    a.get_by_role("button", name="Play").click()
    wait_for(lambda: panel.player.position > start + 0.3, what="playback advancing")
    a.get_by_role("button", name="Pause").click()
    box = gui_input(a, "Speed [")
    box.fill("9")
    box.press("Enter")
    expect(a.get_by_text(re.compile(r"speed: 9(\.0)? is out of range")).first).to_be_visible()
    wait_for(lambda: panel.player.speed == 1.0, what="the speed left unchanged")
    expect(a.locator("#ucat-review")).to_have_text(f"REVIEW {session_id}")  # the status bar says so
    a.screenshot(path=str(ARTIFACTS / "console-review.png"))
    with a.expect_download() as got:  # the shown window of the session, as CSV files
        a.get_by_role("button", name="Export CSV").click()
    download = got.value
    assert download.suggested_filename.startswith(session_id) and download.suggested_filename.endswith(".zip")
    with zipfile.ZipFile(download.path()) as z:
        assert any(n.endswith("/body_state.csv") for n in z.namelist())
    a.get_by_role("button", name="Close", exact=True).click()
    wait_for(lambda: panel.player is None, what="the session closing")
    expect(a.locator("#ucat-review")).to_be_hidden()
