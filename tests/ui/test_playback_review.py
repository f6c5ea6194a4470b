"""The review tab on one time base and one session at a time: the plots, events, markers and
position in seconds from the session's start; nothing of a session left when another opens
or it closes; a seek and a marker asked while the session opens applied once it is open; the
playhead; the REVIEW badge's state; the CSV export.

The session is recorded a few seconds after the console started, so that its stream time and
its session time differ.
"""

from __future__ import annotations

import csv
import io
import threading
import types
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import viser
from support import Console, wait_for

from ucat_console.backend.access import LOCAL
from ucat_console.backend.sessions import files
from ucat_console.backend.sessions.reader import SessionReader
from ucat_console.config import AppConfig
from ucat_console.telemetry import channels as ch
from ucat_console.ui.page_jobs import PageJobs
from ucat_console.ui.playback import PlaybackPanel
from ucat_console.ui.plots import playhead_marks

PLOT_RATE = 10.0
BEFORE = 3.0  # s the console runs before the recording starts


@dataclass
class Late:
    directory: Path
    path: Path
    start: float  # stream s
    end: float
    body_times: list[float]

    @property
    def session_id(self) -> str:
        return files.parse_part_name(self.path)[0]


@pytest.fixture(scope="module")
def late(tmp_path_factory: pytest.TempPathFactory) -> Late:
    d = tmp_path_factory.mktemp("late_sessions")
    sup = Console(AppConfig(), d).sup
    try:
        sup.step(BEFORE)
        sup.set_setpoints(LOCAL, velocity=0.2)
        sup.start_recording(LOCAL, "late run")
        sup.arm(LOCAL)
        sup.step(1.0)
        sup.add_marker(LOCAL, "one second in")
        sup.step(2.0)
        [path] = sup.stop_recording(LOCAL)
    finally:
        sup.stop()
    with SessionReader(path, d) as r:
        start, end = r.start, r.end
        body_times = [m.t for _, m in r.messages([ch.BODY_STATE])]
    assert start > BEFORE - 0.5  # stream time and session time differ
    return Late(d, path, start, end, body_times)


def make_panel(server: viser.ViserServer, late: Late, **kw: Any) -> PlaybackPanel:
    return PlaybackPanel(server.gui, server.scene, AppConfig().plant.geometry, directory=late.directory,
                         plot_rate=PLOT_RATE, max_history=60.0, history=lambda: 60.0, **kw)


@pytest.fixture
def panel(server: viser.ViserServer, late: Late):
    p = make_panel(server, late)
    yield p
    p.stop()
    for f in late.directory.glob("*.markers.json"):
        f.unlink()


def chart_values(panel: PlaybackPanel) -> list[np.ndarray]:
    """Every value series of every review chart (the time axis left out)."""
    return [np.asarray(s, dtype=float) for c in panel.plots.charts for s in c.data[1:]]


def page_event(handle: Any) -> None:
    """What viser does when the page changes ``handle`` (its value already set)."""
    event = types.SimpleNamespace(client_id=1, client=None, target=handle)
    for cb in list(handle._impl.update_cb):
        cb(event)


def test_the_plots_events_markers_and_position_are_in_session_time(panel: PlaybackPanel, late: Late) -> None:
    panel.open(late.session_id)
    panel.seek(2.0)
    rows = panel.feeder.buffer.last(1000)
    last_body = max(t for t in late.body_times if t <= late.start + 2.0 + 1e-9)
    assert rows[-1, 0] == pytest.approx(last_body - late.start)
    assert 0.0 <= rows[0, 0] < 0.2
    assert panel.position() == pytest.approx(2.0)
    wait_for(lambda: "at 2.00 /" in panel.status.content, what="the status at the position")
    # the recorded marker: its change mark and its description, one second in
    assert [round(t, 1) for t in panel.feeder.changes] == [1.0]
    panel.seek(0.5)
    what = panel.next_event()
    assert what is not None and "event at 1.00 s" in panel.messages[-1]
    m = panel.add_marker("late")
    assert f"marker at {m.t - late.start:.2f} s" in panel.messages[-1]
    assert m.t - late.start == pytest.approx(1.0, abs=0.05)


