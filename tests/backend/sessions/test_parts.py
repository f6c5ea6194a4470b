"""A session split into parts, read as one recording: records, state, player, events,
refusals. Sessions are recorded through the real recorder with a small ``split_duration``;
the reference for the whole session is each part read alone with ``SessionReader`` and the
messages that were published."""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path

import pytest
from support import StreamSink, wait_for
from mcap.records import Attachment, Channel, DataEnd, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import Writer
from session_helpers import record

from ucat_console.backend.sessions import files, repair
from ucat_console.backend.sessions.player import Player
from ucat_console.backend.sessions.mcap_read import TruncatedSessionError
from ucat_console.backend.sessions.reader import SessionParts, SessionReader, open_session
from ucat_console.backend.sessions.recorder import Recorder, RecorderConfig
from ucat_console.backend.sessions.replay import counterfactual
from ucat_console.telemetry import channels as C
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.messages import BodyState, FinPlan, FinState, Setpoints
from ucat_console.telemetry.stream import TelemetryStream

OFFSET = 1_700_000_000.0
SPLIT = RecorderConfig(split_duration=1.0, chunk_size=4096)
EVENT_TIMES = (0.55, 1.55, 2.55, 3.55, 4.55)


def body(t: float) -> BodyState:
    return BodyState(t, (t, 0.0, 1.0), (1.0, 0.0, 0.0, 0.0), (0.3, 0.0, 0.0), (0.0, 0.0, 0.0), 1.0)


def make_items() -> list[tuple[str, object]]:
    """Body state every 0.1 s for 5 s, fin 0 every 0.25 s, one setpoint at 0.05 s (only in
    the first part), an event every second."""
    items: list[tuple[str, object]] = [(C.BODY_STATE, body(0.1 * k)) for k in range(50)]
    items += [(C.fin_state(0), FinState(0.25 * k, 0, 0.01 * k, 0.0, 0.0, 0.0)) for k in range(20)]
    items.append((C.SETPOINTS, Setpoints(0.05, 0.2, 1.0, 0.0)))
    items += [(C.EVENTS, Event(t, "operator", "marker", f"event at {t}", "info"))
              for t in EVENT_TIMES]
    items.sort(key=lambda x: x[1].t)  # stable: at equal times, in the order above
    return items


def brute_state(items, t: float) -> dict[str, object]:
    state = {}
    for ch, m in items:
        if m.t <= t + 1e-12:
            state[ch] = m
    return state


def part_records(paths: list[Path], directory: Path, **kwargs) -> list[tuple[str, int, object]]:
    """Every part read alone, concatenated in part order."""
    out = []
    for p in paths:
        with SessionReader(p, directory) as r:
            out += [(x.channel, x.log_time_ns, x.message) for x in r.records(**kwargs)]
    return out


def part_spans(paths: list[Path], directory: Path) -> list[tuple[float, float]]:
    """(first, last) message time of each part, read alone."""
    out = []
    for p in paths:
        with SessionReader(p, directory) as r:
            out.append((r.start, r.end))
    return out


@pytest.fixture
def split(sessions):
    items = make_items()
    paths = record(sessions, items, SPLIT, epoch_offset=OFFSET, notes="split session",
                   config_toml="[loop.mpc]\nlam_st = 4.0\n", weights={"lam_st": 4.0})
    assert len(paths) >= 3
    sid = files.parse_part_name(paths[0])[0]
    return sid, paths, items


