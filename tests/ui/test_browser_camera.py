"""The 3-D view in headless Chromium at 1280x800: the robot in view on the first load, after
a seek of the review far along the recorded path (the camera follows it), and after *Frame
the robot* once the operator turned the camera away. "In view" is what the page draws: the
hull's yellow in the middle of the 3-D view (its background and grid are grey, the water
surface blue)."""

from __future__ import annotations

import io
import sys
from pathlib import Path
from typing import Iterator

import numpy as np
import pytest
from support import wait_for

pytest.importorskip("playwright.sync_api")
from playwright.sync_api import Browser, Page, expect  # noqa: E402
from browser_harness import ARTIFACTS, browser_console, open_page  # noqa: E402
from support import Console  # noqa: E402

sys.path.insert(0, str(Path(__file__).parents[1] / "backend" / "sessions"))
from session_helpers import record  # noqa: E402
from synthetic_run import run_items  # noqa: E402

pytestmark = [pytest.mark.browser, pytest.mark.slow]
SESSION = "20231114-221320-long"
#: the middle of the 3-D view at 1280x800 (between the docked panels, below the bar; clear of
#: the axes' gizmo in its lower left corner and of notifications at its top)
MIDDLE = {"x": 480, "y": 220, "width": 360, "height": 440}


@pytest.fixture
def console(tmp_path: Path) -> Iterator[Console]:
    record(tmp_path, run_items(duration=40.0, speed=0.5), label="long", wall_time=1_700_000_000.0)  # 20 m along x
    c = browser_console(tmp_path)
    yield c
    c.stop()


def robot_drawn(page: Page) -> int:
    """The pixels of the hull's yellow (``look.HULL_COLOUR``, lit or shaded) in the middle of the 3-D view."""
    from PIL import Image

    img = np.asarray(Image.open(io.BytesIO(page.screenshot(clip=MIDDLE))).convert("RGB")).astype(int)
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    return int(((r > 120) & (g > 0.6 * r) & (g < r) & (b < 0.4 * g)).sum())


def test_the_robot_is_in_view_on_first_load_after_a_seek_and_when_framed(browser: Browser, console: Console) -> None:
    page = open_page(browser, console.url, 1280, 800)
    close = page.get_by_role("alert").get_by_role("button")  # the software-WebGL notice
    if close.count():
        close.first.click()
    wait_for(lambda: robot_drawn(page) > 300, timeout=60, what="the live robot drawn on the first load")
    cid = next(iter(console.app.pages))
    review = console.app.reviews[cid]
    review.act(lambda: review.open(SESSION))
    wait_for(lambda: review.player is not None, timeout=30, what="the session open")
    review.act(lambda: review.seek(38.0))  # 19 m from the start
    wait_for(lambda: review.view.scene is not None and (review.view.scene.world_position() or (0,))[0] > 15.0,
             timeout=30, what="the reviewed robot at the seek")
    wait_for(lambda: robot_drawn(page) > 300, timeout=60, what="the reviewed robot drawn after the seek")
    ARTIFACTS.mkdir(exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / "camera-after-seek-1280x800.png"))
    # the operator looks elsewhere (following off), then frames the robot with the button
    page.get_by_role("tab", name="Session", exact=True).click()
    page.get_by_label("Follow the robot").uncheck()
    wait_for(lambda: not console.app.panels[cid].follow.value, what="following off")
    client = console.app.pages[cid].client
    with client.atomic():
        client.camera.position = (-30.0, 30.0, 10.0)
        client.camera.look_at = (-40.0, 40.0, 10.0)
    wait_for(lambda: robot_drawn(page) < 10, timeout=60, what="the robot out of view")
    page.get_by_role("button", name="Frame the robot").click()
    wait_for(lambda: robot_drawn(page) > 300, timeout=60, what="the robot drawn once framed")
    expect(page.locator("#ucat-review")).to_contain_text(SESSION)
    page.close()
