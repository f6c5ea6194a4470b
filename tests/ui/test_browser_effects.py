"""A tuning change's measured effect on the page, in headless Chromium at 1280x800: the
Tuning tab's entry shows the figures of the window before the change at once, says when the
window after it completes, and fills in the after-figures then (the supervisor's own
figures, as the session records them)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from support import Console, console_config, wait_for

pytest.importorskip("playwright.sync_api")
from browser_harness import ARTIFACTS, TOKEN, become_pilot, open_page  # noqa: E402
from playwright.sync_api import Browser, expect  # noqa: E402

from ucat_console.backend.access import LOCAL  # noqa: E402

pytestmark = [pytest.mark.browser, pytest.mark.slow]

#: the windows before and after a change (s): short, so that the test waits seconds
WINDOW = 4.0


def test_a_tuning_changes_effect_fills_in_on_the_page(browser: Browser, tmp_path: Path) -> None:
    cfg = console_config(TOKEN, None, "sim-tuned", scene_rate=15.0, plot_rate=5.0)  # a robot that swims
    cfg = cfg.replace(metrics=cfg.metrics.replace(before=WINDOW, after=WINDOW))
    console = Console(cfg, tmp_path, serve=True)
    try:
        sup = console.sup
        page = open_page(browser, console.url)
        become_pilot(page)
        sup.arm(LOCAL)
        sup.set_setpoints(LOCAL, velocity=0.2)
        t0 = sup.loop.time
        wait_for(lambda: sup.loop.time >= t0 + 2.0 * WINDOW, timeout=120.0, what="a before-window of swimming")
        sup.set_params(LOCAL, {"mpc.lam_st": 2.5})
        entry = wait_for(lambda: next((e for e in sup.effects.entries() if "lam_st" in e.message and e.before),
                                      None), what="the change's entry with its before-figures")
        before = entry.before["power"]
        assert before is not None and before > 0.0  # the robot swam: it used power
        effects = page.locator("text=Measured effects").locator("xpath=ancestor::div[1]")
        # at once: the before-figure, the after-window still to come
        expect(effects).to_contain_text(f"{before:.2f} → … W")
        expect(effects).to_contain_text("after-window fills in")
        # when the after-window has passed: the after-figure, as the supervisor measured it
        done = wait_for(lambda: next((e for e in sup.effects.entries()
                                      if e.t == entry.t and e.after is not None), None),
                        timeout=120.0, what="the after-window completed")
        after = done.after["power"]
        assert after is not None and after > 0.0
        expect(effects).to_contain_text(f"{before:.2f} → {after:.2f} W", timeout=30_000)
        expect(effects).not_to_contain_text(re.compile(r"lam_st[^\n]*after-window fills in"))
        page.screenshot(path=str(ARTIFACTS / "effects-1280x800.png"))
    finally:
        console.stop()
