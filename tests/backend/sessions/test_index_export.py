"""The session index and the CSV export."""

from __future__ import annotations

import csv
import json
import math

import pytest
from session_helpers import example_message, record

from ucat_console.backend.sessions.export import columns, csv_name, export_csv
from ucat_console.backend.sessions.index import list_sessions, session_parts
from ucat_console.backend.sessions.reader import SessionReader
from ucat_console.backend.sessions.recorder import RecorderConfig
from ucat_console.telemetry import channels as C
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.messages import BodyState, Setpoints, Status

OFFSET = 1_700_000_000.0


def test_csv_columns_are_flattened_from_the_type():
    assert columns(BodyState) == [
        "log_time_ns", "t",
        "position.0", "position.1", "position.2",
        "orientation.0", "orientation.1", "orientation.2", "orientation.3",
        "velocity.0", "velocity.1", "velocity.2",
        "rates.0", "rates.1", "rates.2",
        "depth",
    ]
    assert columns(Status) == ["log_time_ns", "t", "armed", "mode", "pilot", "failsafes",
                               "late_plans", "source"]
    assert csv_name("fin/0/state") == "fin_0_state.csv"


def test_csv_export_matches_the_recorded_values(sessions, tmp_path):
    bodies = [example_message(BodyState, k=k, t=0.1 * k) for k in range(20)]
    statuses = [Status(0.05 + k, k % 2 == 0, "mpc", "p1", ("dvl_silent", "late") if k else (),
                       k, "sim") for k in range(3)]
    events = [Event(0.3, "operator", "marker", "a, \"quoted\" note", "info", {"x": 1})]
    items = [(C.BODY_STATE, b) for b in bodies] + [(C.STATUS, s) for s in statuses] + \
        [(C.EVENTS, e) for e in events]
    items.sort(key=lambda x: x[1].t)
    [path] = record(sessions, items, epoch_offset=OFFSET)
    out = tmp_path / "csv"
    with SessionReader(path, sessions) as r:
        result = export_csv(r, [C.BODY_STATE, C.STATUS, C.EVENTS, C.POWER], out)
    assert {c: n for c, (_, n) in result.items()} == {
        C.BODY_STATE: 20, C.STATUS: 3, C.EVENTS: 1, C.POWER: 0
    }
    with open(out / "body_state.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    for b, row in zip(bodies, rows, strict=True):
        assert int(row["log_time_ns"]) == round((b.t + OFFSET) * 1e9)
        assert float(row["t"]) == b.t
        for i in range(3):
            x = float(row[f"position.{i}"])
            assert (math.isnan(x) and math.isnan(b.position[i])) or x == b.position[i]
        d = float(row["depth"])
        assert (math.isnan(d) and math.isnan(b.depth)) or d == b.depth
    with open(out / "status.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["armed"] for r in rows] == ["true", "false", "true"]
    assert [r["failsafes"] for r in rows] == ["", "dvl_silent;late", "dvl_silent;late"]
    with open(out / "events.csv", newline="") as fh:
        [row] = list(csv.DictReader(fh))
    assert row["message"] == 'a, "quoted" note' and json.loads(row["data"]) == {"x": 1}
    assert (out / "power.csv").read_text().strip() == ",".join(columns(C.CHANNELS[C.POWER]))


def test_export_refuses_unknown_channels(sessions, tmp_path):
    [path] = record(sessions, [(C.SETPOINTS, Setpoints(0.0, 0.1, 1.0, 0.0))])
    with SessionReader(path, sessions) as r, pytest.raises(ValueError, match="'fins/9'"):
        export_csv(r, ["fins/9"], tmp_path / "o")


def test_index_lists_sessions_with_parts_duration_notes_events_and_truncation(sessions):
    items = [(C.SETPOINTS, Setpoints(0.25 * k, 0.0, 1.0, 0.0)) for k in range(20)]
    items.insert(5, (C.EVENTS, Event(1.2, "operator", "marker", "x", "info")))
    items.insert(9, (C.EVENTS, Event(2.0, "failsafe", "silence", "dvl", "error")))
    a = record(sessions, items, RecorderConfig(split_duration=2.0), label="split",
               notes="two parts", wall_time=1_700_000_000.0)
    b = record(sessions, [(C.SETPOINTS, Setpoints(0.01 * k, 0.0, 1.0, 0.0)) for k in range(3000)],
               RecorderConfig(chunk_size=4096), label="cut", notes="killed",
               wall_time=1_700_000_100.0)
    b[0].write_bytes(b[0].read_bytes()[: b[0].stat().st_size // 2])
    (sessions / "README.txt").write_text("not a session")
    listed = list_sessions(sessions)
    assert [s.session_id for s in listed] == ["20231114-221320-split", "20231114-221500-cut"]
    split, cut = listed
    # the event at t=2.0 ends part 1 (0..2.0); part 2 holds 2.0..4.0; part 3 4.25..4.75
    assert [p.part for p in split.parts] == [1, 2, 3]
    assert split.duration == pytest.approx(2.0 + 2.0 + 0.5)
    assert split.events == 2 and split.notes == "two parts" and not split.truncated
    assert split.size == sum(p.stat().st_size for p in a)
    assert cut.truncated and cut.duration is None and cut.notes == "killed"
    assert session_parts("20231114-221320-split", sessions) == a
    with pytest.raises(ValueError, match="no files"):
        session_parts("nope", sessions)
