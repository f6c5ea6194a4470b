"""Fin hydrodynamics: quasi-steady force, stroke mean, wake factor, body wrench."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ucat_console.backend.sim.fin_hydro import (
    add_fin_wrench,
    fin_force,
    fin_sign_table,
    fin_strouhal,
    hydro_params,
    wake_factor,
)
from ucat_console.backend.sim.params import FinGeometryConfig, FinHydroConfig
from ucat_console.robot.servo import servo_step

GEOM = FinGeometryConfig()
PAPER_QS = hydro_params(FinHydroConfig(coefficients="paper", wake="quasi_steady"), GEOM)
SOFT_QS = hydro_params(FinHydroConfig(coefficients="soft_fin", wake="quasi_steady"), GEOM)
SOFT_WAKE = hydro_params(FinHydroConfig(coefficients="soft_fin", wake="strouhal_wake"), GEOM)


@pytest.mark.parametrize("ph", [PAPER_QS, SOFT_QS, SOFT_WAKE])
@pytest.mark.parametrize(("theta", "theta_s", "st"), [(0.0, 0.0, 0.3), (0.7, -0.4, 1.5), (-1.2, 0.1, 0.0)])
def test_zero_rate_gives_zero_force(ph: np.ndarray, theta: float, theta_s: float, st: float) -> None:
    fx, fy, _ = fin_force(theta, 0.0, theta_s, st, ph)
    assert fx == 0.0 and fy == 0.0


def test_force_at_a_point_by_hand() -> None:
    # w = 3: v = 0.3, q = 0.5*1000*0.02*0.09 = 0.9; L = 0.225, D = 0.63; at thr = theta = 0
    fx, fy, scale = fin_force(0.0, 3.0, 0.0, 0.3, PAPER_QS)
    assert (fx, fy, scale) == pytest.approx((-0.225, -0.63, 1.0))
    # soft-fin gain scales only the forward (f_x < 0) part
    fx, fy, scale = fin_force(0.0, 3.0, 0.0, 0.3, SOFT_QS)
    assert (fx, fy, scale) == pytest.approx((-0.225 * 4.6, -0.63, 4.6))
    # rotated by theta = pi/2: (f_x, f_y) = (-fyl, fxl) = (0.63, -0.225): backward, not scaled
    fx, fy, _ = fin_force(math.pi / 2, 3.0, math.pi / 2, 0.3, SOFT_QS)
    assert (fx, fy) == pytest.approx((0.63, -0.225))


def _stroke_mean(theta0: float, d: float, vel: float, ph: np.ndarray) -> tuple[np.ndarray, float]:
    th, om, f, t = theta0, 0.0, np.zeros(2), 0.0
    while True:
        th, om, _ = servo_step(th, om, theta0 + d, vel, 64.0, 10.0, 0.001)
        t += 0.001
        fx, fy, _ = fin_force(th, om, theta0, 0.3, ph)
        f += (fx, fy)
        if om == 0.0:
            return f * 0.001 / t, t


@pytest.mark.parametrize(("theta0", "d", "vel"), [(-0.6, 0.6, 3.0), (0.0, -0.6, 3.0), (-1.0, 1.2, 4.0)])
def test_stroke_mean_follows_the_controller_form(theta0: float, d: float, vel: float) -> None:
    """Over a servo stroke the plant's force averages to the (d, w) model of control.md s.1."""
    f, t = _stroke_mean(theta0, d, vel, PAPER_QS)
    w = abs(d) / t
    q = 0.5 * 1000 * 0.020 * (0.10 * w) ** 2
    lift, drag = 0.25 * q, 0.70 * q
    thr, thm = d / 2, theta0 + d / 2
    fxl = -lift * math.cos(thr) - drag * math.sin(thr)
    fyl = -lift * math.sin(thr) - drag * math.cos(thr)
    ref = np.array([math.cos(thm) * fxl - math.sin(thm) * fyl, math.sin(thm) * fxl + math.cos(thm) * fyl])
    # the trapezoid's mean w^2 exceeds (mean w)^2, so the plant is somewhat stronger
    assert 1.0 < np.linalg.norm(f) / np.linalg.norm(ref) < 1.25
    angle = math.atan2(f[1], f[0]) - math.atan2(ref[1], ref[0])
    assert abs(angle) < 0.1


