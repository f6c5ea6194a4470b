"""Strouhal number, surrogate and cost terms (eqs 10-17) in both implementations."""

import math

import numpy as np
import pytest

from ucat_console.control import FinMpc, MpcConfig
from ucat_console.control.cost import cost_terms, eta_hat, strouhal, strouhal_penalty, timed_rates
from ucat_console.control.params import ExecutorConfig

CFG = MpcConfig()
U_PREV = np.array([0.5, -0.5, 2.0, 2.0])


def test_strouhal_hand_computed():
    # d = (0.8, -0.4), w = (2, 4): dt = (0.4, 0.1) s, f = 2 / (2 * 0.5) = 2 Hz,
    # A = mean(0.8 * 0.1 / 2, 0.4 * 0.1 / 2) = 0.03 m, St = 2 * 2 * 0.03 / 0.3 = 0.4
    assert strouhal([0.8, -0.4, 2.0, 4.0], 0.3, CFG) == pytest.approx(0.4)
    # below the speed floor V_B is replaced by v_floor = 0.05: St = 0.12 / 0.05
    assert strouhal([0.8, -0.4, 2.0, 4.0], 0.01, CFG) == pytest.approx(2.4)


def test_equal_strokes_give_st_independent_of_amplitude():
    # control.md: for H = 2 with equal |d|, St = w L_f / (2 V_B)
    for d in (0.1, 0.7, 1.2):
        assert strouhal([d, -d, 3.0, 3.0], 0.25, CFG) == pytest.approx(3.0 * 0.1 / 0.5)


def test_surrogate_peaks_at_st_opt_and_is_asymmetric():
    st = np.linspace(0.01, 1.0, 10_001)
    eta = eta_hat(st, CFG)
    assert st[np.argmax(eta)] == pytest.approx(CFG.st_opt, abs=1e-4)
    assert eta.max() == pytest.approx(CFG.eta_max, abs=1e-8)  # grid step 1e-4 off the peak
    assert eta_hat(CFG.st_opt, CFG) == pytest.approx(CFG.eta_max, abs=1e-15)
    assert strouhal_penalty(CFG.st_opt, CFG) == pytest.approx(0.0, abs=1e-15)
    # the same distance below the peak costs more than above it (Floryan et al.)
    for delta in (0.05, 0.1, 0.2):
        below = strouhal_penalty(CFG.st_opt - delta, CFG)
        above = strouhal_penalty(CFG.st_opt + delta, CFG)
        assert below > above > 0
    # hand value: St = 0.15, x = 0.5: eta = 0.5 e^0.5 = 0.824361
    assert strouhal_penalty(0.15, CFG) == pytest.approx(1 - 0.5 * math.exp(0.5), abs=1e-9)


def test_cost_terms_hand_computed():
    # theta0 = 0, u = (0.8, -0.4, 2, 4), target (-0.2, 0.3), V = 0.3
    u = np.array([0.8, -0.4, 2.0, 4.0])
    t = cost_terms(u, np.array([-0.2, 0.3]), 0.3, 0.0, U_PREV, CFG)
    # stroke 1: v = 0.2, L = 0.1, D = 0.28, thr = 0.4, mid angle 0.4
    # stroke 2: v = 0.4, L = 0.4, D = 1.12, thr = -0.2, mid angle 0.8 - 0.2 = 0.6
    def body(theta_mid, lift, drag, thr):
        fxl = -lift * math.cos(thr) - drag * math.sin(thr)
        fyl = -lift * math.sin(thr) - drag * math.cos(thr)
        c, s = math.cos(theta_mid), math.sin(theta_mid)
        return c * fxl - s * fyl, s * fxl + c * fyl

    f1 = body(0.4, 0.1, 0.28, 0.4)
    f2 = body(0.6, 0.4, 1.12, -0.2)
    w1, w2 = 0.4 / 0.5, 0.1 / 0.5  # W_k = dt_k / sum dt
    fbx = w1 * f1[0] + w2 * f2[0]
    fby = w1 * f1[1] + w2 * f2[1]
    assert t["fbx"] == pytest.approx(fbx, abs=1e-12)
    assert t["fby"] == pytest.approx(fby, abs=1e-12)
    c_force = abs(fbx + 0.2) + abs(fby - 0.3)
    assert t["force"] == pytest.approx(c_force, abs=1e-12)
    c_st = 1 - (0.4 / 0.3) * math.exp(1 - 0.4 / 0.3)
    assert t["strouhal_penalty"] == pytest.approx(c_st, abs=1e-12)
    # A_k = 0.04 and 0.02 m: only the second is below A_min = 0.03
    assert t["amplitude"] == pytest.approx(0.01, abs=1e-12)
    # c_diff = 0.5 (|0.8-0.5| + |-0.4+0.5| + |2-2| + |4-2|) = 1.2
    assert t["smoothness"] == pytest.approx(1.2, abs=1e-12)
    assert t["total"] == pytest.approx(1.5 * c_force + 5.0 * c_st + 1.0 * 0.01 + 1.0 * 1.2, abs=1e-12)