def test_opening_a_session_over_another_and_closing_it_leave_nothing_shown(panel: PlaybackPanel, late: Late) -> None:
    panel.open(late.session_id)
    panel.seek(2.5)
    panel.view.refresh_plots()
    assert any(np.isfinite(v).any() for v in chart_values(panel))  # drawn
    panel.feeder.changes.append(99.0)  # something only the first opening had
    panel.open(late.session_id)  # opened over the open one: the same path as another session
    assert all(not np.isfinite(v).any() for v in chart_values(panel))  # no line of the first
    assert 99.0 not in panel.feeder.changes
    panel.seek(2.5)
    panel.view.refresh_plots()
    panel.close_session()
    assert all(not np.isfinite(v).any() for v in chart_values(panel))
    assert len(panel.feeder.buffer) == 0 and not panel.feeder.changes
    assert panel.view.scene is None and panel.reviewing == ""


def test_the_charts_have_no_line_before_their_first_rows(panel: PlaybackPanel) -> None:
    for chart in panel.plots.charts:
        assert list(chart.data[0]) == [0.0, 1.0]  # an x range, as viser's page needs
        assert all(np.isnan(np.asarray(s, dtype=float)).all() for s in chart.data[1:])


def test_the_playhead_is_drawn_at_the_position(panel: PlaybackPanel, late: Late) -> None:
    panel.open(late.session_id)
    panel.seek(1.5)
    panel.view.refresh_plots()
    for chart in panel.plots.charts:
        t, head = np.asarray(chart.data[0]), np.asarray(chart.data[-1])
        [at] = np.flatnonzero(head == 1.0)
        assert t[at] <= 1.5 + 1e-9 and (at == len(t) - 1 or t[at + 1] > 1.5)
        assert t[at] > 1.3
    t = np.array([0.0, 0.1, 0.2, 0.3])
    assert list(playhead_marks(t, 0.15)) == [-1.0, 1.0, -1.0, -1.0]
    assert list(playhead_marks(t, None)) == [-1.0] * 4
    assert list(playhead_marks(t, -0.5)) == [-1.0] * 4


def test_a_seek_and_a_marker_asked_while_the_session_opens_apply_once_it_is_open(
        server: viser.ViserServer, late: Late) -> None:
    jobs = PageJobs()  # the console's rationing: jobs at least 0.5 s apart
    hold = threading.Event()
    panel = make_panel(server, late,
                       jobs=lambda what, job, coalesce: jobs.submit("page", what, job, coalesce=coalesce))
    try:
        assert jobs.submit("page", "Hold", lambda: hold.wait(30.0)) is None  # the open waits behind it
        panel.choice.value = late.session_id
        page_event(panel.open_button)
        panel.timeline.value = 2.0
        page_event(panel.timeline)
        panel.note.value = "two seconds in"
        page_event(panel.marker_button)
        panel.timeline.value = 0.0  # the console showing the player's position meanwhile
        hold.set()
        wait_for(lambda: panel.player is not None and not jobs.busy("page"), what="open, seek and marker done")
        assert panel.position() == pytest.approx(2.0)
        [m] = panel.player.markers.markers
        assert m.note == "two seconds in" and m.t - late.start == pytest.approx(2.0)
    finally:
        jobs.stop()
        panel.stop()
        for f in late.directory.glob("*.markers.json"):
            f.unlink()


def test_csv_export_of_the_shown_window(server: viser.ViserServer, late: Late) -> None:
    panel = make_panel(server, late)
    panel.history = lambda: 1.0
    sent: list[tuple[str, bytes]] = []
    try:
        with pytest.raises(ValueError, match="no session open"):
            panel.export_csv(lambda name, content: sent.append((name, content)))
        panel.open(late.session_id)
        panel.seek(2.5)
        rows = panel.export_csv(lambda name, content: sent.append((name, content)))
        [(name, content)] = sent
        assert name.startswith(late.session_id) and name.endswith(".zip")
        with zipfile.ZipFile(io.BytesIO(content)) as z:
            names = z.namelist()
            body = [n for n in names if n.endswith("/body_state.csv")]
            assert body and any(n.endswith("body_state.columns.json") for n in names)
            table = list(csv.DictReader(io.StringIO(z.read(body[0]).decode())))
        times = [float(r["t"]) - late.start for r in table]
        # the plots' window: the last second before the position, every body state in it
        assert 1.5 - 1e-6 <= times[0] < 1.53 and 2.47 < times[-1] <= 2.5 + 1e-6
        assert len(times) == rows[ch.BODY_STATE] and len(times) >= 50
    finally:
        panel.stop()


def test_the_status_bar_says_review_while_a_session_plays(panel: PlaybackPanel, late: Late) -> None:
    assert panel.reviewing == ""
    panel.open(late.session_id)
    assert panel.reviewing == late.session_id
    panel.close_session()
    assert panel.reviewing == ""
