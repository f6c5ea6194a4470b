"""The closed-stroke formulation: its cost terms, its gradient, exact closure, and the
slow-and-fast loophole of eq 10 that its per-stroke Strouhal penalty refuses."""

import math

import numpy as np
import pytest

from ucat_console.control import FinMpc, MpcConfig
from ucat_console.control.cost import cost_terms
from ucat_console.robot.fin_plate import STROKE_INERTIA

CFG = MpcConfig(formulation="closed_stroke")
U_PREV = np.array([0.5, -0.5, 2.0, 2.0])
FORWARD = -1.2277  # centre of a forward-thrust stroke pair under the paper's coefficients


def test_closed_stroke_terms_hand_computed():
    # u = (0.6, -0.4, 3, 2) at V = 0.2 m/s from theta0 = 0
    u = np.array([0.6, -0.4, 3.0, 2.0])
    t = cost_terms(u, np.array([-0.2, 0.1]), 0.2, 0.0, U_PREV, CFG)
    # St_k = w_k L_f / (2 V) = 0.75 and 0.5; c(St) = 1 - x e^{1-x}, x = St / 0.3
    c1 = 1 - 2.5 * math.exp(1 - 2.5)
    c2 = 1 - (0.5 / 0.3) * math.exp(1 - 0.5 / 0.3)
    assert t["strouhal_penalty"] == pytest.approx(0.5 * (c1 + c2), abs=1e-12)
    # opening |0.6 - 0.4| = 0.2 rad
    assert t["closure"] == pytest.approx(0.2, abs=1e-12)
    # k_D = 0.5 * 1000 * 0.7 * 0.02 * 0.1^3 = 0.007; I = 2.8e-5
    # E = 0.007 (0.6 * 9 + 0.4 * 4) + 1.4e-5 (9 + 4) = 0.049182 J; T = 0.2 + 0.2 = 0.4 s
    energy = 0.007 * (0.6 * 9 + 0.4 * 4) + 1.4e-5 * 13
    assert t["energy"] == pytest.approx(energy / 0.4, abs=1e-12)
    paper = cost_terms(u, np.array([-0.2, 0.1]), 0.2, 0.0, U_PREV, MpcConfig())
    # force, amplitude and smoothness are the paper's; the cycle St reported is eq 10's
    for key in ("force", "amplitude", "smoothness", "st", "fbx", "fby"):
        assert t[key] == pytest.approx(float(paper[key]), abs=1e-15)
    assert paper["closure"] == 0.0 and paper["energy"] == 0.0
    expected = (1.5 * t["force"] + 5.0 * 0.5 * (c1 + c2) + 1.0 * t["amplitude"] + 1.0 * t["smoothness"]
                + 0.3 * 0.2 + 1.0 * energy / 0.4)
    assert t["total"] == pytest.approx(expected, abs=1e-12)


def test_each_stroke_is_charged_for_the_blade_the_water_and_the_rotor_it_spins_up():
    # blade 2.8e-5 (eeUVsim); water: a plate R = sqrt(3) 0.1 m from the shaft, span 0.02 / R,
    # 1000 pi span^2 R^3 / 12; rotor: 1.35e-5 kg m2 through a 35:1 gearhead
    radius = math.sqrt(3.0) * 0.1
    water = 1000.0 * math.pi * (0.02 / radius) ** 2 * radius ** 3 / 12.0
    assert water == pytest.approx(0.01814, abs=1e-5)
    assert STROKE_INERTIA == pytest.approx(2.8e-5 + water + 1.35e-5 * 35.0 ** 2, rel=1e-12)


def test_a_cruise_is_planned_with_long_strokes_whatever_the_seed():
    """Making the same forward force at the same rate, short strokes reverse more often; with
    the reversals charged for what the drive spins up, every seed of the solver settles on a
    long stroke (with the blade's inertia alone, 0.44-0.93 rad over these seeds)."""
    cfg = CFG.replace(lam_f=10.0, lam_st=2.0, lam_d=0.3, centre_rate=3.0, max_cycle=1.0,  # sim-tuned's
                      fin_inertia=STROKE_INERTIA)
    lengths = []
    for seed in range(10):
        mpc = FinMpc(cfg, seed=seed)
        u, theta = (0.4, -0.4, 3.0, 3.0), FORWARD + 0.2
        for k in range(6):  # a few cycles of a cruise at 0.2 m/s, each from where the last ended
            u = mpc.plan((-0.45, 0.0), 0.2, theta, u, seed=100 * seed + k).u
            theta += u[0] + u[1]
        lengths.append(abs(u[0]) + abs(u[1]))
    assert min(lengths) >= 0.8


