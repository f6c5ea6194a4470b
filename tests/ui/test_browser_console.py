"""The operator's page at the pool side, in headless Chromium: the fixed status bar and DISARM
on every tab at 1280x800 and 1920x1080, the link-loss banner, keyboard and gamepad driving
(a gamepad stood in by the page's ``navigator.getGamepads``; a viewer's keys and stick doing
nothing), the theme remembered across reloads, review plots drawn
whichever plot tab was chosen first. Screenshots go to ``test-artifacts/``."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Iterator

import pytest
from support import wait_for

pytest.importorskip("playwright.sync_api")
from browser_harness import (  # noqa: E402
    ARTIFACTS,
    become_pilot,
    browser_console,
    gui_input,
    inside_viewport,
)
from browser_harness import open_page as open_url  # noqa: E402
from playwright.sync_api import Browser, Page, expect  # noqa: E402
from support import Console  # noqa: E402

from ucat_console.backend.access import LOCAL  # noqa: E402
from ucat_console.telemetry.events import Event  # noqa: E402

pytestmark = [pytest.mark.browser, pytest.mark.slow]
TABS = ("Tuning", "MPC", "Safety", "Session", "Review")


@pytest.fixture
def console(tmp_path: Path) -> Iterator[Console]:
    c = browser_console(tmp_path)
    yield c
    c.stop()


def open_page(browser: Browser, console: Console, width: int = 1280, height: int = 800, context=None) -> Page:
    return open_url(browser, console.url, width, height, context)


@pytest.mark.parametrize("size", [(1280, 800), (1920, 1080)])
def test_status_bar_armed_state_and_disarm_are_on_screen_on_every_tab(browser: Browser, console: Console,
                                                                      size: tuple[int, int]) -> None:
    page = open_page(browser, console, *size)
    become_pilot(page)
    console.sup.arm(LOCAL)
    expect(page.locator("#ucat-armed")).to_have_text("ARMED")
    expect(page.locator("#ucat-disarm")).to_be_enabled()
    close = page.get_by_role("alert").get_by_role("button")  # the software-WebGL notice
    if close.count():
        close.first.click()
    ARTIFACTS.mkdir(exist_ok=True)
    for tab in TABS:
        page.get_by_role("tab", name=tab, exact=True).click()
        expect(page.get_by_role("tab", name=tab, exact=True)).to_have_attribute("aria-selected", "true")
        for sel in ("#ucat-bar", "#ucat-armed", "#ucat-disarm"):
            assert inside_viewport(page, sel), (tab, sel)
        # mode and setpoints without scrolling
        for label in ("Mode", "Velocity m/s", "Depth m", "Yaw rate"):
            box = gui_input(page, label).bounding_box()
            assert box is not None and box["y"] + box["height"] <= size[1], (tab, label)
        page.screenshot(path=str(ARTIFACTS / f"console-{size[0]}x{size[1]}-{tab.lower()}.png"))
    lights = page.locator("#ucat-lights .light-dot")
    assert {lights.nth(i).get_attribute("data-name") for i in range(lights.count())} == \
        {"IMU", "DVL", "Depth", "Drives", "Planner", "Control", "Recording", "Vehicle"}
    page.locator("#ucat-disarm").click()  # one click
    wait_for(lambda: not console.sup.armed, what="the bar's DISARM")
    expect(page.locator("#ucat-disarm")).to_be_disabled()
    page.close()


def test_a_full_bar_keeps_the_armed_state_and_disarm_on_screen(browser: Browser, console: Console) -> None:
    """A named pilot, a recording and an active failsafe fill the bar at 1280 px: the text
    in between gives way, never the armed state or DISARM."""
    sup = console.sup
    page = open_page(browser, console, 1280, 800)
    become_pilot(page)
    name = gui_input(page, "Your name")
    name.fill("Operator on the far deck of the pool")
    name.press("Enter")
    sup.start_recording(LOCAL, "a full bar")
    sup.report_event(Event(sup.loop.time, "epos2.fin0", "emcy", "a drive fault, to fill the bar", "error", {}))
    expect(page.locator("#ucat-failsafes")).to_contain_text("motor")
    expect(page.locator("#ucat-rec")).to_contain_text("REC")
    for sel in ("#ucat-armed", "#ucat-disarm", "#ucat-theme"):
        assert inside_viewport(page, sel), sel
    page.screenshot(path=str(ARTIFACTS / "console-1280x800-full-bar.png"))
    sup.stop_recording(LOCAL)
    page.close()


def test_a_number_box_left_without_a_number_gets_its_value_back(browser: Browser, console: Console) -> None:
    sup = console.sup
    page = open_page(browser, console)
    become_pilot(page)
    page.get_by_role("tab", name="Tuning", exact=True).click()
    box = gui_input(page, "lam_st ")
    before = box.input_value()
    assert float(before) == sup.loop.mpc_config.lam_st
    box.click()
    box.press("Control+a")
    box.press("Backspace")
    box.type("abc")
    box.press("Tab")  # leave the box
    expect(box).to_have_value(before)
    assert sup.loop.mpc_config.lam_st == float(before)  # nothing changed in force
    box.fill("4.5")  # and the box still works
    box.press("Tab")
    page.get_by_role("button", name="Apply tuning").click()
    wait_for(lambda: sup.loop.mpc_config.lam_st == 4.5, what="a typed weight applied")
    page.close()


def test_keys_drive_the_pilot_and_do_nothing_for_a_viewer(browser: Browser, console: Console) -> None:
    sup = console.sup
    pilot = open_page(browser, console)
    viewer = open_page(browser, console)
    become_pilot(pilot)
    pilot.locator("#ucat-bar").click()  # focus on the page, not in a text box
    for _ in range(3):
        pilot.keyboard.press("w")
    wait_for(lambda: sup.setpoints.velocity == pytest.approx(0.15), what="three velocity steps")
    pilot.keyboard.press("e")
    wait_for(lambda: sup.setpoints.yaw_rate == pytest.approx(0.05), what="a yaw-rate step")
    viewer.locator("#ucat-bar").click()
    viewer.keyboard.press("w")
    viewer.keyboard.press(" ")
    pilot.keyboard.press("r")  # something the pilot does after the viewer's keys
    wait_for(lambda: sup.setpoints.depth == pytest.approx(0.4), what="a depth step")
    assert sup.setpoints.velocity == pytest.approx(0.15)  # the viewer's keys did nothing
    pilot.keyboard.press(" ")  # stop
    wait_for(lambda: sup.setpoints.velocity == 0.0 and sup.setpoints.yaw_rate == 0.0, what="the stop key")
    sup.arm(LOCAL)
    expect(pilot.locator("#ucat-armed")).to_have_text("ARMED")
    pilot.keyboard.press("Escape")
    wait_for(lambda: not sup.armed, what="Esc disarming")


#: a gamepad the page can poll (headless Chromium has none): ``window.__pad`` is the test's stick
FAKE_GAMEPAD = """
window.__pad = {id: "test pad", index: 0, connected: true, mapping: "standard", axes: [0, 0, 0, 0],
                buttons: Array.from({length: 16}, () => ({pressed: false, touched: false, value: 0}))};
