"""The performance table made from the benchmarks' JSON files (``ucat-console bench report``)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from ucat_console.bench import report

ROOT = Path(__file__).resolve().parents[2]
MACHINE = {"cpu_model": "Test CPU 9000", "logical_cpus": 4, "python": "3.11.7", "numba": "0.68.1"}


def write(directory: Path, name: str, data: dict) -> None:
    (directory / f"{name}.json").write_text(json.dumps({**data, "machine": MACHINE}))


def test_the_table_holds_the_files_figures_and_names_the_cpu(tmp_path: Path) -> None:
    write(tmp_path, "sim", {"realtime_factor": {"headless": {"mpc": 1234.4, "baseline": 987.6},
                                                "subscribed": {"mpc": 500.0, "baseline": 401.2}}})
    write(tmp_path, "sessions", {"throughput": {"rate_msgs_per_s": 45678.9, "dropped": 0},
                                 "seek": {"hours": 1.0, "median_ms": 4.44, "p95_ms": 9.96}})
    text = report.table(tmp_path)
    assert "Test CPU 9000, 4 logical CPUs" in text
    assert "| 1,234x, 988x |" in text  # headless, in the file's mode order
    assert "| 500x, 401x |" in text
    assert "45,679 messages/s (0)" in text
    assert "4.4 / 10.0 ms" in text
    assert "bench mpc" not in text  # no file, no row


def test_a_file_of_another_shape_is_refused_naming_it(tmp_path: Path) -> None:
    write(tmp_path, "ui", {"pages": "not a list"})
    with pytest.raises(ValueError, match="ui.json"):
        report.table(tmp_path)
    with pytest.raises(ValueError, match="no benchmark files"):
        report.table(tmp_path / "empty")


def test_the_block_is_replaced_between_its_markers_only() -> None:
    text = f"before\n{report.START}\nold\n{report.END}\nafter\n"
    assert report.replace_block(text, "new", "x") == f"before\n{report.START}\nnew\n{report.END}\nafter\n"
    with pytest.raises(ValueError, match="README.md: needs exactly one pair"):
        report.replace_block("no markers", "new", "README.md")


@pytest.mark.parametrize("doc", ["README.md", "docs/performance.md"])
def test_the_docs_table_is_the_committed_benchmark_files(doc: str) -> None:
    """The table in the docs is what ``bench report`` makes of benchmarks/*.json: a figure
    changed in one and not the other fails here (run ``bench report --write``)."""
    text = (ROOT / doc).read_text()
    assert report.replace_block(text, report.table(ROOT / "benchmarks"), doc) == text


def test_the_tracking_rows_over_seeds_give_each_modes_worst_case(tmp_path: Path) -> None:
    def goals(**worst: float) -> dict:
        return {"goals": {k.replace("__", "/"): {"worst": v} for k, v in worst.items()}}

    write(tmp_path, "tracking_seeds", {"seeds": list(range(10)), "quick": True, "cases": {"nominal": {
        "baseline": goals(depth_step__heading_all_deg=1.23, straight__heading_all_deg=0.71),
        "mpc": goals(depth_step__heading_all_deg=23.46, straight__heading_all_deg=7.8)}}})
    write(tmp_path, "tracking_cases", {"seeds": [0, 1], "quick": True, "cases": {
        "weak_fin": {"mpc": goals(depth_step__heading_all_deg=13.18)},
        "heavy_1pc": {"mpc": goals(straight__depth_dev=0.0981)}}})
    text = report.table(tmp_path)
    assert "the depth step, from its start, over 10 seeds (half-length manoeuvres), the worst (deg) | " \
           "baseline 1.2, mpc 23.5 | <= 5 |" in text
    assert "| baseline 0.7, mpc 7.8 | <= 3 |" in text
    assert "half speed: heading error through the depth step, worst of 2 seeds (deg) | mpc 13.2 | <= 10 |" in text
    assert "1 % heavy: depth error from 30 s, worst of 2 seeds (m) | mpc 0.10 | <= 0.1 |" in text
    assert "1 % light" not in text  # a case not run, no row


def test_the_mpc_rows_include_the_shipped_configurations_plan(tmp_path: Path) -> None:
    row = {"n": 500, "solver": "numba", "stage": "two_stage", "formulation": "paper", "mean_cost": 1.9,
           "p50_us": 37.54, "p99_us": 53.0, "solves": 605}
    write(tmp_path, "mpc", {"runs": [row], "shipped": {**row, "p50_us": 468.7, "p99_us": 1482.1,
                                                        "config": "sim-tuned", "centre_rate": 3.0,
                                                        "centre_grid": 12}})
    text = report.table(tmp_path)
    assert "| 37.5 / 53.0 us | <= 80 / <= 200 us |" in text
    assert "as sim-tuned runs it (the cycle centred by its cost over a 12 x 12 grid): p50 / p99 | " \
           "468.7 / 1482.1 us |" in text
    write(tmp_path, "mpc", {"runs": [row]})  # a file from before: no such row
    assert "as sim-tuned runs it" not in report.table(tmp_path)
