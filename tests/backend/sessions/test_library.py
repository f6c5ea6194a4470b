"""The run library: sessions recorded through the real recorder indexed (facts and figures
against values known by hand), every query term against sessions it should and should not
match, bad queries refused by name, the index rebuilt from the files, changed and vanished
files followed, tags and notes through the sidecar, and `sessions find --json`."""

from __future__ import annotations

import calendar
import json
import shutil
import sqlite3
from pathlib import Path

import pytest
from session_helpers import record
from synthetic_run import run_items
from support import SHORT_LADDER

from ucat_console.backend.sessions import library_read, sidecar
from ucat_console.backend.sessions.library import DB_NAME, SCHEMA_VERSION, Library
from ucat_console.backend.sessions.library_query import QueryError
from ucat_console.cli import main
from ucat_console.telemetry import channels as C
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.messages import Status

DAY1 = calendar.timegm((2026, 11, 24, 10, 0, 0)) + 0.0  # UTC
DAY2 = calendar.timegm((2026, 12, 1, 10, 0, 0)) + 0.0


def _toml(mode: str = "mpc", formulation: str = "paper", c_d0: float = 0.05, model: str = "plate") -> str:
    return (f'robot = "sim"\n[loop]\nmode = "{mode}"\n[loop.mpc]\nformulation = "{formulation}"\n'
            f'lam_st = {2.0 if formulation == "paper" else 0.5}\n'
            f'[plant.hydro]\nmodel = "{model}"\nc_d0 = {c_d0}\n')


def _status(mode: str, t: float = 0.05) -> tuple[str, Status]:
    return C.STATUS, Status(t, True, mode, "", (), 0, "sim")


def _folder(d: Path) -> dict[str, str]:
    """Four sessions, their ids by label."""
    ids = {}

    def rec(label: str, items: list, epoch: float, **start) -> None:
        [path] = record(d, sorted(items, key=lambda it: it[1].t), epoch_offset=epoch, label=label,
                        wall_time=epoch, **start)
        ids[label] = path.name.removesuffix("_001.mcap")

    # a fast MPC run in a pool, switched to the baseline half way, a marker, a failsafe
    events = (Event(2.0, "operator", "marker", "fin 2 looks weak", "info"),
              Event(5.0, "loop", "mode", "controller mpc -> baseline", "info", {"from": "mpc", "to": "baseline"}),
              Event(6.0, "failsafe", "depth_limit", "too deep", "error"),
              Event(6.5, "failsafe", "cleared", "depth_limit cleared", "info", {"failsafe": "depth_limit"}))
    rec("fast", [*run_items(10.0, speed=0.2, events=events), _status("mpc")], DAY2,
        notes="weak fin on the left", config_toml=_toml("mpc", c_d0=0.05))
    # a slow baseline run on another plant and formulation, a manoeuvre's segments
    seg = [Event(3.0 + k, "manoeuvre", "segment", f"ladder #{k + 1}", "info",
                 {"manoeuvre": "ladder", "index": k, "label": label}) for k, label in enumerate(("slow", "fast"))]
    rec("slow", [*run_items(10.0, speed=0.1, events=tuple(seg)), _status("baseline")], DAY1,
        notes="calm water", config_toml=_toml("baseline", "closed_stroke", c_d0=0.3))
    # never driven: a status alone
    rec("idle", [_status("mpc"), (C.STATUS, Status(1.0, False, "mpc", "", (), 0, "sim"))], DAY2,
        config_toml=_toml("mpc", model="still_water"))
    # the recorded mode only: no status, no mode event
    rec("plain", run_items(5.0, speed=0.15), DAY2, config_toml=_toml("mpc_sync"))
    return ids


@pytest.fixture(scope="module")
def built(tmp_path_factory) -> tuple[Path, dict[str, str]]:
    d = tmp_path_factory.mktemp("library") / "sessions"
    d.mkdir()
    return d, _folder(d)


@pytest.fixture
def folder(built, tmp_path) -> tuple[Path, dict[str, str]]:
    """A copy of the built folder without its database (each test starts from the files)."""
    d = tmp_path / "sessions"
    shutil.copytree(built[0], d, ignore=shutil.ignore_patterns(DB_NAME + "*"))
    return d, built[1]


def _ids(lib: Library, query: str, **kw) -> set[str]:
    return {r.id for r in lib.find(query, **kw)}


