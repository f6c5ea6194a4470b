"""A weak drive on the simulated robot (``SimRobotIO.weaken_fin``): the fin runs at a share of
the speed asked, from its next command on, while the robot runs; the others are untouched."""

from __future__ import annotations

import pytest

from ucat_console.backend.sim_robot_io import SimRobotIO


class _Plant:
    """Records the commands the robot hands its plant (the real plant's configuration)."""

    def __init__(self, real) -> None:
        self.cfg = real.cfg
        self.sent: list[tuple[int, float, float]] = []

    def command_fin(self, fin: int, target: float, rate: float) -> None:
        self.sent.append((fin, target, rate))


def test_a_weak_fin_runs_at_its_share_of_the_speed_asked_and_is_made_whole_again() -> None:
    io = SimRobotIO(depth=1.0)
    top = io.plant.cfg.servo.max_rate
    io.plant = _Plant(io.plant)
    io.command_fin(2, 0.3, 4.0)
    io.weaken_fin(2, 0.5)
    io.command_fin(2, 0.3, 4.0)
    io.command_fin(1, 0.3, 4.0)  # another fin: as asked
    io.command_fin(2, -0.3, 10.0 * top)  # beyond the servos' maximum: half of the maximum
    io.weaken_fin(2, 1.0)
    io.command_fin(2, 0.3, 4.0)
    assert io.plant.sent == [(2, 0.3, 4.0), (2, 0.3, 2.0), (1, 0.3, 4.0), (2, -0.3, 0.5 * top), (2, 0.3, 4.0)]


def test_a_weak_fin_moves_slower_on_the_plant() -> None:
    """On the real plant: the same stroke asked of two fins, one weakened, takes it longer."""
    io = SimRobotIO(depth=1.0)
    start = io.plant.fin_angles()
    io.weaken_fin(0, 0.5)
    for fin in (0, 3):
        io.command_fin(fin, start[fin] + 0.5, 3.0)
    io.plant.advance(0.1)
    moved = [abs(io.plant.fin_angles()[fin] - start[fin]) for fin in (0, 3)]
    assert 0.0 < moved[0] < 0.7 * moved[1]


@pytest.mark.parametrize("fin, factor", [(4, 0.5), (-1, 0.5), (0, 0.0), (0, 1.5), (0, float("nan")), ("1", 0.5), (True, 0.5)])
def test_a_weak_fin_is_a_fin_and_a_share(fin, factor) -> None:
    with pytest.raises(ValueError, match="fin|factor"):
        SimRobotIO(depth=1.0).weaken_fin(fin, factor)