@pytest.mark.parametrize("force_model", ["analytic", "table"])
def test_compiled_cost_agrees_with_reference(force_model):
    cfg = CFG.replace(force_model=force_model)
    mpc = FinMpc(cfg)
    rng = np.random.default_rng(11)
    for _ in range(300):
        s = rng.choice([-1.0, 1.0])
        u = np.array([
            s * rng.uniform(cfg.d_eps, cfg.d_max), -s * rng.uniform(cfg.d_eps, cfg.d_max),
            rng.uniform(cfg.w_min, cfg.w_max), rng.uniform(cfg.w_min, cfg.w_max),
        ])
        f = rng.uniform([-1.0, 0.0], [0.0, 1.0])
        v = rng.uniform(0.0, 0.6)
        th = rng.uniform(-math.pi, math.pi)
        up = np.array([0.3, -0.7, 1.0, 5.0])
        got = mpc.cost(u, f, v, th, up)
        ref = cost_terms(u, f, v, th, up, cfg, mpc.table)
        assert got.total == pytest.approx(float(ref["total"]), abs=1e-9)
        assert got.force == pytest.approx(float(ref["force"]), abs=1e-9)
        assert got.strouhal_penalty == pytest.approx(float(ref["strouhal_penalty"]), abs=1e-9)
        assert got.amplitude == pytest.approx(float(ref["amplitude"]), abs=1e-12)
        assert got.smoothness == pytest.approx(float(ref["smoothness"]), abs=1e-12)
        assert got.st == pytest.approx(float(ref["st"]), abs=1e-12)


def test_analytic_gradient_matches_finite_differences():
    mpc = FinMpc(CFG)
    rng = np.random.default_rng(5)
    checked = 0
    for _ in range(200):
        u = np.array([rng.uniform(0.1, 1.1), -rng.uniform(0.1, 1.1), rng.uniform(1, 7), rng.uniform(1, 7)])
        args = (np.array([-0.4, 0.3]), 0.3, 0.4, U_PREV)
        g = mpc.cost_gradient(u, *args)
        h = 1e-7
        fd = np.zeros(4)
        for i in range(4):
            e = np.zeros(4)
            e[i] = h
            fd[i] = (cost_terms(u + e, *args, CFG)["total"] - cost_terms(u - e, *args, CFG)["total"]) / (2 * h)
        # skip points within h of a kink (1-norm, max(0, .)), where the two differ by design
        if np.allclose(g, fd, atol=1e-5):
            checked += 1
    assert checked >= 190


# ------------------------------------------------------------------ the drive's timing
DRIVE = ExecutorConfig()  # 64 rad/s2, 10 rad/s


def test_timed_rates_cap_each_rate_at_the_triangle_a_stroke_allows():
    u = np.array([1.0, -0.25, 7.0, 1.0])
    capped = timed_rates(u, CFG, (64.0, 10.0))
    # a stroke of 1 rad from rest to rest at 64 rad/s2: at best sqrt(64 * 1) / 2 = 4 rad/s
    assert capped[2] == pytest.approx(4.0)
    assert capped[3] == 1.0  # 0.25 rad allows 2 rad/s: 1 rad/s stays
    assert list(capped[:2]) == [1.0, -0.25]


@pytest.mark.parametrize("formulation", ["paper", "closed_stroke"])
def test_compiled_cost_with_the_drive_agrees_with_reference(formulation):
    cfg = CFG.replace(formulation=formulation)
    mpc = FinMpc(cfg, drive=DRIVE)
    rng = np.random.default_rng(12)
    capped = 0
    for _ in range(300):
        s = rng.choice([-1.0, 1.0])
        u = np.array([
            s * rng.uniform(cfg.d_eps, cfg.d_max), -s * rng.uniform(cfg.d_eps, cfg.d_max),
            rng.uniform(cfg.w_min, cfg.w_max), rng.uniform(cfg.w_min, cfg.w_max),
        ])
        f = rng.uniform([-1.0, 0.0], [0.0, 1.0])
        v = rng.uniform(0.0, 0.6)
        th = rng.uniform(-math.pi, math.pi)
        up = np.array([0.3, -0.7, 1.0, 5.0])
        got = mpc.cost(u, f, v, th, up)
        ref = cost_terms(u, f, v, th, up, cfg, None, (DRIVE.acceleration, DRIVE.max_rate))
        capped += not np.array_equal(timed_rates(u, cfg, (64.0, 10.0)), u)
        assert got.total == pytest.approx(float(ref["total"]), abs=1e-9)
        assert got.st == pytest.approx(float(ref["st"]), abs=1e-12)
        assert got.mean_force == pytest.approx((float(ref["fbx"]), float(ref["fby"])), abs=1e-12)
    assert capped > 100  # most of the box asks for more than the drive makes


def test_the_gradient_with_the_drive_matches_finite_differences():
    """Where a rate is capped, the cost moves with the stroke (the cap grows with it) and
    not with the rate: the analytic gradient says so."""
    mpc = FinMpc(CFG, drive=DRIVE)
    drive = (DRIVE.acceleration, DRIVE.max_rate)
    rng = np.random.default_rng(6)
    checked = flat = 0
    for _ in range(200):
        u = np.array([rng.uniform(0.1, 1.1), -rng.uniform(0.1, 1.1), rng.uniform(1, 7), rng.uniform(1, 7)])
        args = (np.array([-0.4, 0.3]), 0.3, 0.4, U_PREV)
        g = mpc.cost_gradient(u, *args)
        h = 1e-7
        fd = np.zeros(4)
        for i in range(4):
            e = np.zeros(4)
            e[i] = h
            fd[i] = (cost_terms(u + e, *args, CFG, None, drive)["total"]
                     - cost_terms(u - e, *args, CFG, None, drive)["total"]) / (2 * h)
        if np.allclose(g, fd, atol=1e-5):
            checked += 1
            flat += g[2] == 0.0 or g[3] == 0.0
    assert checked >= 185
    assert flat > 50  # capped rates seen, with their zero partial derivative