def test_the_index_holds_each_sessions_facts_and_its_figures_over_the_driven_part(folder) -> None:
    d, ids = folder
    with Library(d) as lib:
        report = lib.refresh()
        assert (report.added, report.rebuilt) == (4, "no database")
        fast = lib.get(ids["fast"])
        assert fast.status == "ok" and fast.robot == "sim" and fast.plant == "plate_cd0.05"
        assert fast.formulation == "paper" and fast.modes == ("mpc", "baseline")
        assert fast.markers == 1 and fast.failsafes == ("depth_limit",)
        assert fast.config_hash == library_read.config_hash(_toml("mpc", c_d0=0.05))
        assert fast.notes == "weak fin on the left" and fast.date == "2026-12-01"
        # 4 W of shaft power at 0.2 m/s: 20 J/m; errors 0.02 m/s, 0.05 m, 0.1 rad; half the strokes in
        f = fast.figures
        assert f["epm"] == pytest.approx(20.0, rel=1e-6)
        assert f["epm_lo"] <= f["epm"] <= f["epm_hi"]
        assert f["speed"] == pytest.approx(0.2, rel=1e-6)
        assert f["speed_mae"] == pytest.approx(0.02) and f["depth_mae"] == pytest.approx(0.05)
        assert f["heading_mae"] == pytest.approx(0.1) and f["st_in"] == pytest.approx(50.0)
        slow = lib.get(ids["slow"])
        assert slow.plant == "plate_cd0.3" and slow.formulation == "closed_stroke"
        assert slow.manoeuvre == "ladder" and slow.segments == ("slow", "fast")
        assert slow.figures["epm"] == pytest.approx(40.0, rel=1e-6)
        idle = lib.get(ids["idle"])
        assert idle.plant == "still_water" and all(v is None for v in idle.figures.values())
        assert "never driven" in idle.figures_note or "no power" in idle.figures_note
        assert lib.get(ids["plain"]).modes == ("mpc_sync",)  # from the recorded configuration


QUERIES = [
    ("mode=mpc", {"fast", "idle"}),
    ("mode=baseline", {"fast", "slow"}),
    ("mode!=baseline", {"idle", "plain"}),
    ("mode~sync", {"plain"}),
    ("speed>0.15", {"fast"}),
    ("speed>=0.149", {"fast", "plain"}),
    ("speed<0.12", {"slow"}),
    ("epm<=20.0001", {"fast"}),
    ("plant=plate_cd0.05", {"fast", "plain"}),
    ("plant!=plate_cd0.05", {"slow", "idle"}),
    ("date>=2026-12-01", {"fast", "idle", "plain"}),
    ("date<2026-12-01", {"slow"}),
    ("date=2026-11-24", {"slow"}),
    ('notes~"weak fin"', {"fast"}),
    ("notes~WEAK", {"fast"}),
    ("calm", {"slow"}),
    ("-calm", {"fast", "idle", "plain"}),
    ("formulation=closed_stroke", {"slow"}),
    ("manoeuvre=ladder", {"slow"}),
    ("segment=fast", {"slow"}),
    ("segments>1", {"slow"}),
    ("failsafe=depth_limit", {"fast"}),
    ("failsafes=0", {"slow", "idle", "plain"}),
    ("markers>=1", {"fast"}),
    ("mode=mpc speed>0.15 date>=2026-12-01", {"fast"}),
    ("status=ok", {"fast", "slow", "idle", "plain"}),
    ("", {"fast", "slow", "idle", "plain"}),
]


@pytest.mark.parametrize("query,expected", QUERIES)
def test_each_query_term_matches_the_sessions_it_should_and_no_other(folder, query, expected) -> None:
    d, ids = folder
    with Library(d) as lib:
        lib.refresh()
        assert _ids(lib, query) == {ids[k] for k in expected}


