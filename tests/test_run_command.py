"""`ucat-console run --headless`: the supervisor without the page, armed at once, on the
simulated robot, as an unattended run starts it."""

from __future__ import annotations

import json
import re
import tomllib
from pathlib import Path

import pytest

import ucat_console
from ucat_console import shipped
from ucat_console.backend.sessions import files
from ucat_console.backend.sessions.reader import SessionReader
from ucat_console.backend.supervisor import CommandRefused, Supervisor
from ucat_console.cli import main
from ucat_console.config import AppConfig, load_config

ROOT = Path(__file__).resolve().parents[1]


def test_a_headless_run_swims_records_and_reports(tmp_path: Path, monkeypatch, capsys) -> None:
    monkeypatch.setenv(files.SESSIONS_ENV, str(tmp_path))
    code = main(["run", "--config", "sim-tuned", "--headless", "--fast",
                 "--duration", "10", "--mode", "baseline", "--velocity", "0.2", "--depth", "0.5"])
    out = capsys.readouterr().out
    assert code == 0, out
    # the compiled code is ready before the loop runs (loaded here: the test run prepared it)
    assert out.index("preparing the compiled code") < out.index("compiled code ready") \
        < out.index("headless run: mode baseline")
    distance = float(re.search(r"distance ([0-9.]+) m", out).group(1))
    assert distance > 0.4  # it swam: 10 s armed towards 0.2 m/s from rest (noise alone: < 0.1 m)
    # the battery's figure beside the shaft's: the drives draw more than the shaft gives the water
    shaft = float(re.search(r"shaft .*mean power ([0-9.]+) W", out).group(1))
    battery = float(re.search(r"battery power .*mean ([0-9.]+) W", out).group(1))
    assert battery > shaft > 0.0
    (recorded,) = re.findall(r"recorded (\S+)", out)  # armed at once: recorded from arming
    assert Path(recorded).parent == tmp_path.resolve()
    with SessionReader(recorded, tmp_path) as r:
        # from the moment of arming (the run's loop time then, late on a busy machine: the
        # fast loop runs before the arming command reaches it) to 10 s after it
        (armed,) = [e for e in r.events() if e.code == "armed"]
        assert r.start <= armed.t + 1e-6
        assert r.end >= armed.t + 10.0 - 0.05  # --duration counts from arming
        assert r.duration >= r.end - armed.t - 1e-6


def test_the_sessions_folder_flag_wins_and_a_failed_start_leaves_no_session_file(
        tmp_path: Path, monkeypatch, capsys) -> None:
    env_dir, flag_dir = tmp_path / "env", tmp_path / "flag"
    monkeypatch.setenv(files.SESSIONS_ENV, str(env_dir))
    args = ["run", "--config", "sim-tuned", "--headless", "--fast", "--duration", "0.5", "--record",
            "--sessions-dir", str(flag_dir)]
    assert main(args) == 0, capsys.readouterr()
    (recorded,) = re.findall(r"recorded (\S+)", capsys.readouterr().out)
    assert Path(recorded).parent == flag_dir.resolve()
    assert not env_dir.exists()

    # the arming the issue saw fail: the recording (--record) had started before it
    def refused(self, who=None) -> None:
        raise CommandRefused("the loop did not answer in time; nothing was done")

    monkeypatch.setattr(Supervisor, "arm", refused)
    def parts() -> list[Path]:  # the session files (the first run's report is not one)
        return sorted(p for p in flag_dir.iterdir() if p.suffix == ".mcap")

    before = parts()
    assert main(args) == 2
    captured = capsys.readouterr()
    assert "recording session" in captured.out  # it had started ...
    assert "did not answer in time" in captured.err
    assert parts() == before  # ... and is gone
    assert not [p for p in flag_dir.iterdir() if p.name.endswith(".report.html") and p.stem.split(".")[0] not in
                {b.stem.rsplit("_", 1)[0] for b in before}]  # nor a report of it


def test_a_configuration_is_named_or_given_as_a_file(tmp_path: Path, monkeypatch) -> None:
    tuned = load_config("sim-tuned")
    with open(ROOT / "ucat_console" / "configs" / "sim-tuned.toml", "rb") as fh:
        lam_f = tomllib.load(fh)["loop"]["mpc"]["lam_f"]
    assert tuned.loop.mpc.lam_f == lam_f != AppConfig().loop.mpc.lam_f  # the repository's file, by name
    copy = tmp_path / "mine.toml"
    copy.write_text(shipped.config_path("sim-tuned").read_text())
    assert load_config(copy) == tuned
    monkeypatch.chdir(tmp_path)
    assert load_config("mine.toml") == tuned  # a file in the working folder, by its suffix
    assert load_config("./mine.toml") == tuned
    with pytest.raises(ValueError, match=r"'mine' is neither a shipped configuration \(robot, "
                                         r"sim-devices, sim-tuned\) nor a file"):
        load_config("mine")
    with pytest.raises(ValueError, match="nope.toml: configuration file not found"):
        load_config("nope.toml")


def test_recordings_go_to_the_user_data_folder_unless_told_otherwise(tmp_path: Path, monkeypatch,
                                                                    capsys) -> None:
    monkeypatch.delenv(files.SESSIONS_ENV, raising=False)
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))  # platformdirs on Linux
    assert files.sessions_dir() == (tmp_path / "data" / "ucat-console" / "sessions").resolve()
    assert not files.sessions_dir().is_relative_to(Path(ucat_console.__file__).parent)
    monkeypatch.setenv(files.SESSIONS_ENV, str(tmp_path / "env"))
    assert files.sessions_dir() == (tmp_path / "env").resolve()
    assert files.sessions_dir(tmp_path / "given") == (tmp_path / "given").resolve()

    assert main(["paths"]) == 0
    out = capsys.readouterr().out
    assert "sessions" in out and str((tmp_path / "env").resolve()) in out
    assert str(shipped.config_path("robot")) in out
    layout = re.search(r"foxglove layout\s+(\S+)", out).group(1)
    assert json.loads(Path(layout).read_text())["layout"]  # the Foxglove layout, found


def test_the_battery_energy_integrates_readings_and_leaves_out_missing_ones() -> None:
    from ucat_console.cli.run import BatteryEnergy

    b = BatteryEnergy()
    assert "no readings" in b.line()
    for t, w in ((0.0, 10.0), (1.0, 20.0), (2.0, float("nan")), (3.0, 4.0), (4.0, 4.0)):
        b.add(t, w)
    # 15 J over the first second, the NaN and the seconds either side of it left out, 4 J after
    assert b.energy == pytest.approx(19.0) and b.covered == pytest.approx(2.0) and b.skipped == 1
    assert "energy 19.0 J, mean 9.50 W over 2.0 s (1 readings" in b.line()
