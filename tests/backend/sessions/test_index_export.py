"""The session index and the CSV export."""

from __future__ import annotations

import csv
import json
import math

import pytest
from session_helpers import BIG_SEED, awkward_items, example_message, record, same

from ucat_console.backend.sessions import images
from ucat_console.backend.sessions.export import columns, csv_name, data_resource, export_csv
from ucat_console.backend.sessions.index import list_sessions, session_parts
from ucat_console.backend.sessions.reader import SessionReader
from ucat_console.backend.sessions.schema import field_specs
from ucat_console.backend.sessions.recorder import RecorderConfig
from ucat_console.telemetry import channels as C
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.messages import BodyState, FinPlan, Power, Setpoints, Status

#: the channels a CSV file holds (every one but the camera's pictures)
TABULAR = {c: cls for c, cls in C.CHANNELS.items() if not images.is_image(cls)}

OFFSET = 1_700_000_000.0


def test_csv_columns_are_mcap_paths_flattened_from_the_type():
    assert columns(BodyState) == [
        "log_time_ns", "t",
        "position.x", "position.y", "position.z",
        "orientation.x", "orientation.y", "orientation.z", "orientation.w",  # as in the MCAP messages
        "velocity.x", "velocity.y", "velocity.z",
        "rates.x", "rates.y", "rates.z",
        "depth",
    ]
    assert columns(Power)[2:6] == ["per_fin[0]", "per_fin[1]", "per_fin[2]", "per_fin[3]"]
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
        for i, name in enumerate("xyz"):
            x = float(row[f"position.{name}"])
            assert (math.isnan(x) and math.isnan(b.position[i])) or x == b.position[i]
        d = float(row["depth"])
        assert (math.isnan(d) and math.isnan(b.depth)) or d == b.depth
        for i, name in enumerate("wxyz"):  # held w first, written by name
            q = float(row[f"orientation.{name}"])
            assert (math.isnan(q) and math.isnan(b.orientation[i])) or q == b.orientation[i]
    with open(out / "status.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["armed"] for r in rows] == ["true", "false", "true"]
    assert [json.loads(r["failsafes"]) for r in rows] == [[], ["dvl_silent", "late"]] + \
        [["dvl_silent", "late"]]
    with open(out / "events.csv", newline="") as fh:
        [row] = list(csv.DictReader(fh))
    assert row["message"] == 'a, "quoted" note' and json.loads(row["data"]) == {"x": 1}
    assert (out / "power.csv").read_text().strip() == ",".join(columns(C.CHANNELS[C.POWER]))
    side = json.loads((out / "body_state.columns.json").read_text())
    # a Frictionless Tabular Data Resource: the CSV, its dialect and its Table Schema
    assert side["$schema"] == "https://datapackage.org/profiles/2.0/dataresource.json"
    assert (side["type"], side["path"], side["format"], side["channel"]) == (
        "table", "body_state.csv", "csv", C.BODY_STATE)
    fields = side["schema"]["fields"]
    by = {c["name"]: c for c in fields}
    assert [c["name"] for c in fields] == columns(BodyState)
    assert by["position.z"]["unit"] == "m" and "NED" in by["position.z"]["description"]
    assert by["rates.z"]["unit"] == "rad/s" and by["depth"]["type"] == "number"
    assert by["log_time_ns"] == {**by["log_time_ns"], "type": "integer", "unit": "ns",
                                 "constraints": {"required": True}}
    plan = by_name(data_resource(C.fin_plan(0), FinPlan)["schema"]["fields"])
    assert [plan[f"u.{n}"]["unit"] for n in ("d_1", "d_2", "w_1", "w_2")] == ["rad", "rad", "rad/s", "rad/s"]


def by_name(fields: list[dict]) -> dict[str, dict]:
    return {f["name"]: f for f in fields}


def side_of(directory, channel: str) -> dict:
    return json.loads((directory / csv_name(channel).replace(".csv", ".columns.json")).read_text())


_TABLE_TYPES = {"number", "integer", "boolean", "string", "array", "object"}


def _parse(cell: str, field: dict, schema: dict):
    """A CSV cell read back by its Table Schema field alone, as the Table Schema
    specification (v2) reads it (independently of the exporter)."""
    assert field["type"] in _TABLE_TYPES, field
    if cell in field.get("missingValues", schema["missingValues"]):
        return None
    kind = field["type"]
    if kind == "number":
        special = {"nan": math.nan, "inf": math.inf, "-inf": -math.inf}
        return special[cell.lower()] if cell.lower() in special else float(cell)
    if kind == "integer":
        return int(cell)
    if kind == "boolean":
        assert cell in field["trueValues"] + field["falseValues"], (field["name"], cell)
        return cell in field["trueValues"]
    if kind in ("array", "object"):
        value = json.loads(cell)
        assert isinstance(value, list if kind == "array" else dict)
        return value
    return cell


def test_csv_keeps_infinities_large_seeds_empty_text_and_missing_values(sessions, tmp_path):
    items = awkward_items()
    [path] = record(sessions, items, epoch_offset=OFFSET)
    with SessionReader(path, sessions) as r:
        with pytest.raises(ValueError, match="camera/image holds pictures"):
            export_csv(r, list(C.CHANNELS), tmp_path)
        export_csv(r, list(TABULAR), tmp_path)
    for channel, cls in TABULAR.items():
        side = side_of(tmp_path, channel)
        cols = side["schema"]["fields"]
        with open(tmp_path / side["path"], newline="") as fh:
            rows = list(csv.reader(fh))
        assert rows[0] == [c["name"] for c in cols]
        want = [m for c, m in items if c == channel]
        assert len(rows) - 1 == len(want)
        for msg, cells in zip(want, rows[1:]):
            values = dict(zip(rows[0], (_parse(x, c, side["schema"]) for x, c in zip(cells, cols))))
            for name, value in values.items():
                if by_name(cols)[name].get("constraints", {}).get("required"):
                    assert value is not None, (channel, name)
            for spec in field_specs(cls):
                v = getattr(msg, spec.name)
                got = [values[p] for p in spec.paths()]
                if spec.kind == "floats":
                    assert same(None if all(g is None for g in got) else tuple(got), v), spec.name
                elif spec.kind == "seq":
                    assert tuple(got[0]) == v, spec.name
                else:
                    assert same(got[0], v), (channel, spec.name)
    dtypes = {}  # one dtype per column, the same in every file of a message type
    for channel, cls in TABULAR.items():
        for c in side_of(tmp_path, channel)["schema"]["fields"]:
            dtypes.setdefault((cls.__name__, c["name"]), set()).add((c["type"], c["dtype"]))
    assert all(len(d) == 1 for d in dtypes.values())
    plan = side_of(tmp_path, C.fin_plan(1))["schema"]["fields"]
    assert {c["name"]: (c["type"], c["dtype"]) for c in plan}["seed"] == ("integer", "decimal")
    with open(tmp_path / "fin_1_plan.csv", newline="") as fh:
        assert [r["seed"] for r in csv.DictReader(fh)][-1] == str(BIG_SEED)
    with open(tmp_path / "status.csv", newline="") as fh:
        last = list(csv.DictReader(fh))[-1]
    assert last["pilot"] == "" and last["failsafes"] == "[]"


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
