"""The Review tab's library in headless Chromium, end to end: the run table, a search that
narrows it, a run's report downloaded from Open report (its HTML), and a run recorded with the
emulated camera's video played and paused: the frame the page shows is the one at the playhead
(its time, in the camera caption, within one frame period before the playback position the
page shows). A screenshot goes to ``test-artifacts/``."""

from __future__ import annotations

import re
import sys
from pathlib import Path
from typing import Iterator

import pytest
from support import Console, wait_for

pytest.importorskip("playwright.sync_api")
from browser_harness import ARTIFACTS, browser_console, gui_input, open_page  # noqa: E402
from playwright.sync_api import Browser, expect  # noqa: E402
from test_review_library import recorded  # noqa: E402

sys.path.insert(0, str(Path(__file__).parents[1] / "backend" / "sessions"))
from session_helpers import record  # noqa: E402
from synthetic_run import run_items  # noqa: E402

from ucat_console.backend.camera.config import CameraConfig  # noqa: E402
from ucat_console.backend.camera.emulated import EmulatedCamera  # noqa: E402
from ucat_console.backend.review.run_report import write_report  # noqa: E402
from ucat_console.telemetry import channels as ch  # noqa: E402
from ucat_console.telemetry.messages import CameraImage  # noqa: E402

pytestmark = [pytest.mark.browser, pytest.mark.slow]
FPS = 30.0
PERIOD = 1.0 / FPS
DURATION = 8.0


def video_run(directory: Path) -> str:
    """A driven run of :data:`DURATION` s with the emulated camera's frames at :data:`FPS`; its id."""
    cam = EmulatedCamera(CameraConfig(source="emulated", fps=FPS, width=160, height=90, jpeg_quality=70))
    frames = [(ch.CAMERA_IMAGE, CameraImage(t=k * PERIOD, frame_id="camera", format="jpeg", data=cam.frame(k * PERIOD)))
              for k in range(int(DURATION * FPS))]
    items = sorted([*run_items(DURATION, speed=0.2), *frames], key=lambda it: it[1].t)
    [path] = record(directory, items, label="video", notes="with the camera", wall_time=1_800_000_000.0)
    return path.name.removesuffix("_001.mcap")


@pytest.fixture
def runs(tmp_path: Path) -> Iterator[tuple[Console, str, str]]:
    calm, video = recorded(tmp_path, "calm", "calm water"), video_run(tmp_path)
    write_report(video, directory=tmp_path)
    c = browser_console(tmp_path)
    yield c, calm, video
    c.stop()


def _seconds(page, pattern: str) -> float:
    """The number ``pattern``'s group holds in the page's text (waits for it)."""
    loc = page.get_by_text(re.compile(pattern)).first
    expect(loc).to_be_visible(timeout=30_000)
    return float(re.search(pattern, loc.inner_text()).group(1))


def test_the_library_is_searched_a_report_downloaded_and_a_run_played_with_its_video(
        browser: Browser, runs: tuple[Console, str, str]) -> None:
    console, calm, video = runs
    page = open_page(browser, console.url, 1280, 800)
    page.get_by_role("tab", name="Review", exact=True).click()
    table = page.locator("table", has_text=video).first  # the Runs table (the files table lists parts)
    expect(table).to_be_visible(timeout=30_000)
    expect(table).to_contain_text(calm)
    expect(table.locator("th").first).to_have_text("run")
    search = gui_input(page, "Search")
    search.fill("notes~camera")
    search.press("Enter")
    expect(page.get_by_text("1 run match")).to_be_visible(timeout=30_000)
    runs_table = page.locator("table", has=page.locator("th", has_text="manoeuvre")).first
    expect(runs_table).to_contain_text(video)
    expect(runs_table).not_to_contain_text(calm)
    chooser = gui_input(page, "Session")
    expect(chooser).to_have_value(video)
    ARTIFACTS.mkdir(exist_ok=True)
    runs_table.scroll_into_view_if_needed()
    page.screenshot(path=str(ARTIFACTS / "review-table-1280x800.png"))

    # the report: viser offers it as a link in a notification; the file is the run's report HTML
    page.get_by_role("button", name="Open report").click()
    link = page.get_by_role("link", name=re.compile(re.escape(f"{video}.report.html")))
    expect(link).to_be_visible(timeout=30_000)
    with page.expect_download() as got:
        link.click()
    html = Path(got.value.path()).read_text(encoding="utf-8")
    assert html.lstrip().lower().startswith("<!doctype html") and video in html

    # play the run with its video, pause it: the frame shown is the one at the playhead
    page.get_by_role("button", name="Open", exact=True).click()
    review = next(iter(console.app.reviews.values()))
    wait_for(lambda: review.reviewing == video, what="the run open", timeout=30.0)
    expect(page.get_by_text("paused at")).to_be_visible(timeout=30_000)
    page.get_by_role("button", name="Play", exact=True).click()
    wait_for(lambda: (review.position() or 0.0) > 1.5, what="playback advancing", timeout=30.0)
    page.get_by_role("button", name="Pause", exact=True).click()
    wait_for(lambda: review.player is not None and not review.player.playing, what="paused")

    def frame_at_playhead() -> bool:
        at = _seconds(page, r"paused at ([0-9.]+) /")
        shown = _seconds(page, r"frame at ([0-9.]+) s of the session")
        # the playhead as the page shows it (2 decimals) and the frame at or before it
        return -0.006 <= at - shown <= PERIOD + 0.006

    wait_for(frame_at_playhead, what="the page's frame within one frame period of its playhead", timeout=30.0)
    at = _seconds(page, r"paused at ([0-9.]+) /")
    assert 1.5 < at < DURATION  # a paused position inside the run, not its start or end
    page.get_by_text(re.compile(r"frame at [0-9.]+ s of the session")).first.scroll_into_view_if_needed()
    page.screenshot(path=str(ARTIFACTS / "review-video-1280x800.png"))
    page.close()
