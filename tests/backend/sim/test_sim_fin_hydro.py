"""Where the fins meet the hull: the recorded Strouhal number, the body wrench and the flow
past each fin (its transpose)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ucat_console.backend.sim.fin_hydro import (
    add_fin_wrench,
    fin_flow,
    fin_sign_table,
    fin_strouhal,
    hydro_params,
)
from ucat_console.backend.sim.params import FinGeometryConfig, FinHydroConfig

GEOM = FinGeometryConfig()
PAPER_QS = hydro_params(FinHydroConfig(), GEOM)


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


def test_the_flow_past_a_fin_is_the_transpose_of_its_wrench() -> None:
    """The power a fin's force puts into the hull, tau . nu, equals its force times its
    hinge's velocity through the water, f . v with v = -(flow): no power is lost or made
    between the fin and the hull."""
    rng = np.random.default_rng(3)
    signs = fin_sign_table()
    for _ in range(200):
        i = int(rng.integers(4))
        f = rng.normal(size=2)
        nu = rng.normal(size=6)
        tau = np.zeros(6)
        add_fin_wrench(f[0], f[1], *signs[i], PAPER_QS, tau)
        ux, uy = fin_flow(nu, *signs[i], PAPER_QS)
        assert float(tau @ nu) == pytest.approx(-(f[0] * ux + f[1] * uy), abs=1e-12)


def test_surging_forward_the_water_passes_every_fin_rearwards() -> None:
    signs = fin_sign_table()
    for i in range(4):
        ux, uy = fin_flow(np.array([0.3, 0.0, 0.0, 0.0, 0.0, 0.0]), *signs[i], PAPER_QS)
        assert ux == pytest.approx(0.3 * math.cos(math.radians(30))) and uy == 0.0
        # diving (w > 0, body z down): the water passes the fin upwards (y_m up)
        ux, uy = fin_flow(np.array([0.0, 0.0, 0.1, 0.0, 0.0, 0.0]), *signs[i], PAPER_QS)
        assert ux == 0.0 and uy == pytest.approx(0.1)
