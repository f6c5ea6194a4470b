"""The experiments' closed-loop runs: ``backend.scenario``'s, with E7's oracle planner
(``experiments.oracle``) for a scenario that names it. The plant variants are
``backend.sim.variants``', the runs' start fin angle ``backend.fin_rig.START_FIN_ANGLE``.
"""

from __future__ import annotations

from typing import Any

from ucat_console.backend import scenario as _runs
from ucat_console.backend.scenario import Scenario


def run_scenario(sc: Scenario) -> dict[str, Any]:
    """:func:`backend.scenario.run_scenario`, the MPC modes planned by E7's oracle when the
    scenario's ``planner`` is ``"oracle"``."""
    planner = None
    if sc.planner == "oracle":
        from ucat_console.experiments.oracle import OraclePlanner

        planner = lambda index: OraclePlanner(sc.plant, sc.mpc)  # noqa: E731
    return _runs.run_scenario(sc, planner)
