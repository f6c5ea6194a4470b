"""Recording a telemetry stream and reading it back; the file checked independently with
the plain mcap reader and jsonschema."""

from __future__ import annotations

import dataclasses
import json
import math
import random
import time

import jsonschema
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer
from session_helpers import FIXTURES, example_message, record, same

import ucat_console
from ucat_console.backend.sessions import files
from ucat_console.backend.sessions.mcap_read import TruncatedSessionError
from ucat_console.backend.sessions.reader import SessionReader
from ucat_console.backend.sessions.recorder import Recorder, RecorderConfig
from ucat_console.telemetry import channels as C
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.messages import BodyState, FinPlan, FinState, Setpoints
from ucat_console.telemetry.stream import TelemetryStream

OFFSET = 1_700_000_000.0


def every_channel(t0: float = 0.0) -> list[tuple[str, object]]:
    """One example message per channel, at times t0, t0 + 0.5, ..."""
    return [
        (ch, example_message(cls, k=i, t=t0 + 0.5 * i))
        for i, (ch, cls) in enumerate(C.CHANNELS.items())
    ]


def body(t: float, x: float = 0.0) -> BodyState:
    return BodyState(t, (x, 2.0, 3.0), (1.0, 0.0, 0.0, 0.0), (0.3, 0.0, 0.0), (0.0, 0.0, 0.1), 3.0)


def test_every_channel_round_trips_through_recorder_and_reader(sessions):
    items = every_channel()
    [path] = record(sessions, items, epoch_offset=OFFSET)
    with SessionReader(path, sessions) as r:
        back = list(r.messages())
        assert set(r.channels) == set(C.CHANNELS)
        assert r.message_count == len(items)
    assert len(back) == len(items)
    for (ch, msg), (ch2, msg2) in zip(items, back):
        assert ch == ch2
        assert same(msg, msg2), ch
    assert any(isinstance(v, float) and math.isnan(v)
               for _, m in back for v in vars(m).values())  # NaN came back as NaN


