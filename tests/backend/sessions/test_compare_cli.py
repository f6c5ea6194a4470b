"""``ucat-console sessions compare``: two recordings made here, their segments, refusals."""

from __future__ import annotations

import csv

import pytest
from session_helpers import record
from synthetic_run import run_items

from ucat_console.cli import main
from ucat_console.telemetry.events import Event


def _rows(path):
    with open(path, newline="") as fh:
        return {(r["label"], r["figure"]): r for r in csv.DictReader(fh)}


def test_compare_two_sessions_writes_markdown_csv_and_png(sessions, tmp_path, capsys):
    [a] = record(sessions, run_items(), label="slow", wall_time=1_700_000_000.0)
    [b] = record(sessions, run_items(scale=2.0, speed=0.25), label="fast", wall_time=1_700_000_100.0)
    out = tmp_path / "cmp"
    assert main(["sessions", "compare", a.name, b.name, "--out", str(out), "--dir", str(sessions)]) == 0
    printed = capsys.readouterr().out
    assert "NOT COMPARABLE" in printed
    rows = _rows(out / "compare.csv")
    sa, sb = "20231114-221320-slow", "20231114-221500-fast"
    assert float(rows[(sa, "energy_per_metre")]["value"]) == pytest.approx(20.0)
    assert float(rows[(sb, "energy_per_metre")]["value"]) == pytest.approx(32.0)  # 8 W at 0.25 m/s
    assert float(rows[(sb, "cost_of_transport")]["value"]) == pytest.approx(32.0 / 22.0)
    assert rows[(sa, "power")]["not_comparable"] == ""
    # mean speeds 0.25 and 0.2 m/s differ by more than the 0.02 m/s bound
    assert "mean speed differs by 0.05" in rows[(sb, "power")]["not_comparable"]
    md = (out / "compare.md").read_text()
    assert "| 20231114-221500-fast |" in md and "**not comparable**" in md and "32 " in md
    assert (out / "compare.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (out / "compare.png").stat().st_size > 10_000


def test_compare_segments_of_one_session_aligned_at_an_event(sessions, tmp_path, capsys):
    events = (Event(5.0, "operator", "marker", "start | of *test*", "info"),
              Event(10.0, "loop", "mode", "controller mpc -> baseline", "info"),
              Event(12.0, "operator", "marker", "after switch", "info"))
    [a] = record(sessions, run_items(events=events), label="one", wall_time=1_700_000_000.0)
    out = tmp_path / "seg"
    assert main(["sessions", "compare", a.name, "--segments", "mode", "--align", "marker",
                 "--out", str(out), "--dir", str(sessions)]) == 0
    rows = _rows(out / "compare.csv")
    labels = sorted({k[0] for k in rows})
    assert labels == ["20231114-221320-one #1 (start)", "20231114-221320-one #2 (mode: controller mpc -> baseline)"]
    first = rows[(labels[0], "power")]
    assert (float(first["t0"]), float(first["t1"])) == (0.0, 10.0)
    for label in labels:
        assert float(rows[(label, "power")]["value"]) == pytest.approx(4.0)
        # the stroke at the cut (10 s) counts in the second segment only: 20 strokes a fin in each
        assert float(rows[(label, "st_mae")]["value"]) == pytest.approx(0.05)
    md = (out / "compare.md").read_text()
    assert "0.0–10.0" in md and "10.0–19.9" in md
    # a segment without the alignment event is refused, naming it
    assert main(["sessions", "compare", a.name, "--segments", "marker", "--align", "mode",
                 "--out", str(out), "--dir", str(sessions)]) == 2
    assert "no 'mode' event to align at" in capsys.readouterr().err


def test_compare_refuses_a_file_that_is_not_a_session_naming_it(sessions, tmp_path, capsys):
    [a] = record(sessions, run_items(duration=3.0), label="ok", wall_time=1_700_000_000.0)
    bogus = sessions / "notes.mcap"
    bogus.write_text("this is not a recording\n")
    out = tmp_path / "x"
    assert main(["sessions", "compare", a.name, str(bogus), "--out", str(out), "--dir", str(sessions)]) == 2
    err = capsys.readouterr().err
    assert "notes.mcap" in err
    assert not (out / "compare.md").exists()
    assert main(["sessions", "compare", a.name, "--out", str(out), "--dir", str(sessions)]) == 2
    assert "needs --segments" in capsys.readouterr().err


def test_compare_is_of_the_battery_power_with_the_estimate_beside_it(sessions, tmp_path, capsys):
    [a] = record(sessions, run_items(battery_from=0.0), label="slow", wall_time=1_700_000_000.0)
    [b] = record(sessions, run_items(scale=2.0, speed=0.25, battery_from=0.0), label="fast",
                 wall_time=1_700_000_100.0)
    out = tmp_path / "cmp"
    assert main(["sessions", "compare", a.name, b.name, "--out", str(out), "--dir", str(sessions)]) == 0
    assert "power: electrical (battery)" in capsys.readouterr().out
    rows = _rows(out / "compare.csv")
    sa, sb = "20231114-221320-slow", "20231114-221500-fast"
    # the drives' 12 W at 0.2 m/s and 24 W at 0.25 m/s; the estimate's 4 and 8 W beside them
    assert float(rows[(sa, "energy_per_metre")]["value"]) == pytest.approx(60.0)
    assert float(rows[(sb, "energy_per_metre")]["value"]) == pytest.approx(96.0)
    assert float(rows[(sb, "mech_energy_per_metre")]["value"]) == pytest.approx(32.0)
    assert rows[(sb, "power")]["power_source"] == "electrical (battery)"
    assert rows[(sb, "mech_power")]["power_source"] == "mechanical (shaft estimate)"
    assert rows[(sb, "speed")]["power_source"] == ""
    md = (out / "compare.md").read_text()
    assert "Power: electrical (battery)" in md and "96 " in md


def test_compare_with_a_run_without_electrical_readings_is_of_the_estimates_labelled_so(sessions, tmp_path, capsys):
    [a] = record(sessions, run_items(), label="old", wall_time=1_700_000_000.0)
    [b] = record(sessions, run_items(battery_from=0.0), label="new", wall_time=1_700_000_100.0)
    out = tmp_path / "cmp"
    assert main(["sessions", "compare", a.name, b.name, "--out", str(out), "--dir", str(sessions)]) == 0
    label = "mechanical (shaft estimate): no electrical readings in 20231114-221320-old"
    assert f"power: {label}" in capsys.readouterr().out
    rows = _rows(out / "compare.csv")
    # like with like: both runs' estimate (4 W at 0.2 m/s), not one run's battery against the other's estimate
    for s in ("20231114-221320-old", "20231114-221500-new"):
        assert float(rows[(s, "energy_per_metre")]["value"]) == pytest.approx(20.0)
        assert rows[(s, "power")]["power_source"] == label
