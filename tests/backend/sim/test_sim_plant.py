"""The Plant shell and its compiled core."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numba.core.registry import CPUDispatcher

import ucat_console.backend.sim.fin_hydro as fin_hydro_mod
import ucat_console.backend.sim.plant as plant_mod
import ucat_console.backend.sim.vehicle as vehicle_mod
import ucat_console.robot.rotations as rotations_mod
import ucat_console.robot.servo as servo_mod
from ucat_console.backend.sim.params import FinHydroConfig, PlantConfig, VehicleConfig
from ucat_console.backend.sim.plant import F_ENERGY, F_OMEGA, F_THETA, Plant, measure_realtime_factor


def _core_args(plant: Plant, xv: np.ndarray, xf: np.ndarray, n: int, xv_out: np.ndarray, xf_out: np.ndarray) -> tuple:
    return (
        xv, xf, plant._cmd, plant._mrb, plant._ma, plant._minv, plant._pv, plant._ph, plant._signs,
        plant._acc, plant._max_rate, plant._fin_inertia, plant.cfg.dt, n, xv_out, xf_out,
    )


def test_compiled_core_equals_the_python_reference(monkeypatch: pytest.MonkeyPatch) -> None:
    cfg = PlantConfig(vehicle=VehicleConfig(current_ned=(0.05, -0.02, 0.01), disturbance_ned=(0.1, 0.0, 0.2)))
    p = Plant(cfg)
    p.reset(
        position_ned=(0.0, 0.0, 1.0),
        euler=(0.05, -0.1, 0.3),
        body_velocity=(0.2, 0.01, -0.02, 0.05, -0.03, 0.1),
        fin_angles=(0.1, -0.2, 0.3, -0.4),
    )
    p.set_body_wrench((0.3, 0.0, -0.1), (0.0, 0.01, 0.0))
    for i in range(4):
        p.command_fin(i, 0.8 * (-1) ** i, 3.0 + i)
    p.advance(0.05)  # fins moving, stroke starts and mean rates set
    xv0, xf0 = p.state_arrays()
    xv_c, xf_c = np.empty_like(xv0), np.empty_like(xf0)
    assert plant_mod.advance_steps(*_core_args(p, xv0, xf0, 5, xv_c, xf_c))
    reference = plant_mod.advance_steps.py_func
    for mod in (plant_mod, vehicle_mod, fin_hydro_mod, servo_mod, rotations_mod):
        for name, obj in list(vars(mod).items()):
            if isinstance(obj, CPUDispatcher):
                monkeypatch.setattr(mod, name, obj.py_func)
    xv_p, xf_p = np.empty_like(xv0), np.empty_like(xf0)
    assert reference(*_core_args(p, xv0, xf0, 5, xv_p, xf_p))
    assert not np.array_equal(xv_p, xv0)
    np.testing.assert_allclose(xv_c, xv_p, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(xf_c, xf_p, rtol=1e-12, atol=1e-15)


def test_core_in_place_equals_out_of_place() -> None:
    p = Plant()
    for i in range(4):
        p.command_fin(i, 0.5, 2.0)
    xv0, xf0 = p.state_arrays()
    xv_keep, xf_keep = xv0.copy(), xf0.copy()
    xv_a, xf_a = np.empty_like(xv0), np.empty_like(xf0)
    plant_mod.advance_steps(*_core_args(p, xv0, xf0, 100, xv_a, xf_a))
    assert np.array_equal(xv0, xv_keep) and np.array_equal(xf0, xf_keep)  # inputs untouched
    p.advance(0.1)
    xv_b, xf_b = p.state_arrays()
    assert np.array_equal(xv_a, xv_b) and np.array_equal(xf_a, xf_b)
    # ramp of 2/64 s covers 2^2 / (2 * 64) rad, then cruise at 2 rad/s until t = 0.1 s
    assert xf_b[0, F_THETA] == pytest.approx(2.0**2 / 128.0 + 2.0 * (0.1 - 2.0 / 64.0), abs=1e-3)


def test_advance_carries_the_remainder() -> None:
    p = Plant()
    p.advance(0.0004)
    assert p.time == 0.0
    p.advance(0.0007)
    assert p.time == pytest.approx(0.001)
    for _ in range(10):
        p.advance(0.01)
    assert p.time == pytest.approx(0.101)
    p.advance_to(0.1234)
    assert p.time == pytest.approx(0.124)
    with pytest.raises(ValueError, match="duration_s"):
        p.advance(-0.1)


@pytest.mark.parametrize(
    ("args", "match"),
    [((4, 0.1, 1.0), "fin"), ((0, math.nan, 1.0), "target_rad"), ((1, 0.1, 0.0), "profile_velocity"), ((2, 0.1, math.inf), "profile_velocity")],
)
def test_bad_commands_are_named(args: tuple, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        Plant().command_fin(*args)


def test_fin_commands_move_the_fins_and_feedback_is_quantised() -> None:
    p = Plant()
    p.command_fin(1, 0.5, 20.0)  # clipped to max_rate 10 rad/s
    p.advance(0.05)
    assert max(abs(w) for w in p.fin_rates()) <= 10.0
    p.advance(0.5)
    assert p.fin_angles()[1] == 0.5 and p.fin_rates()[1] == 0.0
    assert p.fin_angles()[0] == 0.0
    angle, rate = p.fin_feedback(1)
    assert angle == pytest.approx(0.5, abs=2 * math.pi / (4 * 512 * 35) / 2)
    assert rate == 0.0
    assert p.fin_energy()[1] > 0.0 and p.fin_energy()[0] == 0.0


def _swim(cfg: PlantConfig, seconds: float = 6.0) -> Plant:
    """All fins beat between -0.6 and 0 rad (centre 0.3 rad below neutral) at 3 rad/s."""
    p = Plant(cfg)
    p.reset(position_ned=(0.0, 0.0, 1.0))
    target = -0.6
    while p.time < seconds:
        if all(w == 0.0 for w in p.fin_rates()):
            target = 0.0 if target < 0 else -0.6
            for i in range(4):
                p.command_fin(i, target, 3.0)
        p.advance(0.01)
    return p


def test_beating_fins_with_forward_thrust_drive_the_hull_forward() -> None:
    plant = _swim(PlantConfig())
    u, v, _, _, _, r = plant.body_velocity()
    assert u > 0.05
    assert abs(v) < 1e-6 and abs(r) < 1e-6  # four equal fins: no sway, no yaw
    pos, _ = plant.pose()
    assert pos[0] > 0.1
    assert all(s > 0.0 for s in plant.fin_strouhal())
    # the null plant's fins ignore the stream: no profile drag, no loss of thrust with speed
    assert _swim(PlantConfig(hydro=FinHydroConfig(model="still_water"))).body_velocity()[0] > u


def test_reset_restores_the_initial_state() -> None:
    p = Plant()
    xv0, xf0 = p.state_arrays()
    for i in range(4):
        p.command_fin(i, 0.5, 4.0)
    p.set_body_wrench((1.0, 0.0, 0.0))
    p.advance(1.0)
    p.set_body_wrench()
    p.reset()
    xv1, xf1 = p.state_arrays()
    assert p.time == 0.0 and np.array_equal(xv0, xv1) and np.array_equal(xf0, xf1)
    _, q = p.pose()
    assert sum(c * c for c in q) == pytest.approx(1.0)
    assert xf1[:, F_ENERGY].sum() == 0.0 and xf1[:, F_OMEGA].sum() == 0.0


def test_measure_realtime_factor_runs() -> None:
    factor = measure_realtime_factor(0.05)
    assert math.isfinite(factor) and factor > 0.0
