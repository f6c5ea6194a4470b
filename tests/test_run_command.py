"""`ucat-console run --headless`: the supervisor without the page, armed at once, on the
simulated robot, as an unattended run starts it."""

from __future__ import annotations

import re
from pathlib import Path

from ucat_console.backend.sessions import files
from ucat_console.backend.sessions.reader import SessionReader
from ucat_console.cli import main

ROOT = Path(__file__).resolve().parents[1]


def test_a_headless_run_swims_records_and_reports(tmp_path: Path, monkeypatch, capsys) -> None:
    monkeypatch.setattr(files, "DEFAULT_SESSIONS_DIR", tmp_path)
    code = main(["run", "--config", str(ROOT / "config" / "sim-tuned.toml"), "--headless", "--fast",
                 "--duration", "10", "--mode", "baseline", "--velocity", "0.2", "--depth", "0.5"])
    out = capsys.readouterr().out
    assert code == 0, out
    assert out.index("loading the planners") < out.index("headless run: mode baseline")
    distance = float(re.search(r"distance ([0-9.]+) m", out).group(1))
    assert distance > 0.4  # it swam: 10 s armed towards 0.2 m/s from rest (noise alone: < 0.1 m)
    (recorded,) = re.findall(r"recorded (\S+)", out)  # armed at once: recorded from arming
    assert Path(recorded).parent == tmp_path.resolve()
    with SessionReader(recorded, tmp_path) as r:
        # from the moment of arming (the run's loop time then, late on a busy machine: the
        # fast loop runs before the arming command reaches it) to 10 s after it
        (armed,) = [e for e in r.events() if e.code == "armed"]
        assert r.start <= armed.t + 1e-6
        assert r.end >= armed.t + 10.0 - 0.05  # --duration counts from arming
        assert r.duration >= r.end - armed.t - 1e-6