def rewrite_session_metadata(path: Path, **changes: str) -> None:
    """Copy ``path`` record by record into a new MCAP file with its ``session`` metadata
    record changed."""
    tmp = path.with_name(path.name + ".tmp")
    with open(path, "rb") as src, open(tmp, "wb") as out:
        w = Writer(out)
        w.start(profile=files.PROFILE, library="test")
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for rec in StreamReader(src).records:
            if isinstance(rec, Schema):
                schemas[rec.id] = w.register_schema(rec.name, rec.encoding, rec.data)
            elif isinstance(rec, Channel):
                channels[rec.id] = w.register_channel(rec.topic, rec.message_encoding,
                                                      schemas[rec.schema_id])
            elif isinstance(rec, Message):
                w.add_message(channels[rec.channel_id], log_time=rec.log_time, data=rec.data,
                              publish_time=rec.publish_time, sequence=rec.sequence)
            elif isinstance(rec, Metadata):
                data = dict(rec.metadata)
                if rec.name == files.META_SESSION:
                    data.update(changes)
                w.add_metadata(rec.name, data)
            elif isinstance(rec, Attachment):
                raise AssertionError("no attachments expected")
            elif isinstance(rec, DataEnd):
                break
        w.finish()
    tmp.replace(path)


# ------------------------------------------------------------------ reading
def test_records_are_the_parts_concatenated_in_time_order(split, sessions):
    sid, paths, items = split
    with SessionParts(sid, sessions) as s:
        whole = [(r.channel, r.log_time_ns, r.message) for r in s.records()]
        assert s.session_id == sid and s.paths == tuple(paths) and len(s.parts) == len(paths)
        assert s.message_count == len(items)
        assert s.start == 0.0 and s.end == pytest.approx(4.9)
        assert s.duration == pytest.approx(4.9)
        assert set(s.channels) == set(C.CHANNELS)
        counts = s.message_counts()
        assert counts[C.BODY_STATE] == 50 and counts[C.fin_state(0)] == 20
        assert counts[C.SETPOINTS] == 1 and counts[C.EVENTS] == len(EVENT_TIMES)
        # a range across part boundaries, two channels
        got = list(s.messages([C.BODY_STATE, C.EVENTS], start=0.75, end=3.25))
        assert got == [(c, m) for c, m in items
                       if c in (C.BODY_STATE, C.EVENTS) and 0.75 <= m.t < 3.25]
        # latest first, across the parts
        bodies = [m for c, m in items if c == C.BODY_STATE]
        assert [r.message for r in s.records([C.BODY_STATE], reverse=True)] == bodies[::-1]
        # file-time bounds, as the player asks for them
        mid = s.to_ns(2.0)
        assert [r.message for r in s.records([C.BODY_STATE], start_ns=mid + 1)] == \
            [m for m in bodies if m.t > 2.0 + 1e-9]
        assert [r.message.t for r in s.records([C.BODY_STATE], end_ns=mid, reverse=True)] == \
            [m.t for m in bodies if m.t < 2.0 - 1e-9][::-1]
        with pytest.raises(ValueError, match="unknown telemetry channel 'fins/9'"):
            list(s.records(["fins/9"]))
    assert whole == part_records(paths, sessions)
    assert [(c, m) for c, _, m in whole] == items
    # the parts really are separate files, each with only its own share
    assert all(len(part_records([p], sessions)) < len(items) for p in paths)


def test_opened_by_id_by_any_part_path_or_part_name(split, sessions):
    sid, paths, items = split
    for arg in (sid, paths[0], paths[-1], str(paths[1]), paths[1].name):
        with SessionParts(arg, sessions) as s:
            assert s.paths == tuple(paths), arg
            assert [(c, m) for c, m in s.messages()] == items, arg
    with open_session(paths[1].name, sessions) as s:
        assert s.paths == tuple(paths) and s.session_id == sid


