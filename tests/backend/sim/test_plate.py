"""The fin as a plate hinged at its leading edge: forces by hand, the still-water calibration,
and energy: no shipped plant's fin delivers more power to the hull than its shaft takes."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from ucat_console.backend.sim import plate
from ucat_console.backend.sim.fin_hydro import H_PLATE, hydro_params
from ucat_console.backend.sim.params import FinGeometryConfig, FinHydroConfig, PlantConfig
from ucat_console.backend.sim.variants import PLANT_VARIANTS, e7_plants, family_name, plant_config
from ucat_console.robot.servo import servo_step

GEOM = FinGeometryConfig()
RHO, AREA, R_C, C_D, C_L = 1000.0, 0.020, 0.10, 0.70, 0.25
RADIUS = math.sqrt(3.0) * R_C
SPAN = AREA / RADIUS


def _pf(**hydro: object) -> np.ndarray:
    return hydro_params(FinHydroConfig(**hydro), GEOM)[H_PLATE:]


PF = _pf()


def test_a_fin_at_rest_in_still_water_feels_nothing() -> None:
    assert plate.fin_load(0.4, 0.0, 0.0, 0.0, 0.0, 1e-4, 1e-3, PF) == (0.0, 0.0, 0.0, 0.0, 0.0)


def test_still_water_force_by_hand() -> None:
    """In still water every strip meets the water at 90 degrees: a normal force rho C_N
    span (r w)^2 dr / 2 (C_N = C_D = 0.70), and the circulation pushes along the plate
    towards the shaft with rho span C_R R^3 w^2 / 4, C_R = 2 sqrt(C_L^2 + C_D^2) / 3."""
    w = 3.0
    theta = -plate.plate_angle(C_D, C_L)  # the plate's line along +x_m (trailing rearwards)
    fx, fy, moment = plate.plate_force(theta, w, 0.0, 0.0, PF)
    n = 8
    dr = RADIUS / n
    strips = [(k + 0.5) * dr for k in range(n)]
    normal = sum(0.5 * RHO * C_D * SPAN * dr * (r * w) ** 2 for r in strips)
    along = RHO * SPAN * (2.0 * math.hypot(C_L, C_D) / 3.0) * RADIUS ** 3 * w * w / 4.0
    # the plate turning towards +psi (up) is pushed down; the circulation pushes it forward (-x_m)
    assert (fx, fy) == pytest.approx((-along, -normal), rel=1e-12)
    drag_moment = sum(0.5 * RHO * C_D * SPAN * dr * (r * w) ** 2 * r for r in strips)
    assert moment == pytest.approx(-drag_moment, rel=1e-12)  # the circulation's force is radial here


def _cycle(pf: np.ndarray, centre: float, amplitude: float, rate: float, ux: float, uy: float,
           acceleration: float = 64.0, cycles: int = 3) -> tuple[float, float, float, float, float]:
    """Symmetric stroke pairs through the plant's servo; the means of the last cycle:
    (f_x, f_y, shaft power, power into the hull, shaft power without the no-regeneration clip)."""
    dt = 1e-3
    th, om = centre - amplitude, 0.0
    sums = np.zeros(5)
    n = 0
    for k in range(2 * cycles):
        target = centre + amplitude if k % 2 == 0 else centre - amplitude
        while True:
            th, om, al = servo_step(th, om, target, rate, acceleration, 10.0, dt)
            fx, fy, _, p, useful = plate.fin_load(th, om, al, ux, uy, 2.8e-5, dt, pf)
            null = pf[plate.P_NULL] > 0.5
            moment = plate.plate_force(th, om, 0.0 if null else ux, 0.0 if null else uy, pf)[2]
            raw = ((2.8e-5 + pf[plate.P_ADDED_I]) * al * (om - 0.5 * al * dt) - moment * om
                   + (useful if null else 0.0))
            if k >= 2 * cycles - 2:
                sums += (fx, fy, p, useful, raw)
                n += 1
            if om == 0.0 and th == target:
                break
    return tuple(sums / n)  # type: ignore[return-value]


@pytest.mark.parametrize("stroke", [0.2, 0.6, 1.2])
def test_still_water_mean_force_is_the_identified_model_s(stroke: float) -> None:
    """Calibration: at a steady rate (a servo that reaches it at once), a symmetric stroke
    pair's mean force is the identified model's, q w^2 sqrt(C_L^2 + C_D^2) cos(d/2), pointing
    along c + atan2(-C_D, -C_L): the plate's sin(d/2)/(d/2) against the model's cos(d/2)."""
    w, centre = 3.0, 0.4
    fx, fy, *_ = _cycle(PF, centre, stroke / 2.0, w, 0.0, 0.0, acceleration=5000.0)
    q = 0.5 * RHO * AREA * R_C ** 2
    model = q * w * w * math.hypot(C_L, C_D)
    half = stroke / 2.0
    assert math.hypot(fx, fy) == pytest.approx(model * math.sin(half) / half, rel=0.03)
    assert math.hypot(fx, fy) / (model * math.cos(half)) < 1.15
    direction = math.atan2(fy, fx) - (centre + math.atan2(-C_D, -C_L))
    assert abs(math.remainder(direction, 2.0 * math.pi)) < 1e-3


def _shipped_plants() -> dict[str, np.ndarray]:
    names = [*PLANT_VARIANTS, *e7_plants(), *(family_name(g, m) for g in (1.0, 2.3, 4.6, 9.2)
                                              for m in ("plate", "still_water"))]
    return {n: hydro_params(plant_config(n, 0).hydro, GEOM)[H_PLATE:] for n in names}


SHIPPED = _shipped_plants()


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_no_shipped_plant_delivers_more_power_than_its_shaft_takes(name: str) -> None:
    """T V <= P over a grid of centres, amplitudes, rates and flows (forwards, backwards,
    across): the power a fin delivers to the hull over a cycle never exceeds its shaft
    power, with or without the no-regeneration clip."""
    pf = SHIPPED[name]
    worst = -math.inf
    for centre in (-2.0, -1.2, -0.4, 0.4, 1.5):
        for amplitude in (0.1, 0.35, 0.6):
            for rate in (1.0, 3.0, 6.0, 10.0):
                for ux, uy in ((0.0, 0.0), (0.1, 0.0), (0.3, 0.0), (0.5, 0.0), (-0.2, 0.0), (0.2, 0.15)):
                    _, _, p, useful, raw = _cycle(pf, centre, amplitude, rate, ux, uy, cycles=2)
                    assert useful <= raw + 1e-9 <= p + 2e-9, (centre, amplitude, rate, ux, uy, useful, raw, p)
                    worst = max(worst, useful / p if p > 0 else -math.inf)
    assert worst < 1.0


def test_each_force_either_dissipates_or_does_no_work() -> None:
    """Why energy is conserved: a strip's drag opposes the water's flow past it and its lift is
    across it (the water does no positive work on the plate), and the circulation's force is
    across the velocity of the plate's centre."""
    rng = np.random.default_rng(7)
    for _ in range(500):
        vp, vn = rng.normal(size=2)
        fp, fn = plate.strip_force(vp, vn, 0.05, 0.65, 0.42)
        # the force on the strip along the water's flow past it (V) is the drag: >= 0
        assert fp * vp + fn * vn >= -1e-12
        cd = 0.05 + 0.65 * vn * vn / (vp * vp + vn * vn)
        assert fp * vp + fn * vn == pytest.approx(cd * (vp * vp + vn * vn) ** 1.5)
    # circulation alone (no strips): its force is across the centre's velocity through the water
    pf = PF.copy()
    pf[plate.P_CD0] = pf[plate.P_CD90] = pf[plate.P_CLMAX] = 0.0
    for _ in range(200):
        theta, w, ux, uy = rng.uniform(-3, 3), rng.normal(0, 4), rng.normal(0, 0.3), rng.normal(0, 0.3)
        fx, fy, moment = plate.plate_force(theta, w, ux, uy, pf)
        psi = theta + pf[plate.P_PHI]
        centre = 0.5 * RADIUS * w * np.array([-math.sin(psi), math.cos(psi)]) - (ux, uy)
        assert fx * centre[0] + fy * centre[1] == pytest.approx(0.0, abs=1e-12)
        # and its moment about the shaft is its force at the centre
        assert moment == pytest.approx(0.5 * RADIUS * (-fx * math.sin(psi) + fy * math.cos(psi)), abs=1e-12)