def test_file_checked_with_plain_mcap_reader_and_jsonschema(sessions):
    items = every_channel()
    events = [m for c, m in items if c == C.EVENTS]
    bodies = [m for c, m in items if c == C.BODY_STATE]
    bodies.append(body(20.0, x=1.5))
    items.append((C.BODY_STATE, bodies[-1]))
    [path] = record(sessions, items, epoch_offset=OFFSET, notes="pool day",
                    config_toml="[loop.mpc]\nlam_st = 5.0\n", weights={"lam_st": 5.0, "lam_f": 1.5})
    fox_tf = json.loads((FIXTURES / "foxglove" / "FrameTransform.json").read_text())
    fox_log = json.loads((FIXTURES / "foxglove" / "Log.json").read_text())
    with open(path, "rb") as fh:
        reader = make_reader(fh)
        header = reader.get_header()
        assert header.profile == "ucat_console"
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        topics = {ch.topic: ch for ch in summary.channels.values()}
        assert set(topics) == set(C.CHANNELS) | {
            "foxglove/scene", "foxglove/log",
            *(f"foxglove/tf/{f}" for f in ("odom", "odom_ned", "base_link", "base_link_frd",
                                            "fin0", "fin1", "fin2", "fin3"))}
        for ch in topics.values():  # every channel has a JSON schema
            schema = summary.schemas[ch.schema_id]
            assert schema.encoding == "jsonschema" and ch.message_encoding == "json"
        # chunks no bigger than 256 KiB
        assert all(ci.uncompressed_size <= 256 * 1024 for ci in summary.chunk_indexes)
        meta = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        assert meta["notes"] == {"text": "pool day"}
        assert meta["config"] == {"toml": "[loop.mpc]\nlam_st = 5.0\n"}
        assert meta["weights"] == {"lam_st": "5.0", "lam_f": "1.5"}
        assert meta["version"]["ucat_console"] == ucat_console.__version__
        assert meta["session"]["epoch_offset"] == repr(OFFSET)
        assert set(meta["frames"]) == {"map", "odom", "odom_ned", "base_link_frd", "base_link",
                                       "fin0", "fin1", "fin2", "fin3"}
        assert "NED" in meta["frames"]["odom_ned"] and "FRD" in meta["frames"]["base_link_frd"]
        tf, logs, scenes = [], [], []
        for schema, channel, message in reader.iter_messages():
            obj = json.loads(message.data)
            stamp = obj.get("timestamp") if channel.topic.startswith("foxglove/") else None
            expected_ns = None if stamp is None else stamp["sec"] * 10**9 + stamp["nsec"]
            if channel.topic.startswith("foxglove/tf/"):
                assert channel.topic == "foxglove/tf/" + obj["child_frame_id"]  # one channel each
                jsonschema.validate(obj, fox_tf)
                assert set(obj) <= set(fox_tf["properties"])
                assert message.log_time == expected_ns
                tf.append(obj)
            elif channel.topic == "foxglove/scene":
                jsonschema.validate(obj, json.loads(schema.data))
                scenes.append(obj)
            elif channel.topic == "foxglove/log":
                jsonschema.validate(obj, fox_log)
                assert set(obj) <= set(fox_log["properties"])
                assert message.log_time == expected_ns
                logs.append(obj)
            else:
                jsonschema.validate(obj, json.loads(schema.data),
                                    cls=jsonschema.Draft202012Validator)
                # nanoseconds since the UNIX epoch: (t + offset) * 1e9, both times
                t = obj["t"]
                assert message.log_time == message.publish_time == round((t + OFFSET) * 1e9)
    # the static map -> odom -> odom_ned and base_link -> base_link_frd first, then one
    # transform per finite body pose (the example pose has a NaN: no transform) and one per
    # fin state with a finite angle
    assert [(x["parent_frame_id"], x["child_frame_id"]) for x in tf[:3]] == [
        ("map", "odom"), ("odom", "odom_ned"), ("base_link", "base_link_frd")]
    poses = [x for x in tf if x["child_frame_id"] == "base_link"]
    assert len(poses) == 1
    # the pose in ENU and FLU axes: NED (1.5, 2, 3) is ENU (2, 1.5, -3); the identity attitude
    # (body axes along north, east, down) is base_link's x north, y west, z up: a quarter
    # turn about z from ENU, (w, z) = (cos, sin) of pi/4
    assert poses[0]["parent_frame_id"] == "odom"
    assert poses[0]["translation"] == {"x": 2.0, "y": 1.5, "z": -3.0}
    assert poses[0]["rotation"] == pytest.approx({"x": 0.0, "y": 0.0, "z": math.sqrt(0.5), "w": math.sqrt(0.5)})
    assert poses[0]["timestamp"] == {"sec": 1_700_000_020, "nsec": 0}
    fins = {x["child_frame_id"] for x in tf if x["parent_frame_id"] == "base_link_frd"}
    assert fins == {f"fin{c.split('/')[1]}" for c, m in items  # the channel's fin
                    if c.endswith("/state") and c.startswith("fin/") and math.isfinite(m.angle)}
    assert len(fins) >= 2
    [scene] = scenes  # the hull in the body frame, a blade in each fin's frame
    assert [e["frame_id"] for e in scene["entities"]] == ["base_link_frd"] + [f"fin{i}" for i in range(4)]
    assert [x["level"] for x in logs] == [
        ("debug", "info", "warning", "error", "fatal").index(e.level) + 1 for e in events
    ]
    assert logs[0]["name"] == events[0].source
    assert logs[0]["message"] == f"{events[0].code}: {events[0].message}"


def test_notes_set_while_recording_replace_the_first(sessions):
    stream = TelemetryStream()
    rec = Recorder(stream, directory=sessions)
    rec.start(notes="first")
    stream.publish(C.SETPOINTS, Setpoints(time.time(), 0.3, 1.0, 0.0))
    rec.set_notes("second")
    [path] = rec.stop()
    with SessionReader(path, sessions) as r:
        assert r.notes == "second"


def test_split_by_duration_new_part_same_session(sessions):
    # messages every 0.125 s (exact in binary); a part spans at most 1 s of messages
    items = [(C.SETPOINTS, Setpoints(0.125 * k, float(k), 1.0, 0.0)) for k in range(40)]
    paths = record(sessions, items, RecorderConfig(split_duration=1.0))
    # part n starts at the message after the one that reached 1 s past its first:
    # k = 0..8, 9..17, 18..26, 27..35, 36..39
    assert [files.parse_part_name(p)[1] for p in paths] == [1, 2, 3, 4, 5]
    counts, ids = [], set()
    for i, p in enumerate(paths, 1):
        with SessionReader(p, sessions) as r:
            counts.append(r.message_count)
            ids.add(r.session_id)
            assert r.part == i
            assert set(r.channels) == set(C.CHANNELS)  # each part is self-contained
            assert [m.velocity for _, m in r.messages()] == [
                float(k) for k in range(9 * (i - 1), min(40, 9 * i))
            ]
    assert counts == [9, 9, 9, 9, 4]
    assert len(ids) == 1