def test_metadata_config_and_weights_of_the_first_part_notes_of_the_latest(sessions):
    items = [(C.SETPOINTS, Setpoints(0.125 * k, float(k), 1.0, 0.0)) for k in range(30)]
    stream = TelemetryStream()
    rec = Recorder(stream, SPLIT, directory=sessions, epoch_offset=OFFSET)
    sid = rec.start(notes="before", config_toml="[loop.mpc]\nlam_f = 2.0\n", weights={"lam_f": 2.0})
    for c, m in items[:20]:
        stream.publish(c, m)
    rec.set_notes("after")  # queued behind the messages: written once part 3 is open
    for c, m in items[20:]:
        stream.publish(c, m)
    paths = rec.stop()
    assert len(paths) >= 3
    with SessionReader(paths[0], sessions) as first:
        assert first.notes == "before"
    with SessionParts(sid, sessions) as s:
        assert s.notes == "after"
        assert s.metadata[files.META_NOTES] == {"text": "after"}
        assert s.config_toml == "[loop.mpc]\nlam_f = 2.0\n"
        assert s.weights == {"lam_f": 2.0}
        assert s.metadata[files.META_SESSION]["id"] == sid
        assert s.version and s.epoch_offset == OFFSET


def test_state_just_after_each_boundary_includes_channels_of_earlier_parts(split, sessions):
    sid, paths, items = split
    spans = part_spans(paths, sessions)
    with SessionParts(sid, sessions) as s:
        for k in range(1, len(paths)):
            first = spans[k][0]
            for t in (first, first + 0.01):
                want = brute_state(items, t)
                got = s.state_at(t)
                assert got == want, t
                # the setpoint is only in part 1; the body state before ``first`` is in part k
                assert got[C.SETPOINTS] == Setpoints(0.05, 0.2, 1.0, 0.0)
                assert any(m.t < first for m in want.values())
                with SessionReader(paths[k], sessions) as alone:  # what the part alone knows
                    assert C.SETPOINTS not in alone.state_at(t)
            # the last instant of the previous part
            assert s.state_at(spans[k - 1][1]) == brute_state(items, spans[k - 1][1])
        # everywhere, against brute force; before the start nothing, after the end everything
        for i in range(0, 101):
            t = 0.05 * i
            assert s.state_at(t) == brute_state(items, t), t
        assert s.state_at(-1.0) == {}
        assert s.state_at(99.0) == brute_state(items, 99.0)
        only = s.state_at(3.0, [C.EVENTS, C.SETPOINTS])
        assert only == {C.EVENTS: brute_state(items, 3.0)[C.EVENTS],
                        C.SETPOINTS: Setpoints(0.05, 0.2, 1.0, 0.0)}
        recs = s.state_records_at_ns(s.to_ns(3.0))
        assert {c: r.message for c, r in recs.items()} == brute_state(items, 3.0)
        assert all(r.log_time_ns == s.to_ns(r.message.t) for r in recs.values())


# ------------------------------------------------------------------ the player
def test_player_publishes_every_message_once_in_order_across_parts(split, sessions):
    sid, paths, items = split
    stream = TelemetryStream()
    sink = StreamSink(stream)
    with SessionParts(sid, sessions) as s:
        p = Player(s, stream)
        n = 0
        while not p.at_end:
            n += p.advance(0.05)
        p.close()
    assert sink.take() == items
    assert n == len(items)


def test_player_seek_step_and_advance_across_a_boundary(split, sessions):
    sid, paths, items = split
    bodies = [m.t for c, m in items if c == C.BODY_STATE]
    spans = part_spans(paths, sessions)
    stream = TelemetryStream()
    sink = StreamSink(stream)
    with SessionParts(sid, sessions) as s:
        p = Player(s, stream)
        for k in range(1, len(paths)):
            before = max(t for t in bodies if t < spans[k][0] - 1e-9)  # last frame of part k-1
            after = min(t for t in bodies if t >= spans[k][0] - 1e-9)  # first frame of part k
            assert p.seek(before) == brute_state(items, before)
            sink.take()
            assert p.step(+1) and p.position == pytest.approx(after)
            assert sink.take() == [(c, m) for c, m in items if before + 1e-9 < m.t <= after + 1e-9]
            assert p.step(-1) and p.position == pytest.approx(before)
            want = brute_state(items, before)
            assert dict(sink.take()) == want
            # seek into part k: the state from every part before it
            assert p.seek(after + 0.01) == brute_state(items, after + 0.01)
            # advance from before the boundary to after it
            p.seek(before - 0.2)
            sink.take()
            p.advance(0.5)
            assert sink.take() == [(c, m) for c, m in items
                                   if before - 0.2 + 1e-9 < m.t <= before + 0.3 + 1e-9]
            assert p.position == pytest.approx(before + 0.3)
        p.close()


