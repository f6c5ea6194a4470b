"""``ucat-console sessions ...`` and ``ucat-console replay``."""

from __future__ import annotations

import csv

from session_helpers import record

from ucat_console.backend.sessions.recorder import RecorderConfig
from ucat_console.cli import main
from ucat_console.telemetry import channels as C
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.messages import FinPlan, Setpoints


def _session(sessions):
    items = [(C.SETPOINTS, Setpoints(0.5 * k, 0.1 * k, 1.0, 0.0)) for k in range(10)]
    items.append((C.EVENTS, Event(5.0, "operator", "marker", "here", "info")))
    return record(sessions, items, label="cli", notes="from the cli test",
                  wall_time=1_700_000_000.0)


def test_list_info_export(sessions, tmp_path, capsys):
    [path] = _session(sessions)
    assert main(["sessions", "list", "--dir", str(sessions)]) == 0
    out = capsys.readouterr().out
    assert "20231114-221320-cli" in out and "from the cli test" in out
    assert "0:00:05" in out  # messages from t=0 to the event at t=5.0
    assert main(["sessions", "info", "20231114-221320-cli", "--dir", str(sessions)]) == 0
    out = capsys.readouterr().out
    assert "body/setpoints" in out and "11 messages" in out
    dest = tmp_path / "out"
    assert main(["sessions", "export", path.name, "--topics", "body/setpoints,events",
                 "--format", "csv", "--out", str(dest), "--dir", str(sessions)]) == 0
    with open(dest / "body_setpoints.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [float(r["velocity"]) for r in rows] == [0.1 * k for k in range(10)]
    assert (dest / "events.csv").exists()


def test_errors_are_reported_with_exit_status_2(sessions, tmp_path, capsys):
    (sessions / "junk.mcap").write_text("junk")
    assert main(["sessions", "info", "junk.mcap", "--dir", str(sessions)]) == 2
    assert "not an MCAP file" in capsys.readouterr().err
    outside = tmp_path / "outside.mcap"
    outside.write_text("x")
    assert main(["sessions", "info", str(outside), "--dir", str(sessions)]) == 2
    assert "not an MCAP file" in capsys.readouterr().err  # read where it is, and refused for what it is
    [path] = _session(sessions)
    assert main(["replay", str(path), "--weights", "lam_q=1", "--dir", str(sessions)]) == 2
    assert "lam_q: unknown weight" in capsys.readouterr().err


def test_the_commands_read_a_session_file_the_user_names_outside_the_sessions_folder(sessions, tmp_path, capsys):
    """A path typed at the shell is read wherever it is: a split session's part in another
    folder (its parts beside it), by info, export, compare (which reads it, then finds no
    power to compare) and repair; a bare name is still looked for in the sessions folder."""
    items = [(C.SETPOINTS, Setpoints(0.1 * k, 0.1 * k, 1.0, 0.0)) for k in range(30)]
    parts = record(sessions, items, RecorderConfig(split_duration=1.0, chunk_size=4096), label="away")
    assert len(parts) > 1
    downloads = tmp_path / "downloads"
    downloads.mkdir()
    for p in parts:
        p.rename(downloads / p.name)
    first = downloads / parts[0].name
    assert main(["sessions", "info", str(first), "--dir", str(sessions)]) == 0
    out = capsys.readouterr().out
    assert f"{len(parts)} parts in {downloads}" in out and "30 messages" in out
    dest = tmp_path / "out"
    assert main(["sessions", "export", str(first), "--topics", "body/setpoints", "--out", str(dest)]) == 0
    with open(dest / "body_setpoints.csv", newline="") as fh:
        assert len(list(csv.DictReader(fh))) == 30
    assert main(["sessions", "compare", str(first), str(first), "--out", str(tmp_path / "cmp")]) == 2
    assert "has no power messages" in capsys.readouterr().err  # read, then judged
    assert main(["sessions", "info", first.name, "--dir", str(sessions)]) == 2
    assert "no such session file" in capsys.readouterr().err
    last = downloads / parts[-1].name
    last.write_bytes(last.read_bytes()[:-40])  # cut in its summary: truncated
    assert main(["sessions", "repair", str(last), "--dir", str(sessions)]) == 0
    out = capsys.readouterr().out
    assert "repaired" in out and (downloads / (last.stem + ".orig.mcap")).is_file()


def test_repair_command(sessions, capsys):
    items = [(C.SETPOINTS, Setpoints(0.01 * k, 0.0, 1.0, 0.0)) for k in range(3000)]
    [path] = record(sessions, items, RecorderConfig(chunk_size=4096))
    assert main(["sessions", "repair", str(path), "--dir", str(sessions)]) == 0
    assert "nothing to repair" in capsys.readouterr().out
    path.write_bytes(path.read_bytes()[:20_000])
    assert main(["sessions", "list", "--dir", str(sessions)]) == 0
    assert "truncated" in capsys.readouterr().out
    assert main(["sessions", "repair", str(path), "--dir", str(sessions)]) == 0
    out = capsys.readouterr().out
    assert "repaired" in out and ".orig" in out


def test_replay_command_prints_a_table_and_writes_csv(sessions, tmp_path, capsys):
    plan = FinPlan(0.0, 1, "mpc", (-0.4, 0.1), 0.3, 0.0, (0.5, -0.5, 2.0, 2.0),
                   (0.6, -0.6, 3.0, 3.0), (0.6, 3.0, 0.0, 3.0), 1.0, 0.1, 0.1, 0.0, 0.1, 0.3,
                   (-0.3, 0.1), 0.002, False)
    [path] = record(sessions, [(C.fin_plan(1), plan)],
                    config_toml="[loop.mpc]\nn_samples = 32\nmax_iter = 5\n")
    out_csv = tmp_path / "cf.csv"
    assert main(["replay", str(path), "--weights", "lam_st=2.0", "--out", str(out_csv),
                 "--dir", str(sessions)]) == 0
    out = capsys.readouterr().out
    assert "lam_st=2" in out and "St rec" in out and "all" in out
    with open(out_csv, newline="") as fh:
        [row] = list(csv.DictReader(fh))
    assert row["fin"] == "1" and float(row["recorded_st"]) == 0.3
    # recorded power from the recorded plan: both strokes at 3 rad/s -> 7 * 0.3^3 W
    assert abs(float(row["recorded_power"]) - 7 * 0.3**3) < 1e-12


def _split_session(sessions):
    """Setpoints every 0.25 s for 4 s and a fin plan every 0.5 s, in parts of 1 s."""
    plans = [FinPlan(0.5 * k + 0.1, 1, "mpc", (-0.4, 0.1), 0.3, 0.0, (0.5, -0.5, 2.0, 2.0),
                     (0.6, -0.6, 3.0, 3.0), (0.6, 3.0, 0.0, 3.0), 1.0, 0.1, 0.1, 0.0, 0.1, 0.3,
                     (-0.3, 0.1), 0.002, False, seed=k) for k in range(8)]
    items = [(C.SETPOINTS, Setpoints(0.25 * k, 0.1 * k, 1.0, 0.0)) for k in range(17)]
    items += [(C.fin_plan(1), p) for p in plans]
    items.sort(key=lambda x: x[1].t)
    paths = record(sessions, items, RecorderConfig(split_duration=1.0), label="split",
                   config_toml="[loop.mpc]\nn_samples = 32\nmax_iter = 5\n", wall_time=1_700_000_000.0)
    assert len(paths) >= 3
    return paths, plans


def test_info_export_and_replay_cover_every_part_of_a_split_session(sessions, tmp_path, capsys):
    paths, plans = _split_session(sessions)
    sid = "20231114-221320-split"
    for arg in (sid, paths[1].name, str(paths[-1])):
        assert main(["sessions", "info", arg, "--dir", str(sessions)]) == 0
        out = capsys.readouterr().out
        assert f"session {sid}: {len(paths)} parts" in out
        assert "25 messages" in out  # 17 setpoints and 8 plans, over every part
        assert all(p.name in out for p in paths)
    dest = tmp_path / "out"
    assert main(["sessions", "export", paths[2].name, "--topics", "body/setpoints",
                 "--out", str(dest), "--dir", str(sessions)]) == 0
    with open(dest / "body_setpoints.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [float(r["t"]) for r in rows] == [0.25 * k for k in range(17)]
    out_csv = tmp_path / "cf.csv"
    assert main(["replay", str(paths[0]), "--weights", "lam_st=2.0", "--out", str(out_csv),
                 "--dir", str(sessions)]) == 0
    assert f"{len(plans)} plans replayed" in capsys.readouterr().out
    with open(out_csv, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [float(r["t"]) for r in rows] == [p.t for p in plans]


def test_a_split_session_with_a_missing_part_is_refused_by_the_cli(sessions, capsys):
    paths, _ = _split_session(sessions)
    paths[1].unlink()
    assert main(["sessions", "info", "20231114-221320-split", "--dir", str(sessions)]) == 2
    err = capsys.readouterr().err
    assert paths[1].name in err and "missing" in err


def test_a_replay_process_reads_under_the_consoles_review_limits(sessions):
    """The counterfactual replay's child process puts the console's ``[review]`` limits in
    force, not the defaults: a plan over the configured message size is refused there."""
    from ucat_console.backend.sessions import limits
    from ucat_console.backend.sessions.replay_job import ReplayJob

    plan = FinPlan(0.0, 1, "mpc" + " " * 6000, (-0.4, 0.1), 0.3, 0.0, (0.5, -0.5, 2.0, 2.0),
                   (0.6, -0.6, 3.0, 3.0), (0.6, 3.0, 0.0, 3.0), 1.0, 0.1, 0.1, 0.0, 0.1, 0.3,
                   (-0.3, 0.1), 0.002, False)
    [path] = record(sessions, [(C.fin_plan(1), plan)], config_toml="[loop.mpc]\nn_samples = 32\nmax_iter = 5\n")
    job = ReplayJob(path.name, sessions, {"lam_st": 2.0}, nice=0, review=limits.ReviewConfig(max_message=4096))
    assert job.wait(120.0)
    assert "review.max_message" in job.error and job.result is None
    job = ReplayJob(path.name, sessions, {"lam_st": 2.0}, nice=0)  # the defaults read it
    assert job.wait(120.0)
    assert "review.max_message" not in job.error
