"""The experiments' runs: the backend's scenario runner, E7's oracle planner chosen by name."""

from __future__ import annotations

import pytest

from ucat_console.backend import scenario as backend_scenario
from ucat_console.backend.scenario import Scenario
from ucat_console.experiments import scenario


def test_the_backend_runner_refuses_the_oracle_without_its_planner() -> None:
    with pytest.raises(ValueError, match="planner: 'oracle' needs the oracle's planner"):
        backend_scenario.run_scenario(Scenario(mode="mpc", v_ref=0.2, planner="oracle"))


def test_the_experiments_runner_hands_the_oracle_planner_over(monkeypatch: pytest.MonkeyPatch) -> None:
    seen = {}

    def run(sc: Scenario, planner):  # the backend's runner, recording the planner it is given
        seen[sc.planner] = planner
        return {}

    monkeypatch.setattr(backend_scenario, "run_scenario", run)
    scenario.run_scenario(Scenario(mode="mpc", v_ref=0.2))
    scenario.run_scenario(Scenario(mode="mpc", v_ref=0.2, planner="oracle"))
    assert seen[""] is None
    assert callable(seen["oracle"])


def test_an_unknown_plant_is_named_with_the_forms_a_name_takes() -> None:
    with pytest.raises(ValueError, match=r"plant: 'eeuv' is not one of plate, still_water, eeuvsim, scale<G>_plate"):
        Scenario(mode="mpc", v_ref=0.2, plant="eeuv").check()
