"""The identification manoeuvre's plans and its configuration."""

import math

import pytest

from ucat_console.control.manoeuvre import ManoeuvrePlanner
from ucat_console.control.params import ManoeuvreConfig, MpcConfig

FORWARD = -1.2277  # the forward-thrust centre of the paper's model


def test_steps_follow_the_schedule_about_their_centres_then_hold():
    cfg = ManoeuvreConfig(steps=((0.0, 0.6, 2.0), (0.5, 1.0, 4.0)), step_s=10.0)
    planner = ManoeuvrePlanner(cfg, MpcConfig())
    assert planner.centre == pytest.approx(FORWARD, abs=1e-4)
    u, cmd = planner.plan(3.0, 0.0)
    assert u[2:] == (2.0, 2.0) and abs(u[1]) == pytest.approx(0.6)
    assert sorted((cmd[0], cmd[2])) == pytest.approx([FORWARD - 0.3, FORWARD + 0.3], abs=1e-4)
    assert u[0] == pytest.approx(cmd[0]) and u[0] + u[1] == pytest.approx(cmd[2])
    # second step from the end of a cycle: the pair about centre + 0.5, starting at the far end
    u, cmd = planner.plan(12.0, FORWARD + 0.3)
    assert u[2:] == (4.0, 4.0) and cmd[0] == pytest.approx(FORWARD + 1.0, abs=1e-4)
    assert cmd[2] == pytest.approx(FORWARD, abs=1e-4)
    # a fin a whole turn away strokes about the nearest copy of the centre
    u, cmd = planner.plan(3.0, 2 * math.pi + planner.centre)
    assert abs(u[0]) <= 0.3 + 1e-9
    # after the last step: zero strokes at the slowest admissible rate
    u, cmd = planner.plan(20.0, 0.7)
    assert u == (0.0, 0.0, 0.5, 0.5) and cmd == (0.7, 0.5, 0.7, 0.5)
    assert planner.step_at(-1.0) is None and cfg.duration == 20.0


@pytest.mark.parametrize("steps, match", [
    ((), "at least one step"),
    (((0.0, 0.6),), r"steps\[0\]"),
    (((0.0, 0.6, 2.0), (2.0, 0.6, 2.0)), r"steps\[1\]: centre offset"),
    (((0.0, 0.0, 2.0),), r"steps\[0\]: stroke"),
    (((0.0, 0.6, 90.0),), r"steps\[0\]: rate"),
])
def test_bad_steps_are_refused_naming_the_step(steps, match):
    with pytest.raises(ValueError, match=match):
        ManoeuvreConfig(steps=steps)