def test_playing_thread_crosses_the_boundaries(split, sessions):
    sid, paths, items = split
    stream = TelemetryStream()
    sink = StreamSink(stream)
    with SessionParts(sid, sessions) as s:
        p = Player(s, stream, speed=5.0)
        p.seek(0.5)
        sink.take()
        p.play()
        wait_for(lambda: not p.playing, what="the player at the end")
        assert not p.playing and p.at_end
        p.close()
    assert sink.take() == [(c, m) for c, m in items if m.t > 0.5 + 1e-9]


def test_events_of_every_part_are_jump_targets(split, sessions):
    sid, paths, items = split
    events = [m for c, m in items if c == C.EVENTS]
    with_events = 0
    for path in paths:
        with SessionReader(path, sessions) as r:
            with_events += r.message_counts()[C.EVENTS] > 0
    assert with_events >= 3  # the events really are spread over the parts
    digests = [hashlib.sha256(p.read_bytes()).hexdigest() for p in paths]
    with SessionParts(sid, sessions) as s:
        assert s.events() == events
        assert s.events(1.0, 3.0) == [e for e in events if 1.0 <= e.t < 3.0]
        assert list(s.event_index().times_ns) == [ns for _, ns, _ in part_records(paths, sessions,
                                                                      channels=[C.EVENTS])]
        p = Player(s, TelemetryStream())
        p.seek(0.0)
        seen = []
        while (what := p.next_event()) is not None:
            seen.append(what)
            assert p.position == pytest.approx(what.t)
        assert seen == events
        back = []
        while (what := p.prev_event()) is not None:
            back.append(what)
        assert back == events[-2::-1]  # from the last one, every earlier one
        # a review marker in a later part: beside the parts, a jump target too
        m = p.add_marker("late fin", t=4.0)
        sidecar = sessions / f"{sid}.markers.json"
        assert json.loads(sidecar.read_text())["session"] == sid
        p.seek(3.6)
        assert p.next_event() == m and p.position == pytest.approx(4.0)
        p.close()
    assert [hashlib.sha256(p.read_bytes()).hexdigest() for p in paths] == digests


def test_counterfactual_replay_covers_every_part(sessions):
    def plan(t: float) -> FinPlan:
        return FinPlan(t, 1, "mpc", (-0.4, 0.1), 0.3, 0.0, (0.5, -0.5, 2.0, 2.0),
                       (0.6, -0.6, 3.0, 3.0), (0.6, 3.0, 0.0, 3.0), 1.0, 0.1, 0.1, 0.0, 0.1, 0.3,
                       (-0.3, 0.1), 0.002, False, seed=5)

    times = [0.25 * k for k in range(13)]
    paths = record(sessions, [(C.fin_plan(1), plan(t)) for t in times], SPLIT,
                   config_toml="[loop.mpc]\nn_samples = 32\nmax_iter = 5\n")
    assert len(paths) >= 3
    with SessionParts(paths[0], sessions) as s:
        res = counterfactual(s, {"lam_st": 2.0})
    assert [r.t for r in res.rows] == times
    assert res.config.n_samples == 32 and res.config.lam_st == 2.0