Object.defineProperty(Navigator.prototype, "getGamepads",
                      {value: () => [window.__pad.connected ? window.__pad : null], configurable: true});
"""


#: the stick's path (the page polls its gamepad each animation frame, a software-rendered
#: Chromium on a loaded machine draws few frames): a deadline for a machine that never gets there
PAD = 60.0


def page_with_gamepad(browser: Browser, console: Console) -> tuple[Page, object]:
    ctx = browser.new_context(viewport={"width": 1280, "height": 800})
    ctx.add_init_script(FAKE_GAMEPAD)
    return open_page(browser, console, context=ctx), ctx


def wait_for_polls(page: Page, n: int = 3) -> None:
    """Until the page's script has polled its gamepad ``n`` more times."""
    start = page.evaluate("() => window.__ucat.pad.polls")
    page.wait_for_function(f"() => window.__ucat.pad.polls >= {start + n}")


def test_the_gamepad_drives_the_pilot_stops_when_lost_and_disarms(browser: Browser, console: Console) -> None:
    sup = console.sup
    lc = sup.cfg.loop
    pilot, pilot_ctx = page_with_gamepad(browser, console)
    viewer, viewer_ctx = page_with_gamepad(browser, console)
    become_pilot(pilot)
    assert pilot.evaluate("() => document.hasFocus()")
    # a viewer's stick does nothing: its page sends nothing, and the setpoints stay
    viewer.evaluate("() => { window.__pad.axes[1] = -1.0; }")
    wait_for_polls(viewer)
    assert viewer.evaluate("() => window.__ucat.pad.sent") is None
    assert sup.setpoints.velocity == 0.0
    # the pilot's stick: full forward is the envelope's velocity, half right half its yaw rate
    pilot.evaluate("() => { window.__pad.axes[1] = -1.0; window.__pad.axes[0] = 0.575; }")
    wait_for(lambda: sup.setpoints.velocity == pytest.approx(lc.max_velocity), timeout=PAD, what="stick forward")
    wait_for(lambda: sup.setpoints.yaw_rate == pytest.approx(0.5 * lc.max_yaw_rate), timeout=PAD, what="stick right")
    # within the dead zone is zero: released, the page sends zeros once
    pilot.evaluate("() => { window.__pad.axes[1] = -0.1; window.__pad.axes[0] = 0.0; }")
    wait_for(lambda: sup.setpoints.velocity == 0.0 and sup.setpoints.yaw_rate == 0.0, timeout=PAD, what="stick released")
    # the gamepad lost while pushed: driving stops (no runaway stick)
    pilot.evaluate("() => { window.__pad.axes[1] = -1.0; }")
    wait_for(lambda: sup.setpoints.velocity > 0.0, timeout=PAD, what="stick forward again")
    pilot.evaluate("() => { window.__pad.connected = false;"
                   " window.dispatchEvent(new Event('gamepaddisconnected')); }")
    wait_for(lambda: sup.setpoints.velocity == 0.0, timeout=PAD, what="driving stopped with the gamepad gone")
    assert [(e.key, e.new) for e in sup.journal(3) if e.key == "gamepad"][-1] == ("gamepad", "off")
    # button 1 (B / circle) disarms
    pilot.evaluate("() => { window.__pad.connected = true; window.__pad.axes[1] = 0.0; }")
    sup.arm(LOCAL)
    expect(pilot.locator("#ucat-armed")).to_have_text("ARMED")
    pilot.evaluate("() => { window.__pad.buttons[1].pressed = true; window.__pad.buttons[1].value = 1; }")
    wait_for(lambda: not sup.armed, timeout=PAD, what="the gamepad's disarm button")
    assert sup.setpoints.velocity == 0.0  # the viewer's stick, held forward all along, did nothing
    pilot_ctx.close()
    viewer_ctx.close()


