"""The pilot's page on slow links and across restarts of the console, in headless Chromium:
through a link that delays every chunk (``delay_proxy.py``) the page connects and its pilot
takes control; DISARM goes through; and after each restart of the console (same port, the
machine's cores kept busy) the page comes back by itself and presents its kept token again."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Iterator

import pytest
from support import Console, console_config, wait_for

playwright_api = pytest.importorskip("playwright.sync_api")
from browser_harness import ARTIFACTS, TOKEN, browser_console, take_control  # noqa: E402
from ucat_console.bench.delay_proxy import DelayProxy  # noqa: E402
from playwright.sync_api import Browser, Page, expect  # noqa: E402

from ucat_console.backend.access import LOCAL  # noqa: E402
from ucat_console.ui.page_script import TOKEN_KEY  # noqa: E402

pytestmark = [pytest.mark.browser, pytest.mark.slow]

#: how long a page on a slow link or a restarted console may take (a deadline, not a figure)
SLOW = 60_000


#: the page's window has the focus, as the operator's has (a headless page has none): viser's
#: client retried its socket only while focused, closing the one still opening each second
FOCUSED = """
document.hasFocus = () => true;
setInterval(() => window.dispatchEvent(new Event("focus")), 500);
"""


def open_slow(browser: Browser, url: str) -> Page:
    """A page on ``url`` at 1280x800 whose window has the focus, connected (its status bar shown)."""
    page = browser.new_page(viewport={"width": 1280, "height": 800})
    page.add_init_script(FOCUSED)
    page.goto(url, timeout=SLOW)
    expect(page.locator("#ucat-armed")).to_be_visible(timeout=SLOW)
    return page


def become_pilot(page: Page) -> None:
    """Take control, and wait until the page keeps its token (the bar's state saying it flies
    may come after the panel's text: a console stopped before it would find no token to present)."""
    take_control(page)
    expect(page.get_by_text("You are the pilot")).to_be_visible(timeout=SLOW)
    wait_for(lambda: kept_token(page) == TOKEN, timeout=SLOW / 1000, what="the token kept")


def pilot_then_console_gone(browser: Browser, tmp_path: Path) -> tuple[Page, int]:
    """The pilot's page (its token kept) on a console that has stopped under it, the page
    showing its link lost; and the port the console served on."""
    c = browser_console(tmp_path)
    port = c.app.port
    page = open_slow(browser, c.url)
    become_pilot(page)
    c.stop()
    expect(page.locator("#ucat-banner")).to_be_visible(timeout=SLOW)
    return page, port


def kept_token(page: Page) -> Any:
    return page.evaluate(f"() => sessionStorage.getItem({TOKEN_KEY!r})")


@pytest.fixture
def spinners() -> Iterator[None]:
    """Two processes spinning (the machine's cores busy)."""
    procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    yield
    for p in procs:
        p.kill()
        p.wait()


@pytest.mark.parametrize("delay", [0.3, 0.6, 1.0])
def test_the_page_connects_and_takes_control_through_a_slow_link(browser: Browser, tmp_path: Path,
                                                                 delay: float) -> None:
    c = browser_console(tmp_path)
    proxy = DelayProxy(c.app.port, delay)
    try:
        page = open_slow(browser, proxy.url)
        become_pilot(page)  # its token kept in the tab's sessionStorage for a reconnect
        assert c.sup.access.pilot is not None
        assert TOKEN not in page.url
        page.close()
    finally:
        proxy.close()
        c.stop()


def test_disarm_through_a_slow_link_is_applied(browser: Browser, tmp_path: Path) -> None:
    c = browser_console(tmp_path)
    proxy = DelayProxy(c.app.port, 0.6)
    try:
        page = open_slow(browser, proxy.url)
        become_pilot(page)
        c.sup.arm(LOCAL)
        expect(page.locator("#ucat-disarm")).to_be_enabled(timeout=SLOW)
        page.locator("#ucat-disarm").click()
        wait_for(lambda: not c.sup.armed, timeout=30.0, what="DISARM through the slow link")
        page.close()
    finally:
        proxy.close()
        c.stop()


def test_the_pilot_page_comes_back_as_pilot_after_every_restart(browser: Browser, tmp_path: Path,
                                                                spinners: None) -> None:
    c = browser_console(tmp_path)
    port = c.app.port
    page = open_slow(browser, c.url)
    become_pilot(page)
    times = []
    try:
        for _ in range(10):
            c.stop()
            expect(page.locator("#ucat-banner")).to_be_visible(timeout=SLOW)
            t0 = time.monotonic()
            c = browser_console(tmp_path, port=port)
            wait_for(lambda: c.sup.access.pilot is not None, timeout=60.0, what="the page back as pilot")
            times.append(time.monotonic() - t0)
            expect(page.get_by_text("You are the pilot")).to_be_visible(timeout=SLOW)
        page.screenshot(path=str(ARTIFACTS / "console-back-after-restarts.png"))
    finally:
        c.stop()
        print("back as pilot after each restart (s):", [round(t, 1) for t in times])


def test_a_kept_token_is_checked_again_and_forgotten_when_it_fails(browser: Browser, tmp_path: Path) -> None:
    page, port = pilot_then_console_gone(browser, tmp_path)
    cfg = console_config("another-token", None, scene_rate=15.0, plot_rate=5.0, port=port)
    c = Console(cfg, tmp_path, serve=True)
    try:
        # the kept token is presented again and refused as any wrong token: counted by the access rules
        wait_for(lambda: c.sup.access._page_failures and any(f.times for f in c.sup.access._page_failures.values()),
                 timeout=60.0, what="the kept token checked by the server")
        assert c.sup.access.pilot is None
        wait_for(lambda: kept_token(page) is None, timeout=60.0, what="the refused token forgotten")
    finally:
        c.stop()


def test_a_page_back_while_another_flies_does_not_ask_and_forgets_its_token(browser: Browser,
                                                                            tmp_path: Path) -> None:
    c = browser_console(tmp_path, pilot_gone=2.0)
    proxy = DelayProxy(c.app.port, 0.0)
    try:
        first = open_slow(browser, proxy.url)
        become_pilot(first)
        port = proxy.port
        proxy.close()  # the first page's link is lost: it is gone, and nobody flies
        wait_for(lambda: c.sup.access.pilot is None, timeout=30.0, what="the first page gone")
        second = open_slow(browser, c.url)
        become_pilot(second)
        pilot = c.sup.access.pilot
        proxy = DelayProxy(c.app.port, 0.0, port=port)  # the first page's link is back
        expect(first.locator("#ucat-banner")).to_be_hidden(timeout=SLOW)
        # it is a viewer now: it forgets the token and does not ask the pilot for control
        wait_for(lambda: kept_token(first) is None, timeout=30.0, what="the token forgotten")
        assert c.sup.access.pilot == pilot and c.sup.access.pending is None
    finally:
        proxy.close()
        c.stop()


def test_the_pilot_page_keeps_its_token_through_the_loading_page_of_a_restart(browser: Browser,
                                                                           tmp_path: Path) -> None:
    # `ucat-console run` serves its loading page while it prepares the compiled code: the page
    # that flew comes back to it first (nobody can fly yet), and to the console on the same socket
    from ucat_console.backend.supervisor import Supervisor
    from ucat_console.ui.app import ConsoleApp
    from ucat_console.ui.loading import LoadingPage

    page, port = pilot_then_console_gone(browser, tmp_path)
    cfg = console_config(TOKEN, None, scene_rate=15.0, plot_rate=5.0, port=port)
    loading = LoadingPage(cfg, cfg.console.host, port)
    sup = app = None
    try:
        wait_for(lambda: str(page.evaluate("() => window.__ucat.state.pilot")).startswith("none (the console is"),
                 timeout=60.0, what="the page on the loading page")
        expect(page.locator("#ucat-banner")).to_be_hidden(timeout=SLOW)
        assert kept_token(page) == TOKEN
        sup = Supervisor(cfg, sessions_dir=tmp_path)
        app = ConsoleApp(sup, loading_page=loading)
        app.start()
        sup.start()
        wait_for(lambda: sup.access.pilot is not None, timeout=60.0, what="the page back as pilot")
        expect(page.get_by_text("You are the pilot")).to_be_visible(timeout=SLOW)
    finally:
        if sup is not None:
            sup.stop()
        if app is not None:
            app.stop()
        else:
            loading.stop()
