"""Fin power from encoder angles against the analytic answer for a sinusoid."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ucat_console.control.params import PowerConfig
from ucat_console.control.power import (
    PowerEstimator,
    energy_per_metre,
    fleet_mean_power,
    power_trace,
    time_mean,
)

PCFG = PowerConfig()
A, F = 0.5, 2.0
OMEGA = 2.0 * math.pi * F


def sinusoid(periods: int = 2, dt: float = 1e-4):
    t = np.arange(0.0, periods / F + dt / 2, dt)
    return t, A * np.sin(OMEGA * t)


def analytic_drag_mean() -> float:
    # w = A omega cos(omega t); mean |cos|^3 = 4 / (3 pi)
    k = 0.5 * PCFG.rho * PCFG.c_d * PCFG.fin_area * PCFG.r_c**3
    return k * (A * OMEGA) ** 3 * 4.0 / (3.0 * math.pi)


def analytic_inertial_mean(inertia: float) -> float:
    # I alpha w = -I A^2 omega^3 sin cos = -(I A^2 omega^3 / 2) sin(2 omega t);
    # mean of max(0, -sin) = 1 / pi  ->  I A^2 omega^3 / (2 pi)
    return inertia * A**2 * OMEGA**3 / (2.0 * math.pi)


def test_drag_power_of_a_sinusoid():
    t, theta = sinusoid()
    tr = power_trace(t, theta, PowerConfig(filter_tau=0.0))
    expected = analytic_drag_mean()  # 0.7369 W with the paper's coefficients
    assert expected == pytest.approx(0.7369, abs=1e-4)
    assert time_mean(tr.t, tr.p_drag) == pytest.approx(expected, rel=2e-3)


def test_inertial_power_of_a_sinusoid_is_rectified():
    inertia = 0.01
    t, theta = sinusoid()
    tr = power_trace(t, theta, PowerConfig(fin_inertia=inertia, filter_tau=0.0))
    # the signed inertial power averages to zero over whole periods
    assert abs(time_mean(tr.t, tr.p_inert)) < 0.01 * analytic_inertial_mean(inertia)
    positive = time_mean(tr.t, np.maximum(0.0, tr.p_inert))
    assert positive == pytest.approx(analytic_inertial_mean(inertia), rel=5e-3)
    assert tr.mean_power == pytest.approx(
        analytic_inertial_mean(inertia) + analytic_drag_mean(), rel=5e-3
    )


def test_filter_attenuates_rate_like_a_first_order_lag():
    tau = 0.02
    t, theta = sinusoid(periods=6)
    tr = power_trace(t, theta, PowerConfig(filter_tau=tau))
    last_period = tr.t >= tr.t[-1] - 1.0 / F
    peak = np.max(np.abs(tr.w[last_period]))
    assert peak == pytest.approx(A * OMEGA / math.sqrt(1.0 + (OMEGA * tau) ** 2), rel=5e-3)


def test_streaming_equals_batch():
    t, theta = sinusoid(periods=1, dt=1e-3)
    pcfg = PowerConfig()
    tr = power_trace(t, theta, pcfg)
    est = PowerEstimator(pcfg)
    out = [est.update(float(a), float(b)) for a, b in zip(t, theta)]
    assert out[0] is None and out[1] is None
    assert out[-1].p_fin == pytest.approx(tr.p_fin[-1])
    assert out[-1].w == pytest.approx(tr.w[-1])
    assert est.mean_power == pytest.approx(tr.mean_power)


def test_spans_left_out_count_in_neither_energy_nor_mean():
    """The fins' energy and mean power cover only the driven (armed) time."""
    t, theta = sinusoid(periods=2, dt=1e-3)
    half = len(t) // 2
    pcfg = PowerConfig()
    whole, first_half, gapped = (PowerEstimator(pcfg) for _ in range(3))
    for i, (a, b) in enumerate(zip(t, theta)):
        s_whole = whole.update(float(a), float(b))
        if i <= half:
            first_half.update(float(a), float(b))
        # the second period left out (as if disarmed), as is the first span after it
        s_gapped = gapped.update(float(a), float(b), accumulate=i <= half)
        if s_whole is not None:  # the estimate itself is the same
            assert s_gapped.p_fin == s_whole.p_fin
    assert gapped.energy == pytest.approx(first_half.energy, rel=1e-12)
    assert gapped.duration == pytest.approx(first_half.duration, rel=1e-12)
    assert gapped.mean_power == pytest.approx(first_half.mean_power, rel=1e-12)
    assert whole.energy > 1.5 * gapped.energy  # the left-out period did spend energy