def test_the_theme_switch_is_remembered_across_reloads(browser: Browser, console: Console) -> None:
    ctx = browser.new_context(viewport={"width": 1280, "height": 800})
    page = open_page(browser, console, context=ctx)
    expect(page.locator("#ucat-bar")).not_to_have_class(re.compile("light"))  # dark by default
    page.locator("#ucat-theme").click()
    expect(page.locator("#ucat-bar")).to_have_class(re.compile("light"))
    # the bar's state may come ahead of the console's message storing the choice: reloaded
    # once the browser holds it
    page.wait_for_function("() => Object.keys(localStorage).some(k => k.includes('ucat-theme')"
                           " && localStorage.getItem(k).includes('light'))", timeout=30_000)
    page.reload()
    page.wait_for_function("() => !document.body.innerText.includes('Connecting...')", timeout=30_000)
    # the console asks the page for its stored theme and waits up to 20 s for the answer (a
    # busy machine may take most of that): the test waits beyond it
    expect(page.locator("#ucat-bar")).to_have_class(re.compile("light"), timeout=30_000)
    page.screenshot(path=str(ARTIFACTS / "console-light.png"))
    ctx.close()


def test_the_link_loss_banner_shows_when_the_console_stops_and_goes_when_it_returns(
        browser: Browser, tmp_path: Path) -> None:
    c = browser_console(tmp_path)
    page = open_page(browser, c)
    port = c.app.port
    banner = page.locator("#ucat-banner")
    expect(banner).to_be_hidden()
    c.stop()
    expect(banner).to_be_visible()
    expect(banner).to_contain_text("LINK LOST")
    expect(banner).to_contain_text("pilot_gone")  # what the robot does meanwhile
    expect(page.locator("#ucat-info")).to_contain_text("LINK LOST")  # the bar is not live either
    expect(page.locator("#ucat-armed")).to_have_text(re.compile(r"ARMED\?$"))
    # nothing looks live or can act: the lights grey, the page's controls off
    expect(page.locator("#ucat-bar")).to_have_class(re.compile(r"\blost\b"))
    assert page.evaluate("""() => [...document.querySelectorAll('#ucat-lights .dot')].every(
        d => getComputedStyle(d).backgroundColor === 'rgb(107, 114, 128)')""")
    expect(page.get_by_role("button", name="Take control")).to_be_disabled()
    page.screenshot(path=str(ARTIFACTS / "console-link-lost.png"))
    back = browser_console(tmp_path, port=port)
    try:
        # the page reconnects by itself, says the console restarted, and its controls work again
        expect(banner).to_be_hidden(timeout=30_000)
        expect(page.locator("#ucat-notice")).to_contain_text("The console restarted")
        expect(page.locator("#ucat-bar")).not_to_have_class(re.compile(r"\blost\b"))
        expect(page.get_by_role("button", name="Take control")).to_be_enabled()
    finally:
        back.stop()


