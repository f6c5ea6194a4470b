"""E7: the plants frozen by the declaration's hash, the paired statistics, the decision rules, --quick end to end."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pytest

from ucat_console.cli import main
from ucat_console.experiments import e7
from ucat_console.backend.sim.variants import e7_plants
from ucat_console.experiments.efficiency_curves import plant_hash

DECLARATION = Path(__file__).resolve().parents[2] / "docs" / "experiments" / "e7-declaration.md"


def declared_hash() -> str:
    m = re.search(r"Plants hash: `([0-9a-f]{16})`", DECLARATION.read_text())
    assert m, "the declaration names no plants hash"
    return m.group(1)


def test_the_plants_are_the_declared_ones() -> None:
    assert plant_hash(e7_plants()) == declared_hash()


def test_a_changed_plant_changes_the_hash(monkeypatch: pytest.MonkeyPatch) -> None:
    from ucat_console.backend.sim import variants

    monkeypatch.setattr(variants, "E7_CD0", (0.02, 0.05, 0.31))
    assert plant_hash(variants.e7_plants()) != declared_hash()


def test_paired_saving_and_its_interval() -> None:
    a = [0.9, 1.8, 2.7, 3.6]
    b = [1.0, 2.0, 3.0, 4.0]  # every pair 10 % lower: the interval is that point
    s = e7.paired_saving(a, b)
    assert s["comparable"] and s["pairs"] == 4
    assert s["saving"] == pytest.approx(10.0) and s["lo"] == pytest.approx(10.0) and s["hi"] == pytest.approx(10.0)
    noisy = e7.paired_saving([0.8, 1.2, 0.7, 1.3], [1.0, 1.0, 1.0, 1.0])
    assert noisy["lo"] < 0.0 < noisy["hi"]  # no saving: the interval straddles zero
    assert not e7.paired_saving([1.0], [2.0])["comparable"]


def _cmp(plant: str, v: float, a: str, b: str, saving: float, lo: float, hi: float) -> dict:
    return {"plant": plant, "v_ref": v, "a": a, "b": b, "pairs": 5, "saving": saving, "lo": lo, "hi": hi,
            "comparable": not math.isnan(saving)}


def test_decision_rules() -> None:
    st, best = ("mpc_closed_id", "mpc_closed_nost"), ("mpc_closed_id", "baseline_best")
    comps = [
        _cmp("plate_cd0.1", 0.2, *st, 8.0, 2.0, 12.0), _cmp("plate_cd0.1", 0.2, *best, 3.0, 0.5, 6.0),  # pays
        _cmp("plate_cd0.02", 0.2, *st, 6.0, -1.0, 12.0), _cmp("plate_cd0.02", 0.2, *best, 3.0, 0.5, 6.0),  # CI has 0
        _cmp("plate_cd0.3", 0.2, *st, 9.0, 4.0, 14.0), _cmp("plate_cd0.3", 0.2, *best, -2.0, -4.0, 1.0),  # loses to baseline
        _cmp("still_water", 0.2, *st, 2.0, -1.0, 5.0), _cmp("still_water", 0.2, *best, 1.0, -1.0, 3.0),
    ]
    peaks = {("plate_cd0.1", 0.2): 0.30, ("plate_cd0.02", 0.2): 0.20, ("plate_cd0.3", 0.2): 0.40,
             ("still_water", 0.2): 0.05}
    d = e7.decisions(comps, peaks)
    pays = {c["plant"]: c["pays"] for c in d["cases"]}
    assert pays == {"plate_cd0.1": True, "plate_cd0.02": False, "plate_cd0.3": False, "still_water": False}
    assert d["rule1"]["pays_in"] == 1 and not d["rule1"]["verdict"]  # 1 of 3: not a majority
    assert d["rule2"]["inside_mean"] == pytest.approx(8.0) and d["rule2"]["outside_mean"] == pytest.approx(7.5)
    assert d["rule2"]["verdict"]
    assert d["rule3"]["verdict"]  # |2 %| < 3 %
    comps[6] = _cmp("still_water", 0.2, *st, -3.5, -6.0, -1.0)
    assert not e7.decisions(comps, peaks)["rule3"]["verdict"]


def test_matched_tracking() -> None:
    run = {"velocity_mae": 0.02, "velocity_mean": 0.195, "scenario": {"v_ref": 0.2}}
    assert e7.matched(run)
    assert not e7.matched({**run, "velocity_mean": 0.185})  # mean 0.015 off
    assert not e7.matched({**run, "velocity_mae": 0.031})


@pytest.mark.slow
@pytest.mark.timeout(1200)  # two identifications, the oracle's tables and 28 runs: minutes on a busy machine
def test_quick_e7_writes_its_report_with_the_declared_hash(tmp_path: Path) -> None:
    out = tmp_path / "e7"
    assert main(["experiment", "E7", "--quick", "--out", str(out)]) == 0
    doc = json.loads((out / "results.json").read_text())
    res = doc["experiments"]["E7"]
    assert res["protocol"]["declared_hash"] == declared_hash()
    report = (out / "report.md").read_text()
    assert declared_hash() in report and res["protocol"]["plant_hash"] in report
    runs = (out / "e7_runs.csv").read_text().splitlines()
    plants, speeds, seeds = res["protocol"]["plants"], res["protocol"]["speeds"], res["protocol"]["seeds"]
    assert len(runs) - 1 == len(plants) * len(speeds) * len(e7.E7_CONTROLLERS) * len(seeds)
    # every case and every comparison is reported
    assert len(res["decisions"]["cases"]) == len(plants) * len(speeds)
    assert len(res["comparisons"]) == len(plants) * len(speeds) * len(e7.COMPARISONS)
    for c in e7.E7_CONTROLLERS:
        assert f"| {c} |" in report
    assert "Rule 1" in report and "Rule 3" in report
