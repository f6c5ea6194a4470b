"""Screenshots of the console's page at 1280x800, one per tab, for docs/review.md.

Run: ``.venv/bin/python scripts/docs_screenshots.py [OUT_DIR]`` (default docs/images). It
starts the simulated console (the shipped sim-tuned) with two recorded sessions of its own (a few seconds of MPC, then
of the baseline), swims at 0.2 m/s with a tuning change, and photographs each tab; the Review
tab with the two sessions compared.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

from playwright.sync_api import expect, sync_playwright

from ucat_console.backend.access import LOCAL
from ucat_console.backend.supervisor import Supervisor
from ucat_console.bench.ui import CHROMIUM, CHROMIUM_ARGS
from ucat_console.config import AccessConfig, load_config
from ucat_console.ui.app import ConsoleApp

TABS = ("Tuning", "MPC", "Safety", "Session", "Review")


def main(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        shipped = load_config("sim-tuned")  # what scripts/run.sh starts
        cfg = shipped.replace(access=AccessConfig(token="docs-screenshots-token"),
                              console=shipped.console.replace(port=0, record_on_arm=False))
        sup = Supervisor(cfg, sessions_dir=tmp)
        app = ConsoleApp(sup)
        app.start()
        sup.start()
        try:
            sup.arm(LOCAL)
            sup.set_setpoints(LOCAL, velocity=0.2)
            time.sleep(30.0)  # up to speed before the recordings
            for mode in ("mpc", "baseline"):
                sup.set_mode(LOCAL, mode)
                sup.start_recording(LOCAL, notes=f"{mode} at 0.2 m/s")
                time.sleep(12.0)
                sup.stop_recording(LOCAL)
            sup.set_mode(LOCAL, "mpc")
            sup.set_params(LOCAL, {"mpc.lam_st": 2.0})
            with sync_playwright() as p:
                browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
                page = browser.new_page(viewport={"width": 1280, "height": 800})
                page.goto(app.url)
                page.wait_for_function("() => !document.body.innerText.includes('Connecting...')", timeout=60_000)
                close = page.get_by_role("alert").get_by_role("button")  # the software-WebGL notice
                if close.count():
                    close.first.click()
                time.sleep(12.0)  # the change's after-window fills in
                for tab in TABS:
                    page.get_by_role("tab", name=tab, exact=True).click()
                    if tab == "Review":
                        page.get_by_text("Compare runs").click()
                        names = [s.session_id for s in app.session_list.sessions()]
                        for k, name in enumerate(names[:2], 1):
                            label = page.locator("label", has_text=f"Run {k}").first
                            label.locator("xpath=ancestor::div[contains(@class, 'Flex-root')][1]").locator(
                                "input:not([type='hidden'])").first.click()
                            page.get_by_role("option", name=name).click()
                        page.get_by_role("button", name="Compare", exact=True).click()
                        expect(page.get_by_text("compared 2 runs")).to_be_visible(timeout=60_000)
                        page.get_by_role("button", name="Compare", exact=True).scroll_into_view_if_needed()
                    time.sleep(1.0)
                    page.screenshot(path=str(out / f"console-{tab.lower()}-1280x800.png"))
                browser.close()
        finally:
            sup.stop()
            app.stop()


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parents[1] / "docs" / "images")