def test_split_by_size(sessions):
    rng = random.Random(3)
    items = [(C.fin_state(k % 4),
              FinState(0.01 * k, k % 4, rng.random(), rng.random(), rng.random(), float(k)))
             for k in range(6000)]
    cfg = RecorderConfig(split_size=64 * 1024, chunk_size=4096, split_duration=1e5)
    paths = record(sessions, items, cfg)
    assert len(paths) >= 2
    got = []
    for p in paths[:-1]:
        assert p.stat().st_size >= 64 * 1024
    for p in paths:
        with SessionReader(p, sessions) as r:
            got += [m.rate_cmd for _, m in r.messages()]
    assert got == [float(k) for k in range(6000)]  # nothing lost or reordered across parts


def test_queue_overflow_is_counted_and_reported_as_an_event(sessions):
    stream = TelemetryStream()
    seen: list[Event] = []
    stream.subscribe(lambda ch, m: seen.append(m), channels=[C.EVENTS])
    rec = Recorder(stream, RecorderConfig(queue_size=1), directory=sessions)
    rec.start()
    n = 20_000
    for k in range(n):
        stream.publish(C.SETPOINTS, Setpoints(0.001 * k, 0.0, 0.0, 0.0))
    rec.stop()
    stats = rec.stats()
    assert stats.dropped > 0
    overflow = [e for e in seen if e.code == "queue_overflow"]
    assert overflow and all(e.source == "recorder" for e in overflow)
    assert sum(e.data["dropped"] for e in overflow) == stats.dropped
    assert overflow[-1].data["total"] == stats.dropped
    # every message is in the file or counted as dropped
    [path] = rec.paths
    with SessionReader(path, sessions) as r:
        counts = r.message_counts()
    assert counts[C.SETPOINTS] + counts[C.EVENTS] == stats.written
    assert 0 < n - counts[C.SETPOINTS] <= stats.dropped


