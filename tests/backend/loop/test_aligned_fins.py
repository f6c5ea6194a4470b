"""The MPC's fins across the hull from each other begin their cycles together (``[loop.mpc]
align``): each fin takes up a new force target at its own next cycle, so two fins of a pair
on their own beats take up a change of heave or surge demand up to a cycle apart, and the
side that takes it first turns the robot."""

from __future__ import annotations

import numpy as np
import pytest

from ucat_console import shipped
from ucat_console.backend.loop.actuators import PARTNER
from ucat_console.backend.loop.closed_loop import ClosedLoop
from ucat_console.backend.sim_robot_io import SimRobotIO
from ucat_console.config import AppConfig
from ucat_console.control.allocation import BodySetpoints
from ucat_console.robot.fins import PAPER_TO_ROBOT
from ucat_console.telemetry import TelemetryStream
from ucat_console.telemetry import channels as C


def partner_offsets(align: float) -> list[float]:
    """Cruising at 0.2 m/s under the paper MPC of sim-tuned with ``align``: for each cycle a
    fin begins from 10 s on, how far (in its cycle's length) the nearest cycle its partner
    began is."""
    app = AppConfig.from_toml(shipped.config_path("sim-tuned"))
    cfg = app.loop.replace(mode="mpc", mpc=app.loop.mpc.replace(align=align))
    stream = TelemetryStream()
    starts: dict[int, list[tuple[float, float]]] = {f: [] for f in range(4)}
    stream.subscribe(lambda ch, m: starts[m.fin].append((m.t - m.duration, m.duration)),
                     [C.fin_cycle(f) for f in range(4)])
    loop = ClosedLoop(cfg, SimRobotIO(depth=1.0, velocity=0.2, seed=0), stream,
                      setpoints=BodySetpoints(velocity=0.2, depth=1.0))
    try:
        loop.run_until(30.0)
    finally:
        loop.close()
    offsets = []
    for paper in (0, 2):  # the front pair and the rear pair
        mine, theirs = starts[PAPER_TO_ROBOT[paper]], starts[PAPER_TO_ROBOT[PARTNER[paper]]]
        other = np.array([s for s, _ in theirs])
        offsets += [float(np.min(np.abs(other - s))) / d for s, d in mine if s > 10.0]
    return offsets


@pytest.mark.slow
def test_the_fins_of_a_pair_begin_their_cycles_together():
    alone, aligned = partner_offsets(0.0), partner_offsets(0.1)
    assert len(aligned) > 20
    assert np.median(alone) > 0.15  # on their own beats: a fifth to a third of a cycle apart
    assert np.median(aligned) < 0.05
    assert np.quantile(aligned, 0.9) < 0.2