# ------------------------------------------------------------------ refusals
def test_a_missing_middle_part_is_refused_naming_it(split, sessions):
    sid, paths, _ = split
    missing = paths[1]
    missing.unlink()
    for arg in (sid, paths[0], paths[2].name):
        with pytest.raises(ValueError, match=re.escape(missing.name) + ".*missing"):
            SessionParts(arg, sessions)
    with pytest.raises(ValueError, match=re.escape(str(missing))):
        open_session(sid, sessions)


def test_a_missing_first_part_is_refused_naming_it(split, sessions):
    sid, paths, _ = split
    paths[0].unlink()
    with pytest.raises(ValueError, match=re.escape(paths[0].name)):
        SessionParts(sid, sessions)


def test_two_files_of_the_same_part_are_refused_naming_them(split, sessions):
    sid, paths, _ = split
    twin = sessions / f"{sid}_0002.mcap"
    twin.write_bytes(paths[1].read_bytes())
    with pytest.raises(ValueError, match=f"part 2 of session '{sid}' is also"):
        SessionParts(sid, sessions)


def test_parts_that_disagree_on_epoch_offset_are_refused_naming_the_file(split, sessions):
    sid, paths, _ = split
    other = paths[2]
    rewrite_session_metadata(other, epoch_offset=repr(OFFSET + 3600.0))
    with SessionReader(other, sessions) as r:  # the part alone still opens
        assert r.epoch_offset == OFFSET + 3600.0
    with pytest.raises(ValueError, match=re.escape(str(other)) + ".*epoch_offset"):
        SessionParts(sid, sessions)


def test_a_part_of_another_session_is_refused_naming_it(split, sessions):
    sid, paths, _ = split
    rewrite_session_metadata(paths[1], id="20200101-000000-other")
    with pytest.raises(ValueError, match=re.escape(str(paths[1])) + ".*20200101-000000-other"):
        SessionParts(sid, sessions)