def test_messages_published_at_once_beyond_the_queue_are_dropped_and_counted_exactly(sessions):
    """Batches larger than the queue: the recorder keeps what fits, in order, and counts the
    rest; every message is in the file or counted, none twice."""
    stream = TelemetryStream()
    rec = Recorder(stream, RecorderConfig(queue_size=7), directory=sessions)
    rec.start()
    n, batch = 5000, 25
    for k in range(0, n, batch):
        stream.publish_many([(C.SETPOINTS, Setpoints(0.001 * j, 0.0, 0.0, float(j))) for j in range(k, k + batch)])
    rec.stop()
    stats = rec.stats()
    assert stats.dropped >= (n // batch) * (batch - 7)  # at most the queue's size of each batch fits
    [path] = rec.paths
    with SessionReader(path, sessions) as r:
        kept = [m.yaw_rate for c, m in r.messages() if c == C.SETPOINTS]
    assert len(kept) + stats.dropped == n
    assert kept == sorted(kept) and len(set(kept)) == len(kept)
    assert all(j % batch < 7 for j in kept)  # the first ones of a batch are the ones kept


def test_state_at_and_time_ranges_match_brute_force(sessions):
    rng = random.Random(7)
    items = []
    for k in range(3000):
        t = 0.01 * k
        items.append((C.BODY_STATE, body(t, x=float(k))))
        if k % 10 == 0:
            items.append((C.fin_state(k % 4), FinState(t, k % 4, 0.1, 0.2, 0.3, float(k))))
        if k % 700 == 350:
            items.append((C.EVENTS, Event(t, "operator", "marker", f"m{k}", "info")))
    cfg = RecorderConfig(chunk_size=4096)  # many chunks
    [path] = record(sessions, items, cfg, epoch_offset=OFFSET)
    with SessionReader(path, sessions) as r:
        assert r.start == 0.0 and abs(r.end - 29.99) < 1e-9
        for t in [-1.0, 0.0, 0.005, 3.5, 3.505, 7.0, 10.0, 29.99, 40.0] + [
            rng.uniform(0, 30) for _ in range(15)
        ]:
            expected = {}
            for ch, m in items:
                if m.t <= t + 1e-12:
                    expected[ch] = m
            got = r.state_at(t)
            assert got.keys() == expected.keys(), t
            assert all(got[c] == expected[c] for c in got), t
        # [start, end) time range
        got = [m for _, m in r.messages([C.EVENTS, C.fin_state(2)], start=3.5, end=17.5)]
        want = [m for c, m in items
                if c in (C.EVENTS, C.fin_state(2)) and 3.5 <= m.t < 17.5]
        assert got == want
        assert [e.message for e in r.events()] == ["m350", "m1050", "m1750", "m2450"]
        assert r.state_at(5.0, [C.EVENTS]) == {C.EVENTS: items_event(items, "m350")}


def items_event(items, text):
    return next(m for c, m in items if c == C.EVENTS and m.message == text)


# ------------------------------------------------------------------ refusals
def test_non_mcap_file_is_refused(sessions):
    p = sessions / "notes.mcap"
    p.write_text("this is not a recording\n")
    with pytest.raises(ValueError, match="not an MCAP file"):
        SessionReader(p, sessions)


def test_path_outside_the_sessions_directory_is_refused(sessions, tmp_path):
    [path] = record(sessions, every_channel())
    outside = tmp_path / "elsewhere.mcap"
    outside.write_bytes(path.read_bytes())
    with pytest.raises(ValueError, match="outside the sessions directory"):
        SessionReader(outside, sessions)
    with pytest.raises(ValueError, match="outside the sessions directory"):
        SessionReader(sessions / ".." / "elsewhere.mcap", sessions)


def _foreign(path, topic, schema_name, encoding="jsonschema"):
    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start()
        sid = w.register_schema(schema_name, encoding, b'{"type": "object"}')
        cid = w.register_channel(topic, "json", sid)
        w.add_message(cid, log_time=1, data=b"{}", publish_time=1)
        w.finish()


def test_foreign_mcap_is_refused(sessions):
    p = sessions / "camera.mcap"
    _foreign(p, "/camera/image", "sensor_msgs/Image")
    with pytest.raises(ValueError, match="foreign channel '/camera/image'"):
        SessionReader(p, sessions)
    q = sessions / "impostor.mcap"
    _foreign(q, C.BODY_STATE, "other.Pose")
    with pytest.raises(
        ValueError, match="not a session file: channel 'body/state' has schema 'other.Pose'"
    ):
        SessionReader(q, sessions)


def test_truncated_and_corrupted_files_are_refused_with_clear_messages(sessions):
    items = [(C.BODY_STATE, body(0.01 * k, float(k))) for k in range(3000)]
    [path] = record(sessions, items, RecorderConfig(chunk_size=4096))
    data = path.read_bytes()
    cut = sessions / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(TruncatedSessionError, match="sessions repair"):
        SessionReader(cut, sessions)
    # flip bytes inside the data section (the summary stays readable): reads fail clearly
    with SessionReader(path, sessions) as r:
        ci = r._summary.chunk_indexes[len(r._summary.chunk_indexes) // 2]
    bad = bytearray(data)
    mid = ci.chunk_start_offset + ci.chunk_length // 2
    bad[mid: mid + 16] = bytes(16)
    broken = sessions / "broken.mcap"
    broken.write_bytes(bytes(bad))
    with SessionReader(broken, sessions) as r:
        with pytest.raises(ValueError, match="corrupted data"):
            list(r.messages())


# ------------------------------------------------------------------ files of encoding 1
def test_a_session_written_by_encoding_1_reads_back_the_same_messages(sessions):
    """A file the recorder wrote before encoding 2 (fixtures/legacy_v1.py says how it was
    made): arrays for vectors, 1e999 for infinities, numeric seeds."""
    import importlib.util
    import shutil

    spec = importlib.util.spec_from_file_location("legacy_v1", FIXTURES / "legacy_v1.py")
    legacy_v1 = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(legacy_v1)
    src = FIXTURES / "20231114-221320-legacy-v1_001.mcap"
    shutil.copy(src, sessions / src.name)
    with open(src, "rb") as fh:  # it is what encoding 1 wrote
        summary = make_reader(fh).get_summary()
        docs = [json.loads(s.data) for s in summary.schemas.values()
                if s.name.startswith("ucat_console.")]
        assert docs and not any("$id" in d for d in docs)
    with open(src, "rb") as fh:
        raw = b"".join(m.data for _, c, m in make_reader(fh).iter_messages(topics=[C.BODY_STATE]))
        assert b"1e999" in raw and b'"position":[' in raw
    expected = sorted(legacy_v1.messages(), key=lambda item: item[1].t)  # file order
    # the IMU's acceleration was written in standard gravities (accel_g); it reads in m/s^2
    expected = [(ch, dataclasses.replace(m, accel=tuple(9.80665 * v for v in m.accel)) if ch == C.IMU else m)
                for ch, m in expected]
    # the plans were written before they carried their fin's lag: it reads as not recorded
    expected = [(ch, dataclasses.replace(m, lag=math.nan) if isinstance(m, FinPlan) else m) for ch, m in expected]
    with SessionReader(sessions / src.name, sessions) as r:
        back = list(r.messages())
        assert r.notes == "written by encoding 1"
        assert r.state_at(10.0)[C.fin_plan(0)].seed == 17029223188912930816
    assert len(back) == len(expected)
    for (ch, msg), (ch2, msg2) in zip(expected, back):
        assert ch == ch2
        assert same(msg, msg2), ch


def test_fin_transforms_turn_each_mount_by_its_measured_angle_and_skip_a_non_finite_one(sessions):
    """Each fin state's transform is its mount's orientation times a turn by the measured
    angle about the mount's z axis (the general quaternion product), at the mount's
    position; a NaN or infinite angle gives no transform and the recording goes on."""
    from ucat_console.backend.sessions.foxglove import robot_geometry
    from ucat_console.robot.rotations import quaternion_multiply

    rng = random.Random(3)
    angles = [(i % 4, rng.uniform(-1.2, 1.2)) for i in range(12)]
    items = [(C.fin_state(fin), FinState(1.0 + 0.1 * k, fin, a, 0.0, 0.0, 0.0)) for k, (fin, a) in enumerate(angles)]
    items += [(C.fin_state(0), FinState(3.0, 0, math.inf, 0.0, 0.0, 0.0)),
              (C.fin_state(1), FinState(3.1, 1, math.nan, 0.0, 0.0, 0.0)),
              (C.SETPOINTS, Setpoints(3.2, 0.3, 1.0, 0.0))]
    [path] = record(sessions, items, epoch_offset=OFFSET)
    mounts = robot_geometry().fin_mounts
    with open(path, "rb") as fh:
        got = [json.loads(m.data) for _, ch, m in make_reader(fh).iter_messages(
            topics=[f"foxglove/tf/fin{i}" for i in range(4)], log_time_order=True)]
    assert len(got) == len(angles)
    for tf, (fin, angle) in zip(got, angles):
        position, orientation = mounts[fin]
        w, x, y, z = quaternion_multiply(orientation, (math.cos(angle / 2), 0.0, 0.0, math.sin(angle / 2)))
        assert tf["child_frame_id"] == f"fin{fin}" and tf["parent_frame_id"] == "base_link_frd"
        assert [tf["rotation"][k] for k in "wxyz"] == pytest.approx([w, x, y, z], abs=1e-12)
        assert [tf["translation"][k] for k in "xyz"] == pytest.approx(list(position), abs=1e-15)
    with SessionReader(path, sessions) as r:
        back = list(r.messages())
    assert len(back) == len(items)  # the two non-finite fin states are recorded, and what follows
    assert math.isinf(back[-3][1].angle) and back[-1][0] == C.SETPOINTS


def test_every_channel_is_written_in_log_time_order(sessions):
    """A closed-loop recording with events reported late (a device's event stamped before
    messages already written, the way a driver's fault reaches the stream): on every channel,
    derived ones included, the log times never go back; a late message keeps its own time
    in the message and as its MCAP publish time."""
    from collections import defaultdict

    from ucat_console.backend.loop.closed_loop import ClosedLoop
    from ucat_console.backend.loop.config import LoopConfig
    from ucat_console.backend.sim_robot_io import SimRobotIO
    from ucat_console.control.allocation import BodySetpoints

    stream = TelemetryStream()
    rec = Recorder(stream, directory=sessions, epoch_offset=OFFSET)
    loop = ClosedLoop(LoopConfig(mode="baseline"), SimRobotIO(depth=1.0, velocity=0.1), stream,
                      setpoints=BodySetpoints(velocity=0.1, depth=1.0))
    rec.start()
    loop.run_until(1.0)
    late = [Event(t=0.5, source="epos2.1", code="emcy", message="late", level="error"),
            Event(t=0.2, source="imu", code="silence", message="later still", level="warning")]
    for event in late:
        stream.publish(C.EVENTS, event)
    loop.run_until(1.5)
    [path] = rec.stop()
    times: dict[str, list[int]] = defaultdict(list)
    late_events = []
    with open(path, "rb") as fh:
        for _, channel, message in make_reader(fh).iter_messages(log_time_order=False):
            times[channel.topic].append(message.log_time)
            if channel.topic == C.EVENTS and json.loads(message.data)["message"] in ("late", "later still"):
                late_events.append(message)
    assert {C.EVENTS, "foxglove/log", "foxglove/tf/base_link", "foxglove/tf/fin0"} <= set(times)
    for topic, ns in times.items():
        assert ns == sorted(ns), topic
    assert [m.publish_time for m in late_events] == [round((e.t + OFFSET) * 1e9) for e in late]
    assert late_events[1].log_time >= late_events[0].log_time > late_events[1].publish_time
    with SessionReader(path, sessions) as r:  # the reader gives the messages' own times
        got = [m for ch, m in r.messages([C.EVENTS]) if m.message in ("late", "later still")]
    assert got == late