@pytest.mark.parametrize("first", ["Live plots", "Review plots"])
def test_review_plots_draw_whichever_plot_tab_was_chosen_first(browser: Browser, console: Console,
                                                               first: str) -> None:
    sup = console.sup
    sup.arm(LOCAL)
    sup.set_setpoints(LOCAL, velocity=0.2)  # the velocity line leaves its dashed target
    sup.start_recording(LOCAL, "plots")
    t0 = sup.loop.time
    wait_for(lambda: sup.loop.time >= t0 + 4.0, what="four seconds recorded")
    [path] = sup.stop_recording(LOCAL)
    sup.disarm(LOCAL)
    page = open_page(browser, console)
    page.get_by_role("tab", name=first).click()
    review = next(iter(console.app.reviews.values()))
    review.refresh_sessions()
    review.open(path.name.rsplit("_", 1)[0])
    page.get_by_role("tab", name="Review plots").click()
    review.play()
    # uPlot draws on canvases: the review depth chart's canvas gets coloured pixels
    drawn = """() => [...document.querySelectorAll('.uplot')].filter(u => u.getBoundingClientRect().width > 0)
      .some(u => { const c = u.querySelector('canvas'); if (!c || !c.width) return false;
        const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
        for (let i = 0; i < d.length; i += 4)
          if (d[i] > 110 && d[i] > 2.2 * d[i + 1] && d[i] > 2.2 * d[i + 2]) return true;
        return false; })"""
    try:
        page.wait_for_function(drawn, timeout=20_000)  # a red (velocity) line in a shown chart
    finally:
        page.screenshot(path=str(ARTIFACTS / f"console-review-plots-{first.split()[0].lower()}.png"))
    page.close()


@pytest.fixture
def patient_console(tmp_path: Path) -> Iterator[Console]:
    """A console whose pilot page is gone only after 30 s without an answer (a page slow to
    render on a loaded machine stays the pilot)."""
    c = browser_console(tmp_path, pilot_gone=30.0)
    yield c
    c.stop()


def test_the_setpoints_line_follows_what_keys_set_after_an_apply(browser: Browser, patient_console: Console) -> None:
    console = patient_console
    sup = console.sup
    page = open_page(browser, console)
    become_pilot(page)
    gui_input(page, "Velocity m/s").fill("0.1")
    page.get_by_role("button", name="Apply setpoints").click()
    expect(page.get_by_text(re.compile(r"setpoints applied: velocity 0\.1$"))).to_be_visible()
    page.locator("#ucat-bar").click()  # focus on the page, not in a text box
    for velocity in ("0.15", "0.2"):  # each key press: the line says what is in force now
        page.keyboard.press("w")
        expect(page.get_by_text(re.compile(rf"now in force: velocity = {velocity}, depth = "))).to_be_visible()
    page.keyboard.press("e")
    wait_for(lambda: sup.setpoints.yaw_rate == pytest.approx(0.05), what="a yaw-rate step")
    expect(page.get_by_text(re.compile(r"now in force: velocity = 0\.2, depth = [\d.]+, yaw_rate = 0\.05"))
           ).to_be_visible()
    assert page.get_by_text("setpoints applied").count() == 0
    page.close()


def test_revert_to_saved_asks_while_armed_and_says_what_it_did(browser: Browser, patient_console: Console) -> None:
    console = patient_console
    sup = console.sup
    saved = sup.param_value("mpc.lam_st")
    page = open_page(browser, console)
    become_pilot(page)
    page.get_by_role("tab", name="Tuning", exact=True).click()
    revert = page.get_by_role("button", name="Revert to saved")
    # disarmed: at once, and the page says what changed
    sup.set_params(LOCAL, {"mpc.lam_st": saved + 1.0})
    revert.click()
    expect(page.get_by_text(f"reverted to the saved baseline: mpc.lam_st {saved + 1.0:g} → {saved:g}").first
           ).to_be_visible()
    assert sup.param_value("mpc.lam_st") == saved
    # armed: a question first, naming the change; Cancel changes nothing
    sup.set_params(LOCAL, {"mpc.lam_st": saved + 1.0})
    sup.arm(LOCAL)
    expect(page.locator("#ucat-armed")).to_have_text("ARMED")
    revert.click()
    dialog = page.get_by_role("dialog")
    expect(dialog).to_contain_text("Revert the tuning while armed?")
    expect(dialog).to_contain_text(f"mpc.lam_st: {saved + 1.0:g} → {saved:g}")
    assert sup.param_value("mpc.lam_st") == saved + 1.0
    dialog.get_by_role("button", name="Cancel").click()
    expect(page.get_by_text("revert cancelled: the tuning in force is unchanged").first).to_be_visible()
    assert sup.param_value("mpc.lam_st") == saved + 1.0
    revert.click()
    page.get_by_role("dialog").get_by_role("button", name="Revert now").click()
    wait_for(lambda: sup.param_value("mpc.lam_st") == saved, what="the revert confirmed")
    expect(page.get_by_text(f"reverted to the saved baseline: mpc.lam_st {saved + 1.0:g} → {saved:g}").first
           ).to_be_visible()
    page.close()