def test_tags_and_the_config_hash_are_found_and_sorting_follows_the_field(folder) -> None:
    d, ids = folder
    with Library(d) as lib:
        lib.refresh()
        assert lib.set_tags(ids["fast"], ["+pool-3", "+draft"]) == ("pool-3", "draft")
        lib.set_tags(ids["slow"], ["pool-3"])
        assert _ids(lib, "tag:pool-3") == {ids["fast"], ids["slow"]}
        assert _ids(lib, "tag:pool-3 -tag:draft") == {ids["slow"]}
        assert _ids(lib, "tags=0") == {ids["idle"], ids["plain"]}
        digest = library_read.config_hash(_toml("baseline", "closed_stroke", c_d0=0.3))
        assert _ids(lib, f"hash={digest[:10]}") == {ids["slow"]}
        by_speed = [r.id for r in lib.find("status=ok", sort="speed", desc=True)]
        assert by_speed[:3] == [ids["fast"], ids["plain"], ids["slow"]] and by_speed[3] == ids["idle"]  # none last


@pytest.mark.parametrize("query,words", [
    ("foo=1", ["'foo=1'", "no such field", "known fields", "speed"]),
    ("speed>fast", ["'speed>fast'", "number", "'fast'"]),
    ("date>=yesterday", ["'date>=yesterday'", "YYYY-MM-DD"]),
    ("speed~1", ["'speed~1'", "number", "text"]),
    ("mode<mpc", ["'mode<mpc'", "several values"]),
    ('notes~"weak', ["quot"]),
    ("speed>", ["'speed>'", "no value"]),
])
def test_a_bad_query_is_refused_naming_the_term_and_what_is_wrong(folder, query, words) -> None:
    d, _ = folder
    with Library(d) as lib:
        lib.refresh()
        with pytest.raises(QueryError) as e:
            lib.find(query)
        for w in words:
            assert w in str(e.value), str(e.value)
        with pytest.raises(QueryError, match="'nope'.*known fields"):
            lib.find("", sort="nope")


def test_values_reach_sql_as_parameters_never_as_its_text(folder) -> None:
    d, _ = folder
    with Library(d) as lib:
        lib.refresh()
        assert _ids(lib, "notes~\"x'; DROP TABLE sessions; --\"") == set()
        assert _ids(lib, "notes~%") == set() and _ids(lib, "notes~_") == set()  # LIKE's wildcards are text
        assert len(lib.find("")) == 4


def test_the_index_is_rebuilt_from_the_files_when_missing_corrupt_or_of_another_version(folder) -> None:
    d, ids = folder
    with Library(d) as lib:
        lib.refresh()
        lib.set_tags(ids["fast"], ["+keep"])
    db = d / DB_NAME
    db.unlink()
    with Library(d) as lib:
        assert lib.refresh().rebuilt == "no database"
        assert _ids(lib, "tag:keep") == {ids["fast"]}  # from the sidecar
    db.write_bytes(b"this is not a database" * 100)
    with Library(d) as lib:
        report = lib.refresh()
        assert report.rebuilt.startswith("unreadable") and report.added == 4
    conn = sqlite3.connect(db)
    conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION + 1}")
    conn.commit()
    conn.close()
    with Library(d) as lib:
        report = lib.refresh()
        assert "schema version" in report.rebuilt and report.added == 4
        assert _ids(lib, "tag:keep") == {ids["fast"]}


def test_a_changed_file_is_read_again_a_vanished_one_dropped_and_nothing_read_when_nothing_changed(
        folder, monkeypatch, tmp_path) -> None:
    d, ids = folder
    with Library(d) as lib:
        lib.refresh()
        assert lib.get(ids["plain"]).figures["speed"] == pytest.approx(0.15, rel=1e-6)
        read = []
        real = library_read.read_facts
        monkeypatch.setattr("ucat_console.backend.sessions.library.read_facts",
                            lambda sid, *a, **kw: read.append(sid) or real(sid, *a, **kw))
        report = lib.refresh()
        assert (report.unchanged, report.added, report.updated, read) == (4, 0, 0, [])
        # the same session's file replaced by a faster run
        other = tmp_path / "other"
        other.mkdir()
        [path] = record(other, run_items(5.0, speed=0.3), epoch_offset=DAY2, label="plain", wall_time=DAY2,
                        config_toml=_toml("mpc_sync"))
        target = d / f"{ids['plain']}_001.mcap"
        shutil.copyfile(path, target)
        (d / f"{ids['idle']}_001.mcap").unlink()
        report = lib.refresh()
        assert (report.updated, report.removed, read) == (1, 1, [ids["plain"]])
        assert lib.get(ids["plain"]).figures["speed"] == pytest.approx(0.3, rel=1e-6)
        assert ids["idle"] not in _ids(lib, "")


