"""`ucat-console experiment` / `sweep`: complete reports that agree with their JSON; bad input."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pytest

from ucat_console.cli import main
from ucat_console.experiments.report import num, render
from ucat_console.experiments.runner import _e6_findings, clean_json, parse_names

_NUMBER = re.compile(r"^-?\d+(\.\d+)?$")


def _leaves(doc: object) -> tuple[list[float], list[str]]:
    nums: list[float] = []
    texts: list[str] = []

    def walk(x: object) -> None:
        if isinstance(x, dict):
            for v in x.values():
                walk(v)
        elif isinstance(x, list):
            for v in x:
                walk(v)
        elif isinstance(x, bool):
            pass
        elif isinstance(x, (int, float)):
            nums.append(float(x))
        elif isinstance(x, str):
            texts.append(x)

    walk(doc)
    return nums, texts


def table_cells(report: str) -> list[str]:
    """Body cells of every Markdown table (header and separator rows left out)."""
    cells: list[str] = []
    rows = [ln for ln in report.splitlines()]
    for i, ln in enumerate(rows):
        if not ln.startswith("|") or ln.startswith("|---"):
            continue
        if i + 1 < len(rows) and rows[i + 1].startswith("|---"):
            continue  # header
        cells += [c.strip() for c in ln.strip("|").split("|")]
    return cells


def check_report_agrees_with_json(report: str, doc: dict) -> int:
    nums, texts = _leaves(doc)
    checked = 0
    for cell in table_cells(report):
        if _NUMBER.match(cell):
            digits = len(cell.split(".")[1]) if "." in cell else 0
            value = float(cell)
            assert any(abs(x - value) <= 0.5 * 10.0**-digits + 1e-9 for x in nums), \
                f"report number {cell} is not in results.json"
            checked += 1
        elif any(ch.isdigit() for ch in cell):
            assert any(cell in t for t in texts), f"report cell {cell!r} is not in results.json"
    return checked


def test_number_format_and_names() -> None:
    assert num(0.12345, 3) == "0.123" and num(None, 2) == "n/a" and num(float("nan"), 1) == "n/a"
    assert parse_names(["e4", "all"]) == ["E4", "E1", "E2", "E3", "E4R", "E5", "E6"]
    with pytest.raises(ValueError, match="E9"):
        parse_names(["E9"])
    assert clean_json({"a": (1.0, float("nan"))}) == {"a": [1.0, None]}


def test_render_reads_only_the_json(tmp_path: Path) -> None:
    doc = {"meta": {"title": "T", "command": "c", "quick": True, "seed": 3, "executor": "x",
                    "finished": "now", "experiments": ["E3"]},
           "experiments": {"E3": {"runtime_s": 1.25, "protocol": {"targets": 2, "speeds": [0.2], "cycles": 5,
                                                                 "seeds": [3]},
                                  "rows": [{"config": "full", "force_error": 0.31234, "st_deviation": 0.02,
                                            "in_range_pct": 88.04, "stability": 1.5, "paper_force_error": 0.1559,
                                            "paper_st_deviation": 0.0285, "paper_in_range_pct": 88.0,
                                            "paper_stability": 1.625}],
                                  "claims": [{"claim": "c", "paper": "p", "ours": "o 1.0", "reproduced": True}]}}}
    text = render(doc)
    assert "| full | 0.1559 | 0.3123 | 0.0285 | 0.0200 | 88.0 | 88.0 | 1.625 | 1.500 |" in text
    assert check_report_agrees_with_json(text, doc) >= 9


def test_savings_only_where_both_runs_track() -> None:
    from ucat_console.experiments.closed_loop_runs import _add_savings
    from ucat_console.experiments.report import sweep_table

    def row(mode: str, mae: float, power: float, lam: float | None) -> dict:
        return {"plant": "p", "v_ref": 0.2, "mode": mode, "lam_st": lam, "lam_d": lam, "power_est": power,
                "power_true": power, "energy_per_metre": 5 * power, "energy_per_metre_true": 5 * power,
                "power_electrical": 3 * power, "energy_per_metre_electrical": 15 * power,
                "velocity_mae": mae, "st_mae": 0.1, "depth_mae": 0.01}

    rows = [row("baseline", 0.01, 0.10, None), row("mpc", 0.02, 0.08, 1.0), row("mpc", 0.12, 0.01, 2.0)]
    _add_savings(rows, ("plant", "v_ref"))
    assert rows[1]["comparable"] and rows[1]["saving_est"] == pytest.approx(20.0)
    assert rows[1]["saving_epm_true"] == pytest.approx(20.0)
    assert rows[1]["saving_epm_el"] == pytest.approx(20.0) and rows[1]["saving_el"] == pytest.approx(20.0)
    # 90 % less power, but 0.12 m/s off the reference: no saving is quoted
    assert not rows[2]["comparable"] and math.isnan(rows[2]["saving_est"])
    text = sweep_table({"rows": rows})
    assert "| 0.2 | mpc | 2.00 | 2.00 | 0.0100 | 0.050 | not comparable | not comparable | 0.1200 |" in text
    assert "| 0.2 | mpc | 1.00 | 1.00 | 0.0800 | 0.400 | 20.0 | 20.0 |" in text
    # a baseline that does not track makes every row of its group not comparable
    rows = [row("baseline", 0.05, 0.10, None), row("mpc", 0.01, 0.08, 1.0)]
    _add_savings(rows, ("plant", "v_ref"))
    assert not rows[1]["comparable"] and "not comparable" in sweep_table({"rows": rows})


def _e6_row(plant: str, v: float, saving: float, *, out: bool = True, comparable: bool = True) -> dict:
    return {"plant": plant, "v_ref": v, "controller": "mpc_closed_id", "baseline_out_of_corridor": out,
            "comparable": comparable, "tracks": comparable, "saving_epm_el": saving, "saving_epm_true": saving}


def test_e6_findings_count_the_target_by_fin_model_and_say_when_the_null_plant_meets_it() -> None:
    res = {"protocol": {"target_pct": 10.0}, "target": {"cases": 5, "comparable": 4, "met": 2},
           "identified": [{"plant": "scale1_plate", "model": "plate"},
                          {"plant": "scale1_still_water", "model": "still_water"}],
           "rows": [_e6_row("scale1_plate", 0.1, 12.0), _e6_row("scale1_plate", 0.2, 5.0),
                    _e6_row("scale1_plate", 0.3, 30.0, comparable=False),
                    _e6_row("scale1_still_water", 0.1, 15.0), _e6_row("scale1_still_water", 0.2, 2.0),
                    _e6_row("scale1_still_water", 0.3, 40.0, out=False)]}
    text = "\n".join(_e6_findings(res))
    assert ("Fin model `plate`: the baseline leaves the corridor in 3 cases, 2 comparable, the target met in 1 "
            "(scale1_plate at 0.1 m/s: 12.0 %).") in text
    assert "Fin model `still_water`: the baseline leaves the corridor in 2 cases, 2 comparable, the target met in 1" in text
    assert "null plant" in text  # met as often where St cannot matter
    res["rows"][3]["saving_epm_el"] = 9.9
    assert "null plant" not in "\n".join(_e6_findings(res))


def test_unknown_experiment_and_impossible_setpoints_exit_non_zero(tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "out"
    assert main(["experiment", "E9", "--out", str(out)]) == 2
    assert "E9" in capsys.readouterr().err
    assert main(["experiment", "E4", "--quick", "--velocities", "0.9", "--out", str(out)]) == 2
    assert "velocity" in capsys.readouterr().err
    assert main(["experiment", "E5", "--quick", "--depth", "-1", "--out", str(out)]) == 2
    assert "depth" in capsys.readouterr().err
    assert main(["sweep", "--quick", "--velocities", "0.7", "--out", str(out)]) == 2
    assert main(["experiment", "E1", "--quick", "--out", str(tmp_path / "missing" / "out")]) == 2
    assert not out.exists() and list(tmp_path.iterdir()) == []  # nothing half-written


def test_unreachable_scheduler_is_a_clear_error(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "out"
    assert main(["experiment", "E4", "--quick", "--scheduler", "tcp://127.0.0.1:9", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "scheduler" in err and "127.0.0.1:9" in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_quick_experiments_write_complete_reports_that_agree_with_their_json(tmp_path: Path) -> None:
    out = tmp_path / "all"
    assert main(["experiment", "all", "--quick", "--out", str(out), "--seed", "1"]) == 0
    doc = json.loads((out / "results.json").read_text())
    report = (out / "report.md").read_text()
    assert list(doc["experiments"]) == ["E1", "E2", "E3", "E4", "E4R", "E5", "E6"]
    for name, res in doc["experiments"].items():
        assert f"## {name}:" in report
        assert res["figures"] and all((out / f).stat().st_size > 1000 for f in res["figures"])
        assert res["runtime_s"] > 0.0
    assert check_report_agrees_with_json(report, doc) > 100
    # every E4 row is in the report: plant x speed x controller
    e4 = doc["experiments"]["E4"]
    assert len(e4["rows"]) == 3 * 2 * 3
    for r in e4["rows"]:
        assert f"| {num(r['v_ref'], 1)} | {r['mode']} | " in report
        assert math.isfinite(r["power_est"]) and r["power_est"] > 0.0
    assert (out / "e2_points.csv").exists() and (out / "e4_runs.csv").exists()
    assert [p.name for p in tmp_path.iterdir()] == ["all"]  # the temporary directory is gone

    sweep = tmp_path / "sweep"
    assert main(["sweep", "--quick", "--lam-st", "5", "--lam-d", "1", "--velocities", "0.2", "--seeds", "1",
                 "--out", str(sweep)]) == 0
    sdoc = json.loads((sweep / "results.json").read_text())
    rows = sdoc["experiments"]["sweep"]["rows"]
    assert sorted(r["mode"] for r in rows) == ["baseline", "mpc"]
    assert (sweep / "sweep.csv").read_text().count("\n") == 3
    # v_ref, power, J/m, vel MAE, St MAE, depth MAE in both rows, lam_st and lam_d in the MPC's,
    # and the two savings in each row that tracks
    savings = sum(2 for r in rows if r["comparable"])
    assert check_report_agrees_with_json((sweep / "sweep.md").read_text(), sdoc) == 2 * 6 + 2 + savings
    assert (sweep / "sweep_power_vs_error.png").exists()
