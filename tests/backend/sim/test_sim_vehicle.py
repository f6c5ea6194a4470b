"""The 6-DOF hull: rest, damping-limited speed, restoring moment, current, disturbance (the
fins held along the stream, where they add no force)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ucat_console.backend.sim.params import FinHydroConfig, PlantConfig, VehicleConfig
from ucat_console.backend.sim.plant import Plant
from ucat_console.backend.sim.plate import plate_angle
from ucat_console.backend.sim.vehicle import vehicle_matrices
from ucat_console.robot.rotations import euler_from_quaternion, quaternion_from_euler

G0 = 9.80665


def _hull_only() -> Plant:
    """A plant whose fins trail in the stream without profile drag: no force from them, so
    the hull's own dynamics show."""
    p = Plant(PlantConfig(hydro=FinHydroConfig(c_d0=0.0)))
    return p


TRAILING = (-plate_angle(0.70, 0.25),) * 4  # the plates' line along the stream


def _terminal_speed(force: float) -> float:
    # 6.542 V + 2.98 V^2 = F  ->  V = (-6.542 + sqrt(6.542^2 + 4 * 2.98 * F)) / (2 * 2.98)
    return (-6.542 + math.sqrt(6.542**2 + 4 * 2.98 * force)) / (2 * 2.98)


def test_at_rest_stays_at_rest_for_20_s() -> None:
    p = Plant()
    p.reset(position_ned=(1.0, -2.0, 1.5), euler=(0.0, 0.0, 0.7))
    p.advance(20.0)
    pos, q = p.pose()
    assert p.time == pytest.approx(20.0)
    assert np.allclose(pos, (1.0, -2.0, 1.5), atol=1e-9)
    assert np.allclose(euler_from_quaternion(q), (0.0, 0.0, 0.7), atol=1e-9)
    assert np.allclose(p.body_velocity(), 0.0, atol=1e-12)


@pytest.mark.parametrize("force", [1.0, 2.0])
def test_constant_body_force_reaches_the_damping_speed(force: float) -> None:
    p = _hull_only()
    p.reset(position_ned=(0.0, 0.0, 1.0), fin_angles=TRAILING)
    p.set_body_wrench(force=(force, 0.0, 0.0))
    p.advance(60.0)  # about 8 time constants of (m + 40 kg) / damping
    u, v, w, pr, qr, rr = p.body_velocity()
    assert u == pytest.approx(_terminal_speed(force), rel=2e-3)
    assert abs(v) < 1e-9 and abs(rr) < 1e-9 and abs(pr) < 1e-9
    pos, _ = p.pose()
    assert pos[0] > 0.0 and abs(pos[1]) < 1e-9


def test_mass_matrix_uses_parallel_axis_and_added_mass() -> None:
    mrb, ma, minv = vehicle_matrices(VehicleConfig())
    assert mrb[0, 0] == 22.0
    assert mrb[0, 4] == pytest.approx(22.0 * 0.1)  # m z_g couples surge and pitch
    assert mrb[4, 4] == pytest.approx(0.66 + 22.0 * 0.01)
    assert mrb[3, 3] == pytest.approx(0.1574 + 22.0 * 0.01)
    assert np.allclose(np.diag(ma), (40.0, 21.0, 2.0, 0.1269, 1.2052, 2.3064))
    assert np.allclose(minv @ (mrb + ma), np.eye(6))


def test_pitch_restoring_period_matches_hand_calculation() -> None:
    """Undamped small pitch oscillation: surge-pitch block [[62, 2.2], [2.2, 2.0852]]."""
    cfg = PlantConfig(vehicle=VehicleConfig(m_qq=0.0, x_u=0.0, x_uu=0.0))
    p = Plant(cfg)
    p.reset(euler=(0.0, 0.05, 0.0))
    m_uu, m_uq, m_qq = 22.0 + 40.0, 22.0 * 0.1, 0.66 + 22.0 * 0.01 + 1.2052
    inv_qq = m_uu / (m_uu * m_qq - m_uq**2)
    period = 2 * math.pi / math.sqrt(inv_qq * 0.1 * 22.0 * G0)  # about 1.92 s
    pitch = []
    for _ in range(4000):
        p.advance(0.001)
        pitch.append(p.euler()[1])
    pitch = np.array(pitch)
    t = np.arange(1, 4001) * 0.001
    crossings = t[np.nonzero(np.diff(np.sign(pitch)))[0]]
    assert crossings[0] == pytest.approx(period / 4, abs=0.003)
    assert np.diff(crossings[:4]) == pytest.approx([period / 2] * 3, abs=0.003)


def test_cg_below_cb_returns_a_pitched_hull_towards_level() -> None:
    p = Plant()
    p.reset(euler=(0.0, 0.3, 0.0))
    p.advance(0.001)
    # first step: q_dot = -M^-1[q,q] z_g W sin(0.3) (hand: about -3.18 rad/s2)
    m_uu, m_uq, m_qq = 62.0, 2.2, 0.66 + 0.22 + 1.2052
    inv_qq = m_uu / (m_uu * m_qq - m_uq**2)
    q_dot = -inv_qq * 0.1 * 22.0 * G0 * math.sin(0.3)
    assert p.body_velocity()[4] / 0.001 == pytest.approx(q_dot, rel=0.01)
    peaks = []
    for _ in range(5):
        seg = []
        for _ in range(200):
            p.advance(0.01)
            seg.append(abs(p.euler()[1]))
        peaks.append(max(seg))
    assert all(b < a for a, b in zip(peaks, peaks[1:]))
    assert peaks[-1] < 0.1


def test_roll_restoring_sign() -> None:
    p = Plant()
    p.reset(euler=(0.2, 0.0, 0.0))
    p.advance(0.01)
    assert p.body_velocity()[3] < 0.0  # starboard-down roll is pushed back


def test_hull_drifts_with_a_constant_current() -> None:
    cfg = PlantConfig(vehicle=VehicleConfig(current_ned=(0.0, 0.1, 0.0)))
    p = Plant(cfg)
    p.reset(position_ned=(0.0, 0.0, 1.0), euler=(0.0, 0.0, math.pi / 2))  # heading east
    p.advance(60.0)
    u = p.body_velocity()[0]
    assert u == pytest.approx(0.1, rel=5e-3)  # no relative velocity left: rides the current
    pos, _ = p.pose()
    assert pos[1] > 3.0 and abs(pos[0]) < 1e-6


def test_disturbance_force_is_resolved_from_ned() -> None:
    cfg = PlantConfig(vehicle=VehicleConfig(disturbance_ned=(0.0, 2.0, 0.0)), hydro=FinHydroConfig(c_d0=0.0))
    p = Plant(cfg)
    p.reset(position_ned=(0.0, 0.0, 1.0), euler=(0.0, 0.0, math.pi / 2), fin_angles=TRAILING)  # east = forward
    p.advance(60.0)
    assert p.body_velocity()[0] == pytest.approx(_terminal_speed(2.0), rel=2e-3)


def test_euler_quaternion_round_trip() -> None:
    for e in [(0.1, -0.2, 0.3), (-1.0, 0.5, -2.5), (0.0, 0.0, math.pi - 1e-3)]:
        assert euler_from_quaternion(quaternion_from_euler(*e)) == pytest.approx(e, abs=1e-12)