def test_tags_and_notes_go_to_the_sidecar_and_come_back_from_it(folder, capsys) -> None:
    d, ids = folder
    sid = ids["fast"]
    with Library(d) as lib:
        lib.refresh()
        lib.set_tags(sid, ["+pool-3", "+draft"])
        lib.set_tags(sid, ["-draft"])
        row = lib.set_notes(sid, "weak fin 2 after the dive", operator="Kati")
        assert row.notes == "weak fin 2 after the dive" and row.operator == "Kati"
        with pytest.raises(ValueError, match="tag 'no good'"):
            lib.set_tags(sid, ["+no good"])
    side = json.loads(sidecar.path_of(d, sid).read_text())
    assert side["tags"] == ["pool-3"] and side["notes"] == "weak fin 2 after the dive"
    assert side["operator"] == "Kati"
    (d / DB_NAME).unlink()
    with Library(d) as lib:
        lib.refresh()
        assert _ids(lib, 'tag:pool-3 notes~"after the dive" operator=kati') == {sid}
    assert main(["sessions", "info", sid, "--dir", str(d)]) == 0
    out = capsys.readouterr().out
    assert "notes: weak fin 2 after the dive" in out and "recorded: weak fin on the left" in out
    assert "tags: pool-3" in out
    # a sidecar edited by hand into something else is said, never read as empty
    sidecar.path_of(d, sid).write_text("[1, 2]")
    with Library(d) as lib:
        lib.refresh()
        row = lib.get(sid)
        assert "expected an object" in row.side_error and row.notes == "weak fin on the left"


