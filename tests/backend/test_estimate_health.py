"""The estimate-health failsafe: the attitude estimate against the accelerometer's gravity
(the EKF correction's innovation as an angle, a pure function), a persistent large one or a
stopped estimate triggers it, and on the emulated rig an accelerometer that reads a tilt the
estimate does not have makes the robot hold."""

from __future__ import annotations

import math

import pytest
from support import Console, wait_for

from ucat_console.backend.safety import SafetyMonitor
from ucat_console.backend.failsafe_config import FailsafeConfig, FailsafeRule
from ucat_console.config import load_config
from ucat_console.control.estimation import gravity_innovation
from ucat_console.robot.readings import ImuReading
from ucat_console.robot.rotations import quaternion_from_euler, rotation_matrix
from ucat_console.robot.units import GRAVITY
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.messages import BodyState
from ucat_console.ui.status_bar import vehicle_parts

TOKEN = "estimate-token"
PILOT = 1
LEVEL = (1.0, 0.0, 0.0, 0.0)
AT_REST = (0.0, 0.0, -GRAVITY)  # a level sensor's specific force
TILTED = (0.5 * GRAVITY, 0.0, -math.sqrt(0.75) * GRAVITY)  # 30 degrees of pitch


def test_the_innovation_is_the_angle_between_measured_and_predicted_gravity() -> None:
    q = quaternion_from_euler(0.3, -0.2, 1.0)
    at_rest = tuple(GRAVITY * (rotation_matrix(q).T @ (0.0, 0.0, -1.0)))
    assert gravity_innovation(q, at_rest, 0.15) == pytest.approx(0.0, abs=1e-6)
    assert gravity_innovation(LEVEL, TILTED, 0.15) == pytest.approx(math.pi / 6)
    assert math.isnan(gravity_innovation(LEVEL, (0.0, 0.0, -1.5 * GRAVITY), 0.15))  # accelerating
    assert math.isnan(gravity_innovation(LEVEL, (math.nan, 0.0, -GRAVITY), 0.15))


def body(t: float, q=LEVEL) -> BodyState:
    return BodyState(t, (0.0, 0.0, 1.0), q, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 1.0)


def imu(t: float, accel) -> ImuReading:
    return ImuReading(t=t, accel=accel, gyro=(0.0, 0.0, 0.0))


def estimate(transitions: list) -> list[bool]:
    return [tr.active for tr in transitions if tr.name == "estimate"]


def test_a_persistent_large_innovation_triggers_and_a_reading_within_clears() -> None:
    mon = SafetyMonitor(FailsafeConfig(estimate=FailsafeRule("hold", 1.0)))
    mon.on_messages([(ch.BODY_STATE, body(0.0)), (ch.IMU, imu(0.0, TILTED))])
    mon.on_messages([(ch.BODY_STATE, body(0.5)), (ch.IMU, imu(0.5, (0.0, 0.0, -1.5 * GRAVITY)))])  # skipped
    assert estimate(mon.check(0.9)) == []
    mon.on_messages([(ch.BODY_STATE, body(1.0)), (ch.IMU, imu(1.0, TILTED))])
    assert estimate(mon.check(1.0)) == [True]
    assert "0.52 rad off the accelerometer's gravity" in next(s.cause for s in mon.states() if s.name == "estimate")
    mon.on_messages([(ch.BODY_STATE, body(1.1)), (ch.IMU, imu(1.1, AT_REST))])
    assert estimate(mon.check(1.1)) == [False]


def test_a_short_disagreement_does_not_trigger() -> None:
    mon = SafetyMonitor(FailsafeConfig(estimate=FailsafeRule("hold", 1.0)))
    for k in range(20):  # 2 s, every other reading at rest
        mon.on_messages([(ch.BODY_STATE, body(0.1 * k)), (ch.IMU, imu(0.1 * k, TILTED if k % 2 else AT_REST))])
        assert estimate(mon.check(0.1 * k)) == []


def test_a_stopped_estimate_triggers_and_the_next_state_clears_it() -> None:
    mon = SafetyMonitor(FailsafeConfig(estimate=FailsafeRule("hold", 1.0)))
    mon.on_message(ch.IMU, imu(0.5, AT_REST))
    assert estimate(mon.check(0.5)) == []  # no estimate yet: not started
    mon.on_message(ch.BODY_STATE, body(1.0))
    assert estimate(mon.check(5.0)) == []  # no readings since: the loop is not stepping
    mon.on_message(ch.IMU, imu(2.0, AT_REST))
    assert estimate(mon.check(5.0)) == []
    mon.on_message(ch.IMU, imu(2.1, AT_REST))
    assert estimate(mon.check(5.0)) == [True]
    assert "no state estimate for 1.1 s of IMU readings" in next(s.cause for s in mon.states()
                                                                 if s.name == "estimate")
    mon.on_message(ch.BODY_STATE, body(2.2))
    assert estimate(mon.check(5.0)) == [False]


@pytest.mark.slow
def test_an_accelerometer_reading_a_tilt_the_estimate_lacks_makes_the_rig_hold(tmp_path) -> None:
    cfg = load_config("sim-devices")
    cfg = cfg.replace(access=cfg.access.replace(token=TOKEN), console=cfg.console.replace(record_on_arm=False))
    c = Console(cfg, tmp_path, clock=None)
    sup = c.sup
    try:
        c.fly(PILOT, TOKEN)
        wait_for(lambda: sup.loop.time > 1.0 and not sup.safety.active() and sup.safety.estimate()[0],
                 what="the rig running, no failsafe, the attitude checked")
        assert next(x for x in vehicle_parts(sup.state()) if x.name == "Estimate").state == "ok"
        sup.arm(PILOT)
        sup.set_setpoints(PILOT, velocity=0.1)
        # the IMU's accelerometer streams 30 degrees of pitch (1 g: within every plausibility
        # limit) while its orientation, which the estimate takes, stays level
        sup.inject_fault(PILOT, "imu", "implausible", accel_g=(0.5, 0.0, -math.sqrt(0.75)))
        wait_for(lambda: sup.safety.is_active("estimate"), what="the estimate failsafe")
        ev = wait_for(lambda: c.event("failsafe", "estimate"), what="its event")
        assert ev.data["action"] == "hold" and "off the accelerometer's gravity" in ev.data["cause"]
        wait_for(lambda: sup.setpoints.velocity == 0.0, what="the hold")
        assert sup.armed and next(x for x in vehicle_parts(sup.state()) if x.name == "Estimate").state == "bad"
        sup.clear_fault(PILOT, "imu", "implausible")
        wait_for(lambda: not sup.safety.is_active("estimate"), what="the failsafe clearing")
    finally:
        c.stop()
