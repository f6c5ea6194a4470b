"""The foil plant (``foil_inflow``) against hand-computed strip forces."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from ucat_console.backend.sim import foil
from ucat_console.backend.sim.fin_hydro import hydro_params
from ucat_console.backend.sim.params import FinGeometryConfig, FinHydroConfig

GEOM = FinGeometryConfig()
RHO, CD, CL, AREA, RC, GAIN = 1000.0, 0.7, 0.25, 0.020, 0.10, 4.6  # the soft fin's (plant.md)


def _ph(cd0: float = 0.1) -> np.ndarray:
    return hydro_params(FinHydroConfig(coefficients="soft_fin", wake="foil_inflow", foil_cd0=cd0), GEOM)


def _still_water(theta: float, omega: float, theta_s: float) -> tuple[float, float]:
    """The soft fin's quasi-steady force by hand (fin_hydro's docstring), thrust gain on f_x < 0."""
    q = 0.5 * RHO * AREA * (RC * omega) ** 2
    lift, drag = CL * q, CD * q
    thr = theta - theta_s
    fxl = -lift * math.cos(thr) - drag * math.sin(thr)
    fyl = -lift * math.sin(thr) - drag * math.cos(thr)
    fx = math.cos(theta) * fxl - math.sin(theta) * fyl
    fy = math.sin(theta) * fxl + math.cos(theta) * fyl
    return (fx * GAIN if fx < 0.0 else fx), fy


@pytest.mark.parametrize("theta,omega,theta_s,alpha", [(-1.2, 2.0, -1.7, 0.0), (0.4, -3.0, 1.0, 5.0),
                                                       (2.5, 1.0, 2.5, -4.0), (-0.3, 0.0, -0.3, 0.0)])
def test_zero_speed_is_the_quasi_steady_fin(theta: float, omega: float, theta_s: float, alpha: float) -> None:
    inertia = 1e-4
    fx, fy, gain, power = foil.foil_fin(theta, omega, theta_s, alpha, 0.0, inertia, _ph())
    hx, hy = _still_water(theta, omega, theta_s)
    assert fx == pytest.approx(hx, rel=1e-12, abs=1e-15)
    assert fy == pytest.approx(hy, rel=1e-12, abs=1e-15)
    assert gain == GAIN
    k_d = 0.5 * RHO * CD * AREA * RC**3
    # the plate's added inertia (a strip's 2-D added mass rho pi c^2 / 4 over R = sqrt(3) r_c,
    # c = A_f / R) loads the shaft when the fin accelerates; at a steady rate the power is the
    # quasi-steady model's k_D |w|^3
    radius = math.sqrt(3.0) * RC
    added = RHO * math.pi * (AREA / radius) ** 2 * radius**3 / 12.0
    assert power == pytest.approx(max(0.0, k_d * abs(omega) ** 3 + (inertia + added) * alpha * omega), abs=1e-15)


@pytest.mark.parametrize("alpha_deg", [0.0, 10.0, 30.0, 45.0, 60.0, 90.0, -20.0, 150.0])
def test_lift_and_drag_at_a_known_angle_of_attack(alpha_deg: float) -> None:
    cd0, cd90, clmax = 0.1, 2.0, 1.2
    a = math.radians(alpha_deg)
    c_l, c_d = foil.lift_drag(a, cd0, cd90, clmax)
    assert c_l == pytest.approx(clmax * math.sin(2 * a))
    assert c_d == pytest.approx(cd0 + cd90 * math.sin(a) ** 2)
    # tabulated: 30 deg gives C_L = 1.2 sin 60 = 1.0392, C_D = 0.1 + 2 / 4 = 0.6
    if alpha_deg == 30.0:
        assert (c_l, c_d) == (pytest.approx(1.03923, abs=1e-5), pytest.approx(0.6))
    # a strip in a unit flow at that angle: drag along the flow, lift across it (turned +90 deg)
    speed = 0.3
    vp, vn = speed * math.cos(a), speed * math.sin(a)
    fp, fn = foil.strip_force(vp, vn, cd0, cd90, clmax)
    along = (fp * vp + fn * vn) / speed
    across = (-fp * vn + fn * vp) / speed
    assert along == pytest.approx(c_d * speed**2, abs=1e-12)
    assert across == pytest.approx(c_l * speed**2, abs=1e-12)


def test_a_fin_at_rest_aligned_with_the_stream_feels_its_profile_drag() -> None:
    """At rest with the plate along the stream (alpha 0): F = rho A_f U^2 C_D0 / 2 rearwards."""
    ph = _ph(cd0=0.1)
    pf = ph[foil.H_FOIL:]
    theta = -pf[foil.P_PHI]  # plate line psi = theta + phi = 0
    u = 0.3
    fx, fy, _ = foil.stream_force(theta, 0.0, u, pf)
    assert fx == pytest.approx(0.5 * RHO * AREA * u**2 * 0.1, rel=1e-9)
    assert fy == pytest.approx(0.0, abs=1e-12)
    # and with the plate across the stream (alpha 90 deg): C_D0 + C_D90, no lift
    fx, fy, _ = foil.stream_force(theta + math.pi / 2, 0.0, u, pf)
    assert math.hypot(fx, fy) == pytest.approx(0.5 * RHO * AREA * u**2 * 2.1, rel=1e-9)


def test_shaft_power_is_never_negative() -> None:
    rng = np.random.default_rng(3)
    ph = _ph(cd0=0.02)
    powers = [foil.foil_fin(rng.uniform(-math.pi, math.pi), rng.uniform(-8, 8), rng.uniform(-math.pi, math.pi),
                            rng.uniform(-400, 400), rng.uniform(0.0, 0.5), 1e-4, ph)[3] for _ in range(5000)]
    assert min(powers) >= 0.0
    assert max(powers) > 0.0  # the fin does work


def test_the_stream_loads_the_shaft() -> None:
    """In a stream the strips' moment changes the shaft power (the plant's power path reads it)."""
    ph = _ph()
    still = foil.foil_fin(-1.0, 3.0, -1.6, 0.0, 0.0, 1e-4, ph)[3]
    moving = foil.foil_fin(-1.0, 3.0, -1.6, 0.0, 0.3, 1e-4, ph)[3]
    assert moving != pytest.approx(still, rel=1e-3)


def test_no_strouhal_number_in_the_foil_module() -> None:
    text = Path(foil.__file__).read_text()
    assert not re.search(r"strouhal|\bst\b|\bst_|_st\b", text, re.IGNORECASE)
    assert "fin_strouhal" not in text and "wake_factor" not in text
