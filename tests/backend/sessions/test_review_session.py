"""A page's review without the page (``backend.review.session.ReviewSession``): the folder,
opening a session, playing, jumping, markers, export and what it refuses."""

from __future__ import annotations

import io
import zipfile
from pathlib import Path

import pytest
from session_helpers import example_message, record

from ucat_console.backend.review.session import MARKER_INTERVAL, ReviewSession
from ucat_console.backend.sessions.shared import SharedReaders
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.messages import BodyState
from ucat_console.telemetry.stream import TelemetryStream


@pytest.fixture
def folder(tmp_path: Path) -> tuple[Path, str]:
    items = [(ch.BODY_STATE, example_message(BodyState, t=0.01 * k, nan=False)) for k in range(300)]
    items.insert(150, (ch.EVENTS, Event(1.5, "operator", "mark", "half way", "warning")))
    [path] = record(tmp_path, items)
    return tmp_path, path.name.split("_")[0]


def review(folder: tuple[Path, str], **kw) -> tuple[ReviewSession, list]:
    stream = TelemetryStream()
    got: list = []
    stream.subscribe(lambda c, m: got.append((c, m)), [ch.BODY_STATE])
    return ReviewSession(folder[0], stream, **kw), got


def test_a_session_opens_plays_onto_the_stream_and_closes(folder) -> None:
    readers = SharedReaders()
    r, got = review(folder, readers=readers)
    [info] = r.listing().sessions
    assert info.session_id == folder[1]
    reader, player = r.open(folder[1])
    assert r.reviewing == folder[1] and r.position() == 0.0 and "1 part" in r.said
    assert readers.users(reader) == 1 and readers.budget.used > 0
    player.seek(player.start + 2.0)
    assert got and got[-1][1].t == pytest.approx(2.0, abs=0.011)  # the state at the new position
    assert r.position() == pytest.approx(2.0, abs=0.011)
    assert r.close() and r.reviewing == "" and r.position() is None
    assert readers.users(reader) == 0 and readers.budget.used == 0


def test_jumps_markers_and_export(folder) -> None:
    now = [100.0]
    r, _ = review(folder, clock=lambda: now[0])
    r.open(folder[1])
    event = r.jump(True, {"warning"})
    assert isinstance(event, Event) and event.code == "mark"
    with pytest.raises(ValueError, match="over the limit of 2048 bytes"):
        r.add_marker("x" * 5000)
    m = r.add_marker("look here")
    assert m.note == "look here" and "marker at 1.50 s" in r.said
    with pytest.raises(ValueError, match="at most one every"):
        r.add_marker("too soon")
    now[0] += MARKER_INTERVAL
    r.add_marker("later")
    x = r.export(history=1.0)
    assert x.start == pytest.approx(0.5, abs=0.011) and x.end == pytest.approx(1.5, abs=0.011)
    names = zipfile.ZipFile(io.BytesIO(x.content)).namelist()
    assert any(n.endswith(f"{ch.BODY_STATE.replace('/', '_')}.csv") for n in names), names
    assert 95 <= x.rows[ch.BODY_STATE] <= 101  # a second of 100 Hz states


@pytest.mark.parametrize("bad", ["", "..", "../elsewhere", "/etc/passwd", 3, None])
def test_a_name_that_is_not_a_plain_session_name_is_refused_and_nothing_changes(folder, bad) -> None:
    r, _ = review(folder)
    r.open(folder[1])
    with pytest.raises(ValueError, match="is not a session or a file name"):
        r.open(bad)
    assert r.reviewing == folder[1]  # the open session stays open


def test_commands_without_a_session_or_with_bad_values_are_refused(folder) -> None:
    r, _ = review(folder)
    for fn in (lambda: r.need(), lambda: r.export(1.0), lambda: r.run_counterfactual("lam_st=2"),
               lambda: r.jump(True, None)):
        with pytest.raises(ValueError, match="no session open"):
            fn()
    for bad in (float("nan"), True, "1"):
        with pytest.raises(ValueError, match="time"):
            r.check_time(bad)
    with pytest.raises(ValueError, match="step"):
        r.check_step(2)
    with pytest.raises(ValueError):
        r.set_speed(0.0)
    assert r.speed == 1.0
    with pytest.raises(ValueError, match="loop"):
        r.set_loop("yes")


def test_repair_only_when_allowed(folder) -> None:
    def refuse() -> None:
        raise PermissionError("only the pilot's page repairs")

    r, _ = review(folder, may_repair=refuse)
    with pytest.raises(PermissionError):
        r.repair(folder[1])
    r, _ = review(folder)
    [report] = r.repair(folder[1])
    assert not report.repaired and "nothing to repair" in r.said