@pytest.mark.parametrize("force_model", ["analytic", "table"])
def test_compiled_closed_stroke_cost_agrees_with_reference(force_model):
    cfg = CFG.replace(force_model=force_model, lam_e=20.0, lam_c=2.0)
    mpc = FinMpc(cfg)
    rng = np.random.default_rng(3)
    for _ in range(200):
        s = rng.choice([-1.0, 1.0])
        u = np.array([s * rng.uniform(0.05, 1.2), -s * rng.uniform(0.05, 1.2),
                      rng.uniform(0.5, 8.0), rng.uniform(0.5, 8.0)])
        f, v, th = rng.uniform([-1.0, 0.0], [0.0, 1.0]), rng.uniform(0.0, 0.6), rng.uniform(-3.1, 3.1)
        got = mpc.cost(u, f, v, th, U_PREV)
        ref = cost_terms(u, f, v, th, U_PREV, cfg, mpc.table)
        assert got.total == pytest.approx(float(ref["total"]), abs=1e-9)
        assert got.strouhal_penalty == pytest.approx(float(ref["strouhal_penalty"]), abs=1e-9)
        assert got.closure == pytest.approx(float(ref["closure"]), abs=1e-12)
        assert got.energy == pytest.approx(float(ref["energy"]), abs=1e-12)


def test_closed_stroke_gradient_matches_finite_differences():
    cfg = CFG.replace(lam_e=20.0, lam_c=2.0)  # terms large enough to show in the gradient
    mpc = FinMpc(cfg)
    rng = np.random.default_rng(8)
    checked = 0
    for _ in range(200):
        u = np.array([rng.uniform(0.1, 1.1), -rng.uniform(0.1, 1.1), rng.uniform(0.6, 7), rng.uniform(0.6, 7)])
        args = (np.array([-0.4, 0.3]), 0.2, 0.4, U_PREV)
        g = mpc.cost_gradient(u, *args)
        h = 1e-7
        fd = np.array([(cost_terms(u + h * e, *args, cfg)["total"] - cost_terms(u - h * e, *args, cfg)["total"])
                       / (2 * h) for e in np.eye(4)])
        if np.allclose(g, fd, atol=1e-5):  # points within h of a kink differ by design
            checked += 1
    assert checked >= 190


def test_closed_strokes_are_returned_exactly():
    mpc = FinMpc(CFG.replace(lam_f=3.0, lam_st=2.0, lam_d=0.3), seed=1)
    closed = 0
    cases = [((fx, 0.0), v, FORWARD + 0.3 * k) for fx in (-0.1, -0.3) for v in (0.15, 0.3) for k in (-1, 0, 1)]
    for target, v, theta in cases:
        u_prev = (0.6, -0.6, 2.0, 2.0)
        for _ in range(4):  # a few cycles from the same start: the receding horizon's steady state
            p = mpc.plan(target, v, theta, u_prev)
            u_prev = p.u
        closed += p.u[0] + p.u[1] == 0.0
        if p.u[0] + p.u[1] == 0.0:
            assert p.cost.closure == 0.0 and p.commands[2] == pytest.approx(theta, abs=1e-12)  # back at the start
    assert closed >= len(cases) - 1


def test_per_stroke_strouhal_penalty_refuses_slow_and_fast_strokes():
    # the loophole: a slow stroke and a fast return whose cycle St (eq 10) is in the corridor
    v = 0.27
    loophole = np.array([0.6, -0.6, 0.9, 8.0])
    target, theta0 = np.array([-0.3, 0.0]), FORWARD - 0.3
    paper = cost_terms(loophole, target, v, theta0, U_PREV, MpcConfig())
    closed = cost_terms(loophole, target, v, theta0, U_PREV, CFG)
    assert 0.25 <= float(paper["st"]) <= 0.35 and float(paper["strouhal_penalty"]) < 1e-3
    # St_1 = 0.17 and St_2 = 1.48: the fast stroke pays for its own St
    assert float(closed["strouhal_penalty"]) > 0.3
    # the same cycle with equal strokes at the rate of the same cycle St costs far less
    w = 2 * v * float(paper["st"]) / 0.1
    even = cost_terms(np.array([0.6, -0.6, w, w]), target, v, theta0, U_PREV, CFG)
    assert float(even["strouhal_penalty"]) < 0.01
    # and the solver does not plan such cycles where the paper's cost does: a demand the
    # corridor cannot meet (0.5 N at 0.2 m/s), three cycles from a neutral previous plan
    def rates(formulation):
        mpc = FinMpc(MpcConfig(formulation=formulation, lam_f=3.0, lam_st=2.0, lam_d=0.3), seed=2)
        u_prev, theta = (0.6, -0.6, 2.0, 2.0), FORWARD - 0.3
        for _ in range(3):
            p = mpc.plan((-0.5, 0.0), 0.2, theta, u_prev)
            u_prev, theta = p.u, theta + p.u[0] + p.u[1]
        return p.u[2:]

    slow_fast = rates("paper")
    assert max(slow_fast) / min(slow_fast) > 3.0
    even = rates("closed_stroke")
    assert max(even) / min(even) < 1.5


def test_bad_formulation_and_weights_are_refused():
    with pytest.raises(ValueError, match="formulation.*'closed'"):
        MpcConfig(formulation="closed")
    with pytest.raises(ValueError, match="lam_e"):
        MpcConfig(lam_e=-1.0)
    with pytest.raises(ValueError, match="lam_c"):
        MpcConfig(lam_c=-0.5)
    with pytest.raises(ValueError, match="solver.*numba"):
        MpcConfig(formulation="closed_stroke", solver="scipy")
