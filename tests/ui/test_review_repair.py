"""Review's Repair on a served console, pressed from raw websocket pages: only the pilot's
page repairs (a viewer's press is refused on the server, the reason shown on its page), the
original stays listed beside the repaired file, and the part being recorded is never
repaired: the recording goes on and is complete when it stops."""

from __future__ import annotations

from pathlib import Path
from typing import Callable

from support import TOKEN, Console, console_config, wait_for

from ucat_console.backend.access import LOCAL
from ucat_console.backend.sessions import index
from ucat_console.backend.sessions.reader import SessionReader
from ucat_console.backend.sessions.recorder import Recorder, RecorderConfig
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.messages import Setpoints
from ucat_console.telemetry.stream import TelemetryStream
from ucat_console.ui.markdown import esc

SETTINGS = {"scene_rate": 10.0, "plot_rate": 2.0}


def truncated_session(directory: Path) -> Path:
    """A recording cut short, as a killed recorder leaves it (no summary)."""
    stream = TelemetryStream()
    rec = Recorder(stream, RecorderConfig(chunk_size=4096), directory=directory)
    rec.start(label="cut")
    for k in range(3000):
        stream.publish(ch.SETPOINTS, Setpoints(0.01 * k, float(k), 1.0, 0.0))
    [path] = rec.stop()
    path.write_bytes(path.read_bytes()[:20_000])
    return path


def shown(console: Console, cid: int, text: str) -> bool:
    """Whether page ``cid``'s Review tab has shown a message holding ``text``."""
    review = console.app.reviews.get(cid)
    return review is not None and any(text in m for m in review.messages)


def pilot_page(console: Console):
    page = console.page()
    cid = console.cid_of(page)
    page.take_control(TOKEN)
    wait_for(lambda: console.sup.access.pilot == cid, what="the page taking control")
    return page, cid


def test_only_the_pilots_page_repairs_and_the_original_stays_listed(
        make_console: Callable[..., Console], tmp_path: Path) -> None:
    cut = truncated_session(tmp_path)
    original = tmp_path / (cut.stem + ".orig.mcap")
    # the pilot page may be slow to answer the console's heartbeats on a loaded machine
    console = make_console(console_config(pilot_gone=30.0, **SETTINGS), serve=True)
    viewer = console.page()
    viewer_cid = console.cid_of(viewer)
    viewer.click("Repair")
    wait_for(lambda: shown(console, viewer_cid, "repair: refused"), what="the viewer's refusal")
    review = console.app.reviews[viewer_cid]
    assert "only the pilot" in review.messages[-1] and "Refused" in review.message.content
    assert index.list_sessions(tmp_path)[0].truncated and not original.exists()

    pilot, pilot_cid = pilot_page(console)
    pilot.click("Repair")
    wait_for(lambda: shown(console, pilot_cid, f"repaired {cut.name}"), what="the pilot's repair")
    review = console.app.reviews[pilot_cid]
    assert f"the original kept as {original.name}" in review.messages[-1]
    names = [p.path.name for s in index.list_sessions(tmp_path) for p in s.parts]
    assert sorted(names) == sorted([cut.name, original.name])
    assert esc(f"the original of {cut.name}, kept by its repair") in review.browser.content


def test_the_session_being_recorded_is_not_repaired_and_records_on_complete(
        make_console: Callable[..., Console], tmp_path: Path) -> None:
    # the pilot page may be slow to answer the console's heartbeats on a loaded machine
    console = make_console(console_config(pilot_gone=30.0, **SETTINGS), serve=True)
    sup = console.sup
    sid = sup.start_recording(LOCAL)
    [path] = sup.recorder.paths
    wait_for(lambda: sup.recorder.stats().written > 100 and path.stat().st_size > 0, what="the recording")
    pilot, cid = pilot_page(console)
    review = console.app.reviews[cid]
    wait_for(lambda: review.choice.value == sid, what="the session in the page's list")
    assert "recording" in review.browser.content and review.repair_button.disabled
    pilot.click("Repair")  # pressed anyway (a page may send what its button does not offer)
    refusal = f"repair: {path.name} is being recorded; stop the recording first"
    wait_for(lambda: shown(console, cid, refusal), what="the refusal")
    written = sup.recorder.stats().written
    wait_for(lambda: sup.recorder.stats().written > written + 100, what="the recording going on")
    assert sup.stop_recording(LOCAL) == [path]
    assert sorted(p.name for p in tmp_path.glob("*.mcap")) == [path.name]  # no original, no snapshot
    with SessionReader(path, tmp_path) as r:
        assert r.message_count == sup.recorder.stats().written
