"""The fin drive from shaft to battery: hand-computed points, no energy back to the battery,
and the simulated robot's electrical figures against the plant's own."""

from __future__ import annotations

import math

import pytest

from ucat_console.backend.drive_power import electrical_power
from ucat_console.robot.motor import FinMotor, battery_power, motor_current

M = FinMotor()
K_T, R, I_0, N, ETA_G, ETA_B, P_Q = 0.036, 0.942, 0.238, 35.0, 0.7, 0.95, 0.5


def _current(tau: float, w: float, a: float = 0.0) -> float:
    k_t, _, i_0, j_r, n, eta_g, _, _ = M.constants()
    return motor_current(tau, w, a, k_t, i_0, j_r, n, eta_g)


def test_driving_the_fin_by_hand() -> None:
    """0.5 N m at 2 rad/s (1 W at the shaft): the motor gives 0.5 / (35 x 0.7) N m plus its
    friction k_t I_0, so I = 0.8049 A; V_t = R I + k_t 35 x 2 = 3.278 V; the battery gives
    V_t I / 0.95 + 0.5 W = 3.278 W."""
    i = _current(0.5, 2.0)
    assert i == pytest.approx((0.5 / (N * ETA_G) + K_T * I_0) / K_T)
    assert i == pytest.approx(0.80489, abs=1e-5)
    v_t = R * i + K_T * N * 2.0
    assert M.battery_power(i, 2.0) == pytest.approx(v_t * i / ETA_B + P_Q)
    assert M.battery_power(i, 2.0) == pytest.approx(3.2775, abs=1e-4)


def test_the_fin_driving_the_motor_gives_the_battery_nothing_back() -> None:
    """Braking: -0.5 N m at 2 rad/s. The gearhead's losses help (-0.5 x 0.7 / 35 N m), the
    motor's terminal power is negative, and the battery pays only the drive's own 0.5 W."""
    i = _current(-0.5, 2.0)
    assert i == pytest.approx((-0.5 * ETA_G / N + K_T * I_0) / K_T)
    assert (R * i + K_T * N * 2.0) * i < 0.0
    assert M.battery_power(i, 2.0) == pytest.approx(P_Q)


def test_holding_still_costs_copper_and_the_rotor_needs_torque_to_turn() -> None:
    i = _current(0.3, 0.0)
    assert M.battery_power(i, 0.0) == pytest.approx(R * i * i / ETA_B + P_Q)  # no back-EMF
    # accelerating the rotor alone: J_r N a at the motor
    assert _current(0.0, 0.0, 64.0) == pytest.approx(M.rotor_inertia * N * 64.0 / K_T)


def test_at_a_steady_rate_the_battery_never_pays_less_than_the_shaft_takes() -> None:
    """(Slowing down, the rotor's kinetic energy may drive the shaft for a moment: over a
    whole run the plant's test below holds the inequality.)"""
    for tau in (-1.5, -0.2, 0.0, 0.1, 0.8, 2.0):
        for w in (-8.0, -1.0, 0.0, 0.5, 3.0, 9.0):
            i = _current(tau, w)
            assert M.battery_power(i, w) >= max(0.0, tau * w) + P_Q - 1e-12


def test_a_drive_s_message_is_its_battery_power() -> None:
    msg = electrical_power(1.5, (0.8, -0.1, math.nan, 0.0), (24.0,) * 4, (2.0, 2.0, 1.0, 0.0), M)
    assert msg.per_fin[0] == pytest.approx(battery_power(0.8, 2.0, K_T, R, N, ETA_B, P_Q))
    assert msg.per_fin[1] == pytest.approx(P_Q)  # braking
    assert math.isnan(msg.per_fin[2]) and math.isnan(msg.total)  # a drive that did not answer
    assert msg.per_fin[3] == pytest.approx(P_Q)


def test_bad_motor_values_are_named() -> None:
    with pytest.raises(ValueError, match="gear_efficiency"):
        FinMotor(gear_efficiency=1.2)
    with pytest.raises(ValueError, match="torque_constant"):
        FinMotor(torque_constant=0.0)


def test_the_simulated_robot_reports_the_plant_s_battery_energy() -> None:
    """The in-process robot's ``power/electrical`` messages, each the mean since the one
    before, add up to the plant's battery energy; it exceeds the shaft energy."""
    from ucat_console.backend.loop.closed_loop import ClosedLoop
    from ucat_console.backend.sim_robot_io import SimRobotIO
    from ucat_console.config import load_config
    from ucat_console.control.allocation import BodySetpoints

    app = load_config("sim-tuned")
    io = SimRobotIO(app.plant, depth=1.0, velocity=0.2)
    got = []
    io.add_telemetry_sink(lambda channel, m: got.append(m))
    with ClosedLoop(app.loop.replace(mode="baseline"), io, setpoints=BodySetpoints(0.2, 1.0, 0.0)) as loop:
        loop.run_until(20.0)
    tr = io.truth()
    assert len(got) > 40
    first = got[0]
    reported = sum(m.total * (m.t - prev.t) for prev, m in zip(got, got[1:]))
    battery = sum(tr.fin_battery_energy)
    # the messages cover the run from the first one to the last
    assert reported == pytest.approx(battery * (got[-1].t - first.t) / tr.t, rel=0.15)
    assert battery > sum(tr.fin_energy) + 4 * P_Q * tr.t * 0.99


def test_the_shaft_torque_of_a_current_is_what_needs_that_current() -> None:
    """The inverse of the drive model at a steady rate; at the nominal 2.52 A by hand:
    0.036 x (2.52 - 0.238) x 35 x 0.7 = 2.0127 N m (the URDF's fin effort limit)."""
    from ucat_console.robot.motor import NOMINAL_CURRENT

    for current in (0.5, 1.0, NOMINAL_CURRENT, 4.0):
        for w in (0.3, 5.0):
            assert _current(M.shaft_torque(current), w) == pytest.approx(current)
    assert M.shaft_torque(NOMINAL_CURRENT) == pytest.approx(K_T * (2.52 - I_0) * N * ETA_G)
    assert M.shaft_torque(NOMINAL_CURRENT) == pytest.approx(2.0127, abs=1e-4)
