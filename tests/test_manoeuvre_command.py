"""`ucat-console run --headless --manoeuvre`: a scripted manoeuvre from the shell, recorded,
its segments' figures printed and read back by `sessions compare --segments marker`;
`ucat-console manoeuvres list` and a bad file refused before anything starts."""

from __future__ import annotations

import re
from pathlib import Path

from ucat_console.backend.sessions import files
from ucat_console.backend.sessions.reader import SessionReader
from ucat_console.cli import main

SCRIPT = """\
depth = 0.5
settle = 1.0
measure = 3.0

[[segment]]
label = "slow"
velocity = 0.1

[[segment]]
label = "fast"
velocity = 0.25
"""


def test_a_headless_manoeuvre_records_its_segments_and_compare_reads_them(tmp_path: Path, monkeypatch,
                                                                          capsys) -> None:
    monkeypatch.setenv(files.SESSIONS_ENV, str(tmp_path))
    script = tmp_path / "short.toml"
    script.write_text(SCRIPT)
    code = main(["run", "--config", "sim-tuned", "--headless", "--fast", "--manoeuvre", str(script)])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "short: 2 segments, 8 s" in out  # its plan, and its length is the run's
    printed = re.findall(r"short #(\d) (\w+): ([0-9.]+) J/m \[", out)
    assert [(k, label) for k, label, _ in printed] == [("1", "slow"), ("2", "fast")]
    assert all(float(epm) > 0.0 for _, _, epm in printed)
    assert "manoeuvre short: completed; 2 of 2 segments measured" in out
    (recorded,) = re.findall(r"recorded (\S+)", out)
    with SessionReader(recorded, tmp_path) as r:
        events = list(r.events())
        armed = next(e.t for e in events if e.code == "armed")
        assert r.end - armed < 8.0 + 3.0  # the script's length, not an open-ended run
    segments = [e for e in events if e.code == "segment"]
    assert [e.data["label"] for e in segments] == ["slow", "fast"]
    assert segments[1].data["figures"]["speed"]["value"] > segments[0].data["figures"]["speed"]["value"]
    assert sum(e.code == "marker" for e in events) == 5

    code = main(["sessions", "compare", recorded, "--segments", "marker", "--out", str(tmp_path / "cmp")])
    out = capsys.readouterr().out
    assert code == 0, out
    # each measure window is a row (the first settle marker may fall on the session's start,
    # which is no cut: that window is then the run's start)
    for label in ("short #1/2 slow: measure", "short #2/2 fast: settle", "short #2/2 fast: measure",
                  "short: end (completed)"):
        assert f"(marker: {label})" in out


def test_manoeuvres_list_shows_the_shipped_plans_and_a_bad_file_is_refused_first(tmp_path: Path,
                                                                                capsys) -> None:
    assert main(["manoeuvres", "list"]) == 0
    out = capsys.readouterr().out
    for name in ("e4_ladder", "fig8_circle", "depth_step", "ab_modes"):
        assert f"ucat-console run --headless --manoeuvre {name}" in out
    assert "E4 rung 0.4 m/s: velocity 0.4 m/s, depth 1 m" in out
    bad = tmp_path / "bad.toml"
    bad.write_text(SCRIPT.replace("velocity = 0.25", "velocity = 2.5"))
    assert main(["run", "--headless", "--fast", "--manoeuvre", str(bad)]) == 2
    err = capsys.readouterr()
    assert f"{bad}: segment 1 (line 9: [[segment]]), line 11: velocity: 2.5 is out of range" in err.err
    assert "preparing the compiled code" not in err.out  # refused before anything started
    assert main(["run", "--manoeuvre", "e4_ladder"]) == 2
    assert "--manoeuvre: only with --headless" in capsys.readouterr().err
