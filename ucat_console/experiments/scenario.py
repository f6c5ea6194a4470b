"""The experiments' closed-loop runs: ``backend.scenario``'s, with E7's oracle planner
(``experiments.oracle``) for a scenario that names it.

The plant variants are ``backend.sim.variants``' and the runs' start fin angle
``backend.fin_rig.START_FIN_ANGLE``; the names the experiments and sweeps take from here are
those.
"""

from __future__ import annotations

from typing import Any

from ucat_console.backend import scenario as _runs
from ucat_console.backend.fin_rig import START_FIN_ANGLE
from ucat_console.backend.scenario import Scenario
from ucat_console.backend.sim.variants import (
    DEFAULT_PLANT,
    PLANT_VARIANTS,
    cd0_name,
    family_name,
    hydro_of,
    plant_assumptions,
    plant_config,
)

__all__ = ["DEFAULT_PLANT", "PLANT_VARIANTS", "START_FIN_ANGLE", "Scenario", "cd0_name", "family_name", "hydro_of",
           "plant_assumptions", "plant_config", "run_scenario"]


def run_scenario(sc: Scenario) -> dict[str, Any]:
    """:func:`backend.scenario.run_scenario`, the MPC modes planned by E7's oracle when the
    scenario's ``planner`` is ``"oracle"``."""
    planner = None
    if sc.planner == "oracle":
        from ucat_console.experiments.oracle import OraclePlanner

        planner = lambda index: OraclePlanner(sc.plant, sc.mpc)  # noqa: E731
    return _runs.run_scenario(sc, planner)
