"""The player: seek, speed bounds, loop, step, event jumps, markers, the playing thread."""

from __future__ import annotations

import hashlib
import json
import math

import pytest
from support import StreamSink, wait_for
from session_helpers import record

from ucat_console.backend.sessions.player import Player
from ucat_console.backend.sessions.reader import SessionReader
from ucat_console.backend.sessions.recorder import RecorderConfig
from ucat_console.telemetry import channels as C
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.messages import BodyState, FinState
from ucat_console.telemetry.stream import TelemetryStream

OFFSET = 1_700_000_000.0


def body(t: float) -> BodyState:
    return BodyState(t, (t, 0.0, 1.0), (1.0, 0.0, 0.0, 0.0), (0.3, 0.0, 0.0), (0.0, 0.0, 0.0), 1.0)


def make_items():
    """Body state every 0.1 s for 10 s, fin 0 state every 0.25 s, events at 2.05 and 6.05."""
    items = []
    for k in range(100):
        items.append((C.BODY_STATE, body(0.1 * k)))
    for k in range(40):
        items.append((C.fin_state(0), FinState(0.25 * k, 0, 0.01 * k, 0.0, 0.0, 0.0)))
    items.append((C.EVENTS, Event(2.05, "operator", "marker", "first", "info")))
    items.append((C.EVENTS, Event(6.05, "failsafe", "silence", "second", "error")))
    items.sort(key=lambda x: x[1].t)
    return items


@pytest.fixture
def session(sessions):
    items = make_items()
    [path] = record(sessions, items, RecorderConfig(chunk_size=4096), epoch_offset=OFFSET)
    return path, items


def brute_state(items, t):
    state = {}
    for ch, m in items:
        if m.t <= t + 1e-12:
            state[ch] = m
    return state


@pytest.fixture
def player(session, sessions):
    path, items = session
    stream = TelemetryStream()
    sink = StreamSink(stream)
    reader = SessionReader(path, sessions)
    p = Player(reader, stream)
    yield p, sink, items
    p.close()
    reader.close()


def test_seek_publishes_the_state_at_t(player):
    p, sink, items = player
    for t in (0.0, 2.05, 3.333, 9.9):
        state = p.seek(t)
        assert state == brute_state(items, t)
        published = sink.take()
        assert dict(published) == state  # each channel's latest message, once
        assert [m.t for _, m in published] == sorted(m.t for m in state.values())
        assert p.position == pytest.approx(t)
    p.seek(-5.0)
    assert p.position == 0.0  # clamped to the session
    p.seek(50.0)
    assert p.position == pytest.approx(9.9)


@pytest.mark.parametrize("bad", [0.09, 5.01, 0.0, -1.0, math.nan, math.inf, True, "2"])
def test_speed_out_of_range_is_refused(player, bad):
    p, _, _ = player
    with pytest.raises(ValueError, match="speed"):
        p.speed = bad
    assert p.speed == 1.0


def test_speed_bounds_and_advance_publish_exactly_the_messages_in_the_interval(player):
    p, sink, items = player
    p.speed = 0.1
    p.speed = 5.0
    p.speed = 2.0
    p.seek(1.0)
    sink.take()
    n = p.advance(0.75)  # 1.5 s of session time at 2x
    got = sink.take()
    want = [(c, m) for c, m in items if 1.0 + 1e-9 < m.t <= 2.5 + 1e-9]
    assert got == want and n == len(want)
    assert p.position == pytest.approx(2.5)


