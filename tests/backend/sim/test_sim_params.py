"""Plant configuration: defaults from plant.md, validation, TOML, fin numbering, the fin model."""

from __future__ import annotations

import ast
import math
from pathlib import Path

import pytest

import ucat_console.backend.sim as sim_pkg
from ucat_console.backend.sim.params import (
    EEUVSIM_COEFFICIENTS,
    PAPER_COEFFICIENTS,
    FinGeometryConfig,
    FinHydroConfig,
    PlantConfig,
    VehicleConfig,
)
from ucat_console.robot.fins import FIN_NAMES, fin_signs
from ucat_console.robot.fins import PAPER_TO_ROBOT as PAPER_TO_PLANT_FIN
from ucat_console.robot.geometry import fin_plane_axes


def test_defaults_follow_the_spec_table() -> None:
    c = PlantConfig()
    v = c.vehicle
    assert v.mass == 22.0
    assert (v.ixx, v.iyy, v.izz) == (0.1574, 0.66, 0.70)
    assert (v.x_u, v.x_uu) == (-6.542, -2.98)
    assert v.buoyancy_ratio == 1.0
    assert c.fins.mounting_angle_deg == 30.0
    assert (c.fins.arm_roll, c.fins.arm_pitch, c.fins.arm_yaw) == (0.1502, 0.25753, 0.2981)
    assert c.servo.acceleration == 64.0
    assert c.servo.feedback_rate == 100.0
    assert c.sensors.dvl.rate == 8.0
    assert c.sensors.imu.rate == 100.0
    assert c.dt == 0.001
    assert (c.hydro.model, c.hydro.coefficients) == ("plate", "paper")


def test_coefficient_sets() -> None:
    assert (PAPER_COEFFICIENTS.c_d, PAPER_COEFFICIENTS.c_l, PAPER_COEFFICIENTS.area) == (0.70, 0.25, 0.020)
    assert (PAPER_COEFFICIENTS.r_c, PAPER_COEFFICIENTS.rho) == (0.10, 1000.0)
    e = EEUVSIM_COEFFICIENTS
    assert (e.c_d, e.c_l, e.fin_length, e.rho) == (3.2, 1.65, 0.18, 997.0)
    assert FinHydroConfig(coefficients="paper").resolved() == PAPER_COEFFICIENTS
    custom = FinHydroConfig(coefficients="custom", custom=PAPER_COEFFICIENTS.replace(c_l=0.5))
    assert custom.resolved().c_l == 0.5


def test_a_scaled_fin_scales_both_coefficients() -> None:
    """E6's family: G times the thrust per w^2 comes with G times the normal force (the shaft's
    load), never thrust alone."""
    s = PAPER_COEFFICIENTS.scaled(4.6)
    assert (s.c_d, s.c_l) == pytest.approx((0.70 * 4.6, 0.25 * 4.6))
    assert (s.area, s.r_c, s.rho) == (PAPER_COEFFICIENTS.area, PAPER_COEFFICIENTS.r_c, PAPER_COEFFICIENTS.rho)


def test_paper_fin_mapping_puts_paper_front_pair_on_the_front_fins() -> None:
    assert PAPER_TO_PLANT_FIN == (0, 3, 1, 2)
    assert sorted(PAPER_TO_PLANT_FIN) == [0, 1, 2, 3]
    front = [fin_signs(PAPER_TO_PLANT_FIN[k])[1] for k in (0, 1)]
    rear = [fin_signs(PAPER_TO_PLANT_FIN[k])[1] for k in (2, 3)]
    assert front == [1.0, 1.0] and rear == [-1.0, -1.0]
    assert FIN_NAMES[PAPER_TO_PLANT_FIN[0]] == "front_right"
    assert FIN_NAMES[PAPER_TO_PLANT_FIN[1]] == "front_left"


def test_fin_plane_axes_point_rearwards_and_up() -> None:
    g = FinGeometryConfig()
    for i in range(4):
        xm, ym = fin_plane_axes(g, i)
        assert xm[0] == pytest.approx(-math.cos(math.radians(30)))
        assert abs(xm[1]) == pytest.approx(0.5)
        assert ym == (0.0, 0.0, -1.0)  # up in a z-down body frame
    # front fins' x_m points inwards, rear fins' outwards (starboard is +y)
    assert fin_plane_axes(g, 0)[0][1] < 0 and fin_plane_axes(g, 3)[0][1] > 0
    assert fin_plane_axes(g, 1)[0][1] > 0 and fin_plane_axes(g, 2)[0][1] < 0
    with pytest.raises(ValueError, match="fin"):
        fin_signs(4)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"c_d0": 0.8}, "c_d0"),
        ({"lift_ratio": -0.1}, "lift_ratio"),
        ({"model": "vortex"}, "model"),
        ({"coefficients": "soft_fin"}, "coefficients"),
    ],
)
def test_bad_hydro_config_is_named(kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        FinHydroConfig(**kwargs)


def test_bad_vehicle_vectors_are_named() -> None:
    with pytest.raises(ValueError, match="current_ned"):
        VehicleConfig(current_ned=(0.0, float("nan"), 0.0))
    with pytest.raises(ValueError, match="mass"):
        VehicleConfig(mass=-1.0)


def test_toml_round_trip(tmp_path: Path) -> None:
    c = PlantConfig(
        vehicle=VehicleConfig(current_ned=(0.1, -0.05, 0.0)),
        hydro=FinHydroConfig(coefficients="eeuvsim", model="still_water", c_d0=0.1),
        seed=7,
    )
    path = tmp_path / "plant.toml"
    path.write_text(c.to_toml())
    assert PlantConfig.from_toml(path) == c
    path.write_text("[hydro]\nmodel = 'vortex'\n")
    with pytest.raises(ValueError, match="hydro.model"):
        PlantConfig.from_toml(path)


def test_plant_does_not_import_the_controller() -> None:
    """The plant has its own parameters: only the config pattern may come from control."""
    for path in Path(sim_pkg.__file__).parent.glob("*.py"):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("ucat_console.control"):
                assert node.module == "ucat_console.control.params", path.name
                assert [a.name for a in node.names] == ["_Config"], path.name
            elif isinstance(node, ast.Import):
                for a in node.names:
                    assert not a.name.startswith("ucat_console.control"), path.name
