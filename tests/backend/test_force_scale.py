"""Fins stronger than their model: the closed loop on the eeUVsim plant (its fins make several
times the paper's fin model's force) under a configuration that keeps the paper's model
measures it, asks the fins for that much less, and says so (``fin_force_scale``); on the
default plant nothing of it happens."""

from __future__ import annotations

from typing import Any

import pytest

from ucat_console.config import load_config
from ucat_console.telemetry import channels as ch


def cruise(plant_name: str, seconds: float) -> tuple[list[Any], Any]:
    """The baseline holding 0.2 m/s at 1 m on plant ``plant_name`` for ``seconds``: the
    loop's events and its body layer."""
    from ucat_console.backend.fin_rig import START_FIN_ANGLE
    from ucat_console.backend.loop.closed_loop import ClosedLoop
    from ucat_console.backend.sim.variants import plant_config
    from ucat_console.backend.sim_robot_io import SimRobotIO
    from ucat_console.control.allocation import BodySetpoints
    from ucat_console.telemetry.stream import TelemetryStream

    app = load_config("sim-tuned")
    io = SimRobotIO(plant_config(plant_name, 0, (0.0, 0.0, 0.0)), depth=1.0, velocity=0.2)
    io.plant.reset(position_ned=(0.0, 0.0, 1.0), body_velocity=(0.2, 0.0, 0.0, 0.0, 0.0, 0.0),
                   fin_angles=(START_FIN_ANGLE,) * 4, seed=0)
    stream = TelemetryStream(validate=False)
    events: list[Any] = []
    stream.subscribe(lambda _c, ev: events.append(ev), [ch.EVENTS])
    loop = ClosedLoop(app.loop.replace(mode="baseline"), io, stream, setpoints=BodySetpoints(0.2, 1.0, 0.0))
    try:
        loop.run_until(seconds)
    finally:
        loop.close()
    return events, loop.body


def test_fins_stronger_than_the_model_are_measured_followed_and_reported() -> None:
    events, body = cruise("eeuvsim", 40.0)
    scaled = [e for e in events if e.code == "fin_force_scale"]
    assert len(scaled) == 1 and scaled[0].level == "warning" and scaled[0].t < 10.0
    assert scaled[0].data["scale"] >= 2.0 and "identify" in scaled[0].message
    scale, measured = body.force_scale
    assert scale == measured and 3.5 < measured < 7.0  # the plate makes 4.6 times the model's force per w^2


@pytest.mark.parametrize("plant", ["plate", "still_water"])
def test_fins_that_make_about_the_models_force_are_left_as_they_are(plant: str) -> None:
    events, body = cruise(plant, 40.0)
    assert not [e for e in events if e.code.startswith("fin_force_scale")]
    scale, measured = body.force_scale
    assert scale == 1.0 and 0.8 < measured < 1.6