def test_sessions_find_json_tag_and_trend_from_the_command_line(folder, capsys, tmp_path) -> None:
    d, ids = folder
    assert main(["sessions", "tag", ids["slow"], "+pool-3", "-draft", "--dir", str(d)]) == 0
    capsys.readouterr()
    assert main(["sessions", "find", "mode=baseline", "--json", "--sort", "speed", "--dir", str(d)]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert [r["id"] for r in rows] == [ids["slow"], ids["fast"]]
    assert rows[0]["tags"] == ["pool-3"] and rows[1]["figures"]["epm"] == pytest.approx(20.0, rel=1e-6)
    assert main(["sessions", "find", "tag:pool-3", "--dir", str(d)]) == 0
    out = capsys.readouterr().out
    assert ids["slow"] in out and ids["fast"] not in out and "calm water" in out
    assert main(["sessions", "find", "bogus>1", "--dir", str(d)]) == 2
    assert "bogus" in capsys.readouterr().err
    out_csv = tmp_path / "trend.csv"
    assert main(["sessions", "trend", "speed", "status=ok", "--by", "loop.mpc.lam_st", "--out", str(out_csv),
                 "--dir", str(d)]) == 0
    lines = out_csv.read_text().splitlines()
    assert lines[0] == "session,start_utc,loop.mpc.lam_st,speed"
    by_group = {line.split(",")[0]: line.split(",")[2] for line in lines[1:]}
    assert by_group == {ids["slow"]: "0.5", ids["fast"]: "2.0", ids["plain"]: "2.0"}  # idle: no speed


def test_the_documentation_names_every_field_a_query_may_use() -> None:
    from ucat_console.backend.sessions.library_query import FIELDS

    text = (Path(__file__).resolve().parents[3] / "docs" / "library.md").read_text()
    assert [f for f in FIELDS if f"`{f}`" not in text] == []


def test_the_configuration_is_named_by_the_recording_else_by_a_known_hash(folder, tmp_path) -> None:
    d, ids = folder
    [path] = record(d, run_items(2.0), epoch_offset=DAY2, label="named", wall_time=DAY2,
                    config_toml=_toml("mpc"), config_name="sim-tuned")
    named = path.name.removesuffix("_001.mcap")
    slow_hash = library_read.config_hash(_toml("baseline", "closed_stroke", c_d0=0.3))
    with Library(d, known_configs={slow_hash: "slow-one", library_read.config_hash(_toml("mpc")): "x"}) as lib:
        lib.refresh()
        assert lib.get(named).config == "sim-tuned"  # the recording's own name wins
        assert lib.get(ids["slow"]).config == "slow-one" and lib.get(ids["fast"]).config == "x"
        assert lib.get(ids["plain"]).config == ""  # a text no name is known for
        assert _ids(lib, "config=sim-tuned") == {named} and _ids(lib, "slow-one") == {ids["slow"]}
    with Library(d) as lib:  # opened without the names: they are gone at the next refresh
        lib.refresh()
        assert lib.get(ids["slow"]).config == "" and lib.get(named).config == "sim-tuned"




@pytest.mark.slow
def test_a_manoeuvre_recorded_by_the_simulated_console_is_indexed(tmp_path, monkeypatch, capsys) -> None:
    from ucat_console.backend.sessions import files

    monkeypatch.setenv(files.SESSIONS_ENV, str(tmp_path))
    script = tmp_path / "short.toml"
    script.write_text(SHORT_LADDER)
    assert main(["run", "--config", "sim-tuned", "--headless", "--fast", "--manoeuvre", str(script)]) == 0
    capsys.readouterr()
    assert main(["sessions", "find", "manoeuvre=short", "--json"]) == 0
    [row] = json.loads(capsys.readouterr().out)
    assert row["status"] == "ok" and row["config"] == "sim-tuned" and row["robot"] == "sim"
    assert row["segments"] == ["slow", "fast"] and "baseline" in row["modes"]
    assert row["plant"] == "plate_cd0.05" and row["markers"] >= 4
    f = row["figures"]
    # a percentile interval of a ratio need not hold the ratio itself on a short run: its ends only
    assert f["epm"] > 0.0 and 0.0 < f["epm_lo"] <= f["epm_hi"] and f["speed"] > 0.0


def test_a_trend_carries_each_runs_interval_and_charts_by_weight_and_by_date(folder) -> None:
    from ucat_console.backend.review import trend

    d, ids = folder
    with Library(d) as lib:
        lib.refresh()
        points = lib.trend("epm", "loop.mpc.lam_st")
        by_id = {p.session_id: p for p in points}
        assert set(by_id) == {ids["fast"], ids["slow"], ids["plain"]}  # idle was never driven
        for p in points:  # the library's interval, around the value
            assert p.lo is not None and p.hi is not None and p.lo <= p.value <= p.hi
        assert all(p.lo is None and p.hi is None for p in lib.trend("speed", "date"))  # no interval kept
        # 4 W at 0.2, 0.1 and 0.15 m/s; lam_st 2.0 (paper) for fast and plain, 0.5 for slow
        c = trend.chart(points, "loop.mpc.lam_st")
        assert list(c.x) == [0.5, 2.0, 2.0] and c.groups == 2 and c.left_out == 0 and c.has_interval
        assert c.value[0] == pytest.approx(40.0, rel=1e-5)
        assert sorted(c.value[1:]) == pytest.approx([20.0, 4.0 / 0.15], rel=1e-5)
        assert c.mean[1] == c.mean[2] == pytest.approx((20.0 + 4.0 / 0.15) / 2, rel=1e-5)
        assert (c.lo <= c.value).all() and (c.value <= c.hi).all()
        by_day = trend.chart(lib.trend("epm", "date"), "date")
        assert by_day.x[0] == pytest.approx(DAY1, abs=60.0) and by_day.groups == 2  # slow ran first
        # a run whose configuration has no such key has no place on the axis: left out, counted
        none = trend.chart(lib.trend("epm", "loop.mpc.lam_d"), "loop.mpc.lam_d")
        assert len(none.x) == 0 and none.left_out == 3


@pytest.mark.parametrize(("figure", "by", "words"), [
    ("password", "date", "trend figure 'password'"),
    ("epm_lo", "date", "trend figure 'epm_lo'"),
    (3, "date", "trend figure '3'"),
    ("epm", "loop.mpc.nope", "trend axis 'loop.mpc.nope'"),
    ("epm", "plant.hydro.c_d0", "trend axis 'plant.hydro.c_d0'"),
    ("epm", None, "trend axis 'None'"),
])
def test_a_trend_choice_outside_the_pages_choices_is_refused_by_name(figure, by, words) -> None:
    from ucat_console.backend.review import trend

    with pytest.raises(ValueError, match="not one of") as e:
        trend.check_choice(figure, by)
    assert words in str(e.value)
    assert trend.check_choice("energy per metre (J/m)", "date") == ("epm", "date")  # the page's label
    assert trend.check_choice("st_in", "loop.mpc.lam_st") == ("st_in", "loop.mpc.lam_st")