def test_stroke_below_neutral_makes_thrust() -> None:
    """A stroke centred 0.3 rad below neutral has f_x < 0: forward propulsion."""
    for d in (0.6, -0.6):
        theta0 = -0.3 - d / 2
        f, _ = _stroke_mean(theta0, d, 3.0, SOFT_WAKE)
        assert f[0] < 0.0


def test_wake_factor_peak_and_asymmetry() -> None:
    c = FinHydroConfig()
    st = np.linspace(0.0, 2.0, 20001)
    w = np.array([wake_factor(s, c.st_peak, c.sigma_low, c.sigma_high, c.floor) for s in st])
    peak = st[np.argmax(w)]
    assert 0.25 <= peak <= 0.35
    assert w.max() == pytest.approx(1.0)
    for delta in (0.02, 0.05, 0.1, 0.2):
        below = wake_factor(peak - delta, c.st_peak, c.sigma_low, c.sigma_high, c.floor)
        above = wake_factor(peak + delta, c.st_peak, c.sigma_low, c.sigma_high, c.floor)
        assert below < above  # falls faster below the peak
    assert w[-1] == pytest.approx(c.floor, abs=1e-6)
    # split Gaussian by hand: W(0.15) = 0.25 + 0.75 exp(-0.5 (0.15/0.08)^2)
    assert wake_factor(0.15, 0.30, 0.08, 0.20, 0.25) == pytest.approx(0.25 + 0.75 * math.exp(-0.5 * (0.15 / 0.08) ** 2))


def test_wake_scales_thrust_with_strouhal_only_in_strouhal_wake() -> None:
    near, far = 0.3, 1.5
    fx_near, _, s_near = fin_force(0.0, 3.0, 0.0, near, SOFT_WAKE)
    fx_far, _, s_far = fin_force(0.0, 3.0, 0.0, far, SOFT_WAKE)
    assert s_near == pytest.approx(4.6) and fx_near < fx_far < 0.0
    assert fin_force(0.0, 3.0, 0.0, near, SOFT_QS) == fin_force(0.0, 3.0, 0.0, far, SOFT_QS)


def test_fin_strouhal_number() -> None:
    # St = w_bar L_f / (2 max(|u|, v_floor)) with L_f = 0.10: 6 * 0.1 / 0.6 = 1.0
    assert fin_strouhal(6.0, 0.3, PAPER_QS) == pytest.approx(1.0)
    assert fin_strouhal(6.0, -0.3, PAPER_QS) == pytest.approx(1.0)
    assert fin_strouhal(0.6, 0.0, PAPER_QS) == pytest.approx(0.6 * 0.1 / (2 * 0.05))


def test_body_wrench_of_single_fins_by_hand() -> None:
    signs = fin_sign_table()
    c30, s30 = math.cos(math.radians(30)), 0.5
    # front-right fin, forward thrust f_x = -1: forward, outwards (starboard), nose to port
    tau = np.zeros(6)
    add_fin_wrench(-1.0, 0.0, *signs[0], PAPER_QS, tau)
    assert tau == pytest.approx([c30, s30, 0.0, 0.0, 0.0, -0.2981])
    # back-left fin, forward thrust: forward, inwards (starboard), nose to starboard
    tau = np.zeros(6)
    add_fin_wrench(-1.0, 0.0, *signs[2], PAPER_QS, tau)
    assert tau == pytest.approx([c30, s30, 0.0, 0.0, 0.0, 0.2981])
    # front-right fin, upward force f_y = 1: F_z = -1, roll to port (K < 0), nose up (M > 0)
    tau = np.zeros(6)
    add_fin_wrench(0.0, 1.0, *signs[0], PAPER_QS, tau)
    assert tau == pytest.approx([0.0, 0.0, -1.0, -0.1502, 0.25753, 0.0])
    # back-left fin, upward: roll to starboard, nose down
    tau = np.zeros(6)
    add_fin_wrench(0.0, 1.0, *signs[2], PAPER_QS, tau)
    assert tau == pytest.approx([0.0, 0.0, -1.0, 0.1502, -0.25753, 0.0])


def test_equal_fins_give_pure_surge_and_heave() -> None:
    signs = fin_sign_table()
    tau = np.zeros(6)
    for i in range(4):
        add_fin_wrench(-0.5, 0.2, *signs[i], PAPER_QS, tau)
    assert tau == pytest.approx([4 * 0.5 * math.cos(math.radians(30)), 0.0, -0.8, 0.0, 0.0, 0.0], abs=1e-12)