def test_a_truncated_part_is_refused_naming_it_then_repaired(split, sessions):
    sid, paths, items = split
    cut = paths[1]
    data = cut.read_bytes()
    cut.write_bytes(data[: len(data) * 2 // 3])
    with pytest.raises(TruncatedSessionError, match=re.escape(str(cut)) + ".*sessions repair"):
        SessionParts(sid, sessions)
    report = repair.repair(cut, sessions)
    assert report.repaired
    with SessionParts(sid, sessions) as s:
        whole = [(r.channel, r.log_time_ns, r.message) for r in s.records()]
        assert s.message_count == len(whole)
    assert whole == part_records(paths, sessions)
    rest = iter(items)  # what the repair kept, in order: none of it new or moved
    assert all(any(x == (c, m) for x in rest) for c, _, m in whole)


def test_unknown_session_and_missing_file_are_refused(sessions, tmp_path):
    record(sessions, make_items(), SPLIT)
    with pytest.raises(ValueError, match="session 'nope': no files"):
        SessionParts("nope", sessions)
    with pytest.raises(ValueError, match="nope_001.mcap: no such session file"):
        SessionParts("nope_001.mcap", sessions)
    outside = tmp_path / "x_001.mcap"
    outside.write_bytes(b"x")
    with pytest.raises(ValueError, match="outside the sessions directory"):
        SessionParts(outside, sessions)


# ------------------------------------------------------------------ sessions of one part
def test_a_one_part_session_reads_as_its_file(sessions):
    items = make_items()
    [path] = record(sessions, items, RecorderConfig(chunk_size=4096), epoch_offset=OFFSET,
                    notes="one part", config_toml="[loop.mpc]\nlam_a = 2.0\n", weights={"lam_a": 2.0})
    sid = files.parse_part_name(path)[0]
    with SessionReader(path, sessions) as r, SessionParts(sid, sessions) as s:
        assert s.paths == (path,) and s.path == r.path and s.session_id == r.session_id
        for name in ("start_ns", "end_ns", "start", "end", "duration", "message_count",
                     "notes", "config_toml", "weights", "version", "metadata", "channels",
                     "epoch_offset"):
            assert getattr(s, name) == getattr(r, name), name
        assert s.message_counts() == r.message_counts()
        assert list(s.records()) == list(r.records())
        assert list(s.records(reverse=True)) == list(r.records(reverse=True))
        assert list(s.messages([C.EVENTS], 1.0, 3.0)) == list(r.messages([C.EVENTS], 1.0, 3.0))
        assert s.events() == r.events() and s.event_index() == r.event_index()
        for t in (-1.0, 0.0, 0.05, 1.0, 2.55, 4.9, 10.0):
            assert s.state_at(t) == r.state_at(t) == brute_state(items, t), t
        assert s.to_ns(1.5) == r.to_ns(1.5) and s.from_ns(s.to_ns(1.5)) == r.from_ns(r.to_ns(1.5))
    with SessionParts(path, sessions) as s:
        assert list(s.messages()) == items


def test_a_file_not_named_as_a_part_is_read_alone(sessions):
    items = make_items()
    [path] = record(sessions, items, epoch_offset=OFFSET)
    renamed = path.with_name("pool-day.mcap")
    path.rename(renamed)
    with SessionParts(renamed, sessions) as s:
        assert s.paths == (renamed,) and s.session_id == "pool-day.mcap"  # its name, not its metadata
        assert list(s.messages()) == items


def test_an_empty_last_part_is_left_out_of_the_times(sessions):
    # the message at 1.0 s closes part 1; the recording stops before part 2 gets any
    items = [(C.SETPOINTS, Setpoints(0.125 * k, float(k), 1.0, 0.0)) for k in range(9)]
    paths = record(sessions, items, SPLIT, epoch_offset=OFFSET)
    assert len(paths) == 2
    with SessionReader(paths[1], sessions) as r:
        assert r.message_count == 0
    with SessionParts(paths[1], sessions) as s:
        assert s.start == 0.0 and s.end == 1.0 and s.duration == 1.0
        assert list(s.messages()) == items
        assert s.state_at(5.0) == {C.SETPOINTS: items[-1][1]}
        stream = TelemetryStream()
        sink = StreamSink(stream)
        p = Player(s, stream)
        while not p.at_end:
            p.advance(0.1)
        assert sink.take() == items


def test_parts_that_overlap_in_time_are_merged(sessions):
    # part 1 ends at 1.0 s; a late event stamped 0.5 s is written to part 2 (1.375 s is
    # less than split_duration after it: no third part)
    sp = [(C.SETPOINTS, Setpoints(0.125 * k, float(k), 1.0, 0.0)) for k in range(12)]
    late = (C.EVENTS, Event(0.5, "fins", "late", "stamped early", "warning"))
    again = (C.SETPOINTS, Setpoints(0.5, -1.0, 1.0, 0.0))  # a second setpoint at 0.5 s
    published = sp[:9] + [late, again] + sp[9:]
    paths = record(sessions, published, SPLIT, epoch_offset=OFFSET)
    assert len(paths) == 2
    with SessionReader(paths[1], sessions) as r:
        assert list(r.messages()) == [late, again] + sp[9:]  # the late ones are in part 2
    in_time = sorted(published, key=lambda x: x[1].t)  # at 0.5 s: part 1's setpoint first
    with SessionParts(paths[0], sessions) as s:
        assert list(s.messages()) == in_time
        assert [m for _, m in s.messages(start=0.4, end=0.7)] == \
            [m for _, m in in_time if 0.4 <= m.t < 0.7]
        assert [r.message for r in s.records(reverse=True)] == [m for _, m in in_time][::-1]
        # at equal times the later message (part 2's) is the latest, as in the records
        assert s.state_at(0.6) == brute_state(in_time, 0.6)
        assert s.state_at(0.6) == {C.EVENTS: late[1], C.SETPOINTS: again[1]}
        assert s.state_at(0.5) == {C.EVENTS: late[1], C.SETPOINTS: again[1]}