def test_the_null_plant_ignores_the_flow_and_pays_for_its_thrust() -> None:
    null = _pf(model="still_water")
    for args in [(0.3, 2.0, 0.5), (-1.0, -4.0, 10.0), (2.0, 6.0, -20.0)]:
        still = plate.fin_load(*args, 0.0, 0.0, 1e-4, 1e-3, null)
        moving = plate.fin_load(*args, 0.3, 0.1, 1e-4, 1e-3, null)
        assert moving[:2] == still[:2]
        assert moving[4] == pytest.approx(-(still[0] * 0.3 + still[1] * 0.1))
        assert moving[2] == pytest.approx(still[2] + moving[4] / args[1])  # the thrust's work as a torque


def test_at_a_given_force_and_speed_the_null_plant_costs_the_same_at_any_frequency() -> None:
    """The null case: two ways to make one forward force at 0.3 m/s (a short fast stroke and
    a long slow one) cost the same shaft power per unit of force to within the stroke's
    shape (its Strouhal number changes threefold)."""
    null = _pf(model="still_water")
    centre = -plate.plate_angle(C_D, C_L)
    flow = 0.3 * math.cos(math.radians(30))
    cost = []
    for amplitude, rate in ((0.2, 4.5), (0.6, 1.5 * 1.73)):
        fx, _, _, useful, raw = _cycle(null, centre, amplitude, rate, flow, 0.0, acceleration=5000.0)
        still = _cycle(null, centre, amplitude, rate, 0.0, 0.0, acceleration=5000.0)
        assert raw == pytest.approx(still[4] + useful, rel=1e-6)
        cost.append((raw - useful) / (-fx) ** 1.5)  # still-water power per force^1.5
    assert cost[0] == pytest.approx(cost[1], rel=0.1)


def test_nothing_in_the_plate_reads_a_strouhal_number_or_a_frequency() -> None:
    text = Path(plate.__file__).read_text()
    code = text.split('"""', 2)[2]  # after the module docstring
    assert not re.search(r"strouhal|frequency|fin_length|\bl_f\b", code, re.IGNORECASE)
    assert not re.search(r"\bSt\b", code)


def test_a_beating_plant_never_does_more_work_on_the_hull_than_its_shafts() -> None:
    """The whole plant from rest: the fins beat while the hull speeds up; the work the fins did
    on the hull stays below the shafts' energy, and the hull's kinetic energy below that work."""
    from ucat_console.backend.sim.plant import Plant

    p = Plant(PlantConfig())
    centre = -plate.plate_angle(C_D, C_L)
    for k in range(40):
        for i in range(4):
            p.command_fin(i, centre + (0.5 if k % 2 == 0 else -0.5), 4.0)
        p.advance(0.25)
    work, energy = sum(p.fin_work()), sum(p.fin_energy())
    u = p.body_velocity()[0]
    assert u > 0.05
    assert 0.0 < work < energy
    assert 0.5 * (22.0 + 40.0) * u * u < work
