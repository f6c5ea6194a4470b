"""The shipped sim-tuned configuration: the simulated robot swims from rest, which the paper's
defaults do not achieve on this plant (a finding reported in the README)."""


import numpy as np
import pytest

from ucat_console import shipped
from ucat_console.backend.loop.closed_loop import ClosedLoop
from ucat_console.backend.sim_robot_io import SimRobotIO
from ucat_console.config import AppConfig
from ucat_console.control.allocation import BodySetpoints
from ucat_console.telemetry import TelemetryStream

TUNED = shipped.config_path("sim-tuned")


def mean_speed_from_rest(app: AppConfig, mode: str) -> float:
    io = SimRobotIO(depth=1.0)
    loop = ClosedLoop(app.loop.replace(mode=mode), io, TelemetryStream(),
                      setpoints=BodySetpoints(velocity=0.2, depth=1.0))
    loop.run_until(10.0)
    speeds = []
    while loop.time < 20.0 - 1e-9:
        loop.run(0.5)
        speeds.append(io.truth().velocity[0])
    loop.close()
    return float(np.mean(speeds))


@pytest.mark.parametrize("mode", ["mpc", "mpc_sync", "baseline"])
def test_tuned_configuration_swims_from_rest(mode):
    assert mean_speed_from_rest(AppConfig.from_toml(TUNED), mode) > 0.1


def test_paper_defaults_do_not_start_the_mpc_from_rest():
    assert mean_speed_from_rest(AppConfig(), "mpc") < 0.05
