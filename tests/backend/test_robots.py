"""The robots the console can drive: one live registry, read by the configuration, the
supervisor and the command line; the simulated robot's one start."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from ucat_console.backend import rig, robots
from ucat_console.backend.access import LOCAL
from ucat_console.backend.devices.config import DevicesConfig, SimStartConfig
from ucat_console.backend.loop.clock import SimulatedClock
from ucat_console.backend.robots import Robot
from ucat_console.backend.supervisor import Supervisor
from ucat_console.cli import main
from ucat_console.config import AppConfig

NAME = "outside-sim"


@pytest.fixture
def outside():
    """A robot registered from outside the package: the simulator, counting its builds."""
    built: list[float] = []

    def build(devices, plant, events):
        built.append(devices.start.depth)
        return rig.build_sim(devices, plant, events)

    robots.register(Robot(NAME, "the simulator, registered by a test", build, simulated=True, computed_readings=True))
    yield built
    robots.unregister(NAME)


def test_a_registered_robot_is_taken_by_the_configuration_and_the_supervisor(outside, tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=f"robot: 'submarine' is not allowed; allowed: one of 'sim', 'sim-devices', 'hardware', '{NAME}'"):
        AppConfig.from_dict({"robot": "submarine"})
    cfg = AppConfig.from_dict({"robot": NAME, "devices": {"start": {"depth": 2.0}}})
    assert cfg.simulated
    sup = Supervisor(cfg, clock=SimulatedClock(), sessions_dir=tmp_path)
    try:
        assert outside == [2.0]  # built through its entry, at the configured start
        assert sup.start_depth == 2.0 and sup.setpoints.depth == 2.0
        sup.arm(LOCAL)
        sup.step(1.0)
        assert abs(sup.loop.truth().position[2] - 2.0) < 0.05  # held where it started
    finally:
        sup.stop()


def test_a_registered_robot_runs_from_the_command_line(outside, tmp_path: Path, capsys) -> None:
    toml = tmp_path / "outside.toml"
    toml.write_text(f'robot = "{NAME}"\n[devices.start]\ndepth = 1.5\n')
    code = main(["run", "--config", str(toml), "--headless", "--fast", "--duration", "2",
                 "--sessions-dir", str(tmp_path / "s")])
    assert code == 0, capsys.readouterr()
    assert outside == [1.5]


def test_the_simulated_robot_starts_where_its_depth_setpoint_starts_in_process_and_behind_the_emulators(
        tmp_path: Path) -> None:
    """One start for the simulated U-CAT: the depth setpoint of the robot behind the emulators
    starts at its start depth too (it started at the surface, 0 m)."""
    sim = robots.robot("sim").build
    for name in ("sim", "sim-devices"):
        cfg = AppConfig(robot=name, devices=DevicesConfig(start=SimStartConfig(depth=1.2)))
        sup = Supervisor(cfg, clock=SimulatedClock(), sessions_dir=tmp_path,
                         robot_factory=lambda c, ev: sim(c.devices, c.plant, ev))
        try:
            assert sup.start_depth == 1.2 and sup.setpoints.depth == 1.2, name
        finally:
            sup.stop()
    sup = Supervisor(AppConfig(robot="hardware"), clock=SimulatedClock(), sessions_dir=tmp_path,
                     robot_factory=lambda c, ev: sim(c.devices, c.plant, ev))
    try:
        assert sup.start_depth == 0.0  # the robot's own depth is not known: the surface
    finally:
        sup.stop()


def test_an_older_files_sim_depth_loads_as_the_start_depth_with_a_warning(caplog) -> None:
    with caplog.at_level(logging.WARNING, logger="ucat_console.config"):
        cfg = AppConfig.from_dict({"console": {"sim_depth": 2.5}})
    assert cfg.devices.start.depth == 2.5
    assert "console.sim_depth" in caplog.text and "devices.start.depth = 2.5" in caplog.text
    assert AppConfig.from_dict({"console": {"sim_depth": 2.5}, "devices": {"start": {"depth": 2.5}}}) == cfg
    with pytest.raises(ValueError, match="console.sim_depth: 2.5 and devices.start.depth 1.0 both"):
        AppConfig.from_dict({"console": {"sim_depth": 2.5}, "devices": {"start": {"depth": 1.0}}})


def test_a_name_taken_or_not_a_robot_is_refused() -> None:
    with pytest.raises(ValueError, match="'sim' is registered already"):
        robots.register(Robot("sim", "again", robots.robot("sim").build, simulated=True))
    with pytest.raises(ValueError, match="expected a Robot"):
        robots.register("sim")  # type: ignore[arg-type]
    assert robots.robot_names()[:3] == ("sim", "sim-devices", "hardware")