def test_fleet_mean_per_fin_and_total():
    t, theta = sinusoid()
    angles = np.column_stack([theta, np.zeros_like(theta), theta])
    per_fin, total = fleet_mean_power(t, angles, PowerConfig(filter_tau=0.0))
    assert per_fin[1] == 0.0
    assert per_fin[0] == pytest.approx(per_fin[2])
    assert total == pytest.approx(2.0 * per_fin[0])


def test_energy_per_metre():
    assert energy_per_metre(2.0, 10.0, 4.0) == pytest.approx(5.0)
    with pytest.raises(ValueError, match="distance"):
        energy_per_metre(2.0, 10.0, 0.0)


def test_bad_input():
    est = PowerEstimator(PowerConfig())
    est.update(0.0, 0.0)
    with pytest.raises(ValueError, match="t"):
        est.update(0.0, 0.1)
    with pytest.raises(ValueError, match="theta"):
        est.update(0.1, math.nan)
    with pytest.raises(ValueError, match="theta"):
        power_trace([0.0, 0.1, 0.2], [0.0, 0.1], PowerConfig())
    with pytest.raises(ValueError, match="t"):
        power_trace([], [], PowerConfig())


@pytest.mark.parametrize("tau", [0.0, 0.02])
def test_the_compiled_estimate_is_the_python_one_on_random_samples(tau):
    from control.reference_kernels import ReferencePowerEstimator

    rng = np.random.default_rng(7)
    pcfg = PowerConfig(filter_tau=tau, fin_inertia=1e-3)
    ref, est = ReferencePowerEstimator(pcfg), PowerEstimator(pcfg)
    t = 0.0
    for _ in range(2000):
        t += float(rng.uniform(1e-4, 0.03))
        theta = float(rng.normal(0.0, 0.8))
        acc = bool(rng.random() < 0.8)
        a, b = ref.update(t, theta, acc), est.update(t, theta, acc)
        assert (a is None) == (b is None)
        if a is not None:
            for name in ("t", "w", "alpha", "p_inert", "p_drag", "p_fin"):
                assert getattr(b, name) == pytest.approx(getattr(a, name), rel=1e-12, abs=1e-15)
    assert est.energy == pytest.approx(ref.energy, rel=1e-12)
    assert est.duration == pytest.approx(ref.duration, rel=1e-12)


def test_the_bank_updates_every_fin_as_one_estimator_each():
    from ucat_console.control.power import PowerBank

    t, theta = sinusoid(periods=1, dt=1e-3)
    angles = np.column_stack([theta, 0.5 * theta, -theta, np.zeros_like(theta)])
    pcfg = PowerConfig()
    bank = PowerBank(pcfg, 4)
    single = [PowerEstimator(pcfg) for _ in range(4)]
    for i, ti in enumerate(t):
        bank.update_all(float(ti), angles[i])
        for f in range(4):
            single[f].update(float(ti), float(angles[i, f]))
    for f in range(4):
        assert bank.energy(f) == single[f].energy and bank.p_fin(f) == single[f].last.p_fin
    with pytest.raises(ValueError, match="fin 0's last sample"):
        bank.update_all(float(t[-1]), angles[-1])


def test_the_fins_own_coefficients_not_the_controllers():
    """The estimate takes C_D from PowerConfig: doubling it doubles the drag power."""
    t, theta = sinusoid()
    base = power_trace(t, theta, PowerConfig(filter_tau=0.0))
    double = power_trace(t, theta, PowerConfig(filter_tau=0.0, c_d=2.0 * PowerConfig().c_d))
    assert time_mean(double.t, double.p_drag) == pytest.approx(2.0 * time_mean(base.t, base.p_drag), rel=1e-12)
