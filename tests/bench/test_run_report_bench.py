"""``bench run-report`` on a short session: the report is timed, written after a stop in its
own process, and the figures go into the performance table."""

from __future__ import annotations

import json
from pathlib import Path

from ucat_console.bench.report import table
from ucat_console.cli import main


def test_bench_run_report_measures_a_short_session(tmp_path: Path, capsys) -> None:
    out = tmp_path / "run_report.json"
    assert main(["bench", "run-report", "--seconds", "20", "--segments", "2", "--repeats", "1",
                 "--dir", str(tmp_path), "--json", str(out)]) == 0
    d = json.loads(out.read_text())
    assert d["background_written"] is True
    assert d["report_s_median"] > 0.0 and d["report_bytes"] > 10_000
    assert not any("figures" in m for m in d["missing"])  # the session has its figures
    assert "`bench run-report`" in table(tmp_path)