def test_end_stops_without_loop_and_restarts_with_loop(player):
    p, sink, items = player
    p.seek(9.5)
    sink.take()
    p._playing = True  # as the playing thread would be
    p.advance(2.0)
    assert not p.playing and p.at_end
    assert [m.t for _, m in sink.take()] == [m.t for _, m in items if m.t > 9.5 + 1e-9]
    p.loop = True
    p.seek(9.5)
    sink.take()
    p._playing = True
    p.advance(1.0)  # 0.4 s to the end, then 0.6 s from the start again
    got = sink.take()
    tail = [(c, m) for c, m in items if m.t > 9.5 + 1e-9]
    assert got[: len(tail)] == tail
    restart = got[len(tail):]
    start_state = brute_state(items, 0.0)
    assert dict(restart[: len(start_state)]) == start_state
    assert [m.t for _, m in restart[len(start_state):]] == [
        m.t for _, m in items if 1e-9 < m.t <= 0.6 + 1e-9
    ]
    assert p.playing


def test_step_moves_one_body_state_frame(player):
    p, sink, items = player
    p.seek(1.0)
    sink.take()
    assert p.step(+1)
    got = sink.take()
    assert p.position == pytest.approx(1.1)
    assert got == [(c, m) for c, m in items if 1.0 + 1e-9 < m.t <= 1.1 + 1e-9]
    assert p.step(-1) and p.position == pytest.approx(1.0)
    assert p.step(-1) and p.position == pytest.approx(0.9)
    assert dict(sink.take()[-len(brute_state(items, 0.9)):]) == brute_state(items, 0.9)
    p.seek(9.9)
    assert not p.step(+1)
    p.seek(0.0)
    assert not p.step(-1)
    with pytest.raises(ValueError):
        p.step(2)


def test_event_jumps_and_markers_in_a_sidecar_leaving_the_file_unchanged(player, sessions):
    p, sink, items = player
    path = p.reader.path
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    p.seek(0.0)
    assert p.next_event().message == "first" and p.position == pytest.approx(2.05)
    marker = p.add_marker("fin 2 stalls", t=4.0)
    assert p.next_event() == marker and p.position == pytest.approx(4.0)
    assert p.next_event().message == "second"
    assert p.next_event() is None and p.position == pytest.approx(6.05)
    assert p.prev_event() == marker
    assert p.prev_event().message == "first"
    assert p.prev_event() is None
    # the sidecar holds the marker; the recording is byte-identical
    sidecar = sessions / f"{p.reader.session_id}.markers.json"
    doc = json.loads(sidecar.read_text())
    assert doc["session"] == p.reader.session_id
    assert [(m["t"], m["note"]) for m in doc["markers"]] == [(4.0, "fin 2 stalls")]
    assert hashlib.sha256(path.read_bytes()).hexdigest() == digest
    # a new player of the same session sees it; removing it updates the file
    other = Player(p.reader, TelemetryStream())
    assert other.markers.markers == [marker]
    other.markers.remove(marker)
    assert json.loads(sidecar.read_text())["markers"] == []


def test_bad_sidecar_is_refused(session, sessions):
    path, _ = session
    with SessionReader(path, sessions) as r:
        (sessions / f"{r.session_id}.markers.json").write_text('{"session": "x", "markers": []}')
        with pytest.raises(ValueError, match="markers of session 'x'"):
            Player(r, TelemetryStream())


def test_playing_thread_publishes_everything_in_order_then_stops(player):
    p, sink, items = player
    p.seek(8.0)
    sink.take()
    p.speed = 5.0
    p.play()
    wait_for(lambda: not p.playing, what="the player at the end")
    assert not p.playing
    assert sink.take() == [(c, m) for c, m in items if m.t > 8.0 + 1e-9]
    p.play()  # at the end: starts again from the beginning
    p.pause()
    assert not p.playing


def test_event_jumps_can_stop_only_at_warnings_and_errors(player):
    p, sink, items = player
    p.seek(0.0)
    serious = frozenset({"warning", "error", "fatal"})
    assert p.next_event(serious).message == "second"  # the info event at 2.05 s is passed over
    assert p.position == pytest.approx(6.05)
    assert p.next_event(serious) is None
    assert p.prev_event(serious) is None  # nothing serious before 6.05
    assert p.prev_event().message == "first"  # every event
