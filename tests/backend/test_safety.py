"""Failsafes: each triggers after its timeout, reports its action, latches until its cause clears."""

from __future__ import annotations

import math

import pytest

from ucat_console.robot.readings import DepthReading, DvlVelocity, ImuReading
from ucat_console.backend.safety import SafetyMonitor
from ucat_console.backend.failsafe_config import FailsafeConfig, FailsafeRule
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.events import Event


def dvl(t: float, valid: bool = True, vx: float = 0.1) -> DvlVelocity:
    return DvlVelocity(t, vx, 0.0, 0.0, valid, 5.0, 0.01)


def imu(t: float, gyro_z: float = 0.0) -> ImuReading:
    return ImuReading(t, (0.0, 0.0, 1.0), (0.0, 0.0, gyro_z))


def depth(t: float, d: float = 1.0) -> DepthReading:
    return DepthReading(t, d, 1e4 * d)


def feed_all(m: SafetyMonitor, t: float) -> None:
    m.on_message(ch.IMU, imu(t))
    m.on_message(ch.DVL, dvl(t))
    m.on_message(ch.DEPTH, depth(t))


def names(transitions) -> list[tuple[str, bool]]:
    return [(tr.name, tr.active) for tr in transitions]


def test_pilot_gone_triggers_after_its_timeout_and_latches_until_a_pilot_returns() -> None:
    cfg = FailsafeConfig(pilot_gone=FailsafeRule("surface", 2.0))
    m = SafetyMonitor(cfg)
    m.pilot_present()
    for t in (0.5, 1.0):
        feed_all(m, t)
        assert m.check(t) == []
    m.pilot_left()  # stamped 1.0, the last check
    feed_all(m, 2.9)
    assert m.check(2.9) == []  # 1.9 s gone
    feed_all(m, 3.0)
    (tr,) = m.check(3.0)
    assert (tr.name, tr.active, tr.action, tr.t) == ("pilot_gone", True, "surface", 3.0)
    for t in (5.0, 30.0):
        feed_all(m, t)
        assert m.check(t) == [] and m.active() == ("pilot_gone",)
    m.pilot_present()
    assert names(m.check(30.1)) == [("pilot_gone", False)]
    assert m.active() == ()


def test_a_failsafe_escalates_once_when_its_cause_lasts_and_clears_with_it() -> None:
    cfg = FailsafeConfig(pilot_gone=FailsafeRule("hold", 2.0, "disarm", 30.0))
    m = SafetyMonitor(cfg)
    m.pilot_present()
    feed_all(m, 0.0)
    m.check(0.0)
    m.pilot_left(1.0)
    seen = []
    for k in range(1, 400):  # 0.1 s checks up to 39.9 s, the sensors talking
        t = 0.1 * k
        feed_all(m, t)
        seen += [(round(tr.t, 1), tr.action, tr.escalated) for tr in m.check(t)]
    # hold 2 s after the pilot left, disarm 30 s after that, each once
    assert seen == [(3.0, "hold", False), (33.0, "disarm", True)]
    assert next(st for st in m.states() if st.name == "pilot_gone").action == "disarm"
    m.pilot_present()
    (tr,) = m.check(40.0)
    assert (tr.name, tr.active, tr.action) == ("pilot_gone", False, "disarm")
    assert next(st for st in m.states() if st.name == "pilot_gone").action == "hold"  # afresh


def test_an_escalation_no_stronger_than_the_action_does_nothing() -> None:
    m = SafetyMonitor(FailsafeConfig(pilot_gone=FailsafeRule("disarm", 2.0, "disarm", 1.0)))
    m.pilot_present()
    m.pilot_left(0.0)
    seen = [tr.action for k in range(100) for tr in m.check(0.1 * k) if tr.name == "pilot_gone"]
    assert seen == ["disarm"]


def test_no_pilot_ever_means_no_pilot_gone() -> None:
    m = SafetyMonitor()
    m.pilot_left(0.0)
    for t in (1.0, 10.0):
        feed_all(m, t)
        assert m.check(t) == []


def test_released_control_is_not_a_pilot_gone() -> None:
    m = SafetyMonitor()
    m.pilot_present()
    m.pilot_released()
    m.pilot_left(0.0)
    feed_all(m, 10.0)
    assert m.check(10.0) == []


def test_dvl_with_only_invalid_reports_triggers_then_clears_with_a_valid_one() -> None:
    cfg = FailsafeConfig(dvl=FailsafeRule("hold", 2.0))
    m = SafetyMonitor(cfg)
    t = 0.0
    while t <= 1.0 + 1e-9:  # valid up to 1.0
        m.on_message(ch.DVL, dvl(t))
        m.on_message(ch.IMU, imu(t))
        m.on_message(ch.DEPTH, depth(t))
        m.check(t)
        t += 0.125
    # from here the DVL reports come, but invalid
    while t <= 3.5:
        m.on_message(ch.DVL, dvl(t, valid=False))
        m.on_message(ch.IMU, imu(t))
        m.on_message(ch.DEPTH, depth(t))
        m.check(t)
        if t - 1.0 <= 2.0:
            assert "dvl" not in m.active(), t
        t += 0.125
    assert m.active() == ("dvl",)
    (state,) = [s for s in m.states() if s.name == "dvl"]
    assert state.action == "hold" and "invalid" in state.cause
    m.on_message(ch.DVL, dvl(t))
    assert names(m.check(t)) == [("dvl", False)]


def test_a_silent_sensor_triggers_its_own_failsafe_only() -> None:
    cfg = FailsafeConfig(imu=FailsafeRule("disarm", 1.0), depth=FailsafeRule("disarm", 1.0))
    m = SafetyMonitor(cfg)
    for k in range(30):  # 3 s: IMU and DVL talk, the depth sensor is silent
        t = 0.1 * k
        m.on_message(ch.IMU, imu(t))
        m.on_message(ch.DVL, dvl(t))
        m.check(t)
    assert m.active() == ("depth",)
    (state,) = [s for s in m.states() if s.name == "depth"]
    assert "silent" in state.cause and state.action == "disarm"


def test_a_sensor_fault_is_labelled_with_what_its_driver_reported_since_the_last_valid_reading() -> None:
    """Garbled: the driver dropped corrupt messages (its events, with the ones it held back
    counted); the driver's silence event does not make a garbled line "silent". A valid
    reading taken before the fault, published after its first event, does not end it."""
    m = SafetyMonitor(FailsafeConfig(imu=FailsafeRule("hold", 0.5)))
    feed_all(m, 0.0)
    m.check(0.0)
    m.on_message(ch.EVENTS, Event(0.2, "imu", "checksum", "bad checksum", data={"suppressed": 4}))
    m.on_message(ch.IMU, imu(0.1))  # taken before the fault, through the loop after its event
    m.on_message(ch.EVENTS, Event(0.4, "imu", "silence", "no packet", "error"))
    for t in (0.3, 0.5, 0.7):
        m.on_message(ch.DVL, dvl(t))
        m.on_message(ch.DEPTH, depth(t))
    (tr,) = m.check(0.7)
    assert tr.name == "imu" and tr.cause.endswith("(garbled: 5 corrupt messages dropped)")
    assert m.sensor_silence("imu", 0.7) == (pytest.approx(0.6), "garbled: 5 corrupt messages dropped")
    m.on_message(ch.IMU, imu(0.8))  # a valid reading after it: over
    assert names(m.check(0.8)) == [("imu", False)] and m.sensor_silence("imu", 0.8)[1] == ""
    # invalid readings and a silent sensor say so; a pressure driver's events label the depth
    m.on_message(ch.EVENTS, Event(0.9, "pressure", "broken_loop", "loop current 0 mA", "error"))
    m.on_message(ch.IMU, imu(0.9, gyro_z=math.nan))
    assert m.sensor_silence("depth", 0.9)[1] == "invalid: 1 invalid readings"
    assert m.sensor_silence("imu", 0.9)[1] == "invalid: 1 invalid readings"
    assert m.sensor_silence("dvl", 0.9)[1] == ""
    for t in (1.0, 2.0, 3.0):  # nothing from the DVL since 0.7 s, its timeout 2 s
        m.on_message(ch.IMU, imu(t))
        m.on_message(ch.DEPTH, depth(t))
        m.check(t)
    assert "(silent)" in next(st.cause for st in m.states() if st.name == "dvl")


def test_non_finite_imu_values_are_invalid() -> None:
    m = SafetyMonitor(FailsafeConfig(imu=FailsafeRule("disarm", 0.5)))
    for k in range(10):
        t = 0.1 * k
        m.on_message(ch.IMU, imu(t, gyro_z=math.nan))
        m.on_message(ch.DVL, dvl(t))
        m.on_message(ch.DEPTH, depth(t))
        m.check(t)
    assert m.active() == ("imu",)


def test_motor_fault_from_a_motor_controller_disarms_at_once_and_clears_when_reported_cleared() -> None:
    m = SafetyMonitor()  # motor: disarm, timeout 0
    feed_all(m, 0.0)
    m.check(0.0)
    m.on_message(ch.EVENTS, Event(5.0, "dvl", "heartbeat_lost", "not a motor"))
    m.on_message(ch.EVENTS, Event(5.0, "epos2.3", "mode", "not a fault", "info"))
    feed_all(m, 0.1)
    assert m.check(0.1) == []
    m.on_message(ch.EVENTS, Event(123.0, "epos2.3", "heartbeat_lost", "no heartbeat"))
    (tr,) = m.check(0.1)
    assert (tr.name, tr.active, tr.action) == ("motor", True, "disarm")
    assert "epos2.3: no heartbeat" in tr.cause  # the drive and what it reported
    m.on_message(ch.EVENTS, Event(124.0, "epos2.3", "fault_cleared", "not this one", "info"))
    feed_all(m, 0.2)
    assert m.check(0.2) == [] and m.active() == ("motor",)
    m.on_message(ch.EVENTS, Event(125.0, "epos2.3", "heartbeat_restored", "back", "info"))
    assert names(m.check(0.2)) == [("motor", False)]


def test_a_motor_fault_shorter_than_the_timeout_does_not_trigger() -> None:
    m = SafetyMonitor(FailsafeConfig(motor=FailsafeRule("disarm", 1.0)))
    feed_all(m, 0.0)
    m.check(0.0)
    m.on_message(ch.EVENTS, Event(0.0, "epos2.1", "fault", "fault"))
    feed_all(m, 0.5)
    assert m.check(0.5) == []
    m.on_message(ch.EVENTS, Event(0.0, "epos2.1", "fault_cleared", "ok", "info"))
    feed_all(m, 2.0)
    assert m.check(2.0) == []


def test_planner_late_counts_late_plans_in_its_window() -> None:
    cfg = FailsafeConfig(planner_late=FailsafeRule("warn", 10.0), late_plans=3)
    m = SafetyMonitor(cfg)
    for t in (0.0, 1.0, 2.0):
        feed_all(m, t)
        m.check(t)
        m.on_message(ch.EVENTS, Event(t, "loop", "late_plan", "late"))
    feed_all(m, 3.0)
    (tr,) = m.check(3.0)
    assert (tr.name, tr.active, tr.action) == ("planner_late", True, "warn")
    feed_all(m, 11.5)  # the first late plan (stamped 0.0) left the window
    assert names(m.check(11.5)) == [("planner_late", False)]


def test_unknown_failsafe_name_is_an_error() -> None:
    with pytest.raises(ValueError, match="failsafe"):
        SafetyMonitor().rule("gremlins")


def tracking(t: float, *, driving: bool = True, depth_err: float = 0.0, speed_err: float = 0.0,
             heading_err: float = 0.0):
    from ucat_console.telemetry.messages import BodyTracking

    return BodyTracking(t, driving, 0.2, 1.0, 0.0, 0.0, speed_err, depth_err, heading_err)


def test_tracking_warns_when_an_axis_stays_off_its_band_and_clears_when_back() -> None:
    cfg = FailsafeConfig(tracking=FailsafeRule("warn", 5.0), tracking_depth=0.2)
    m = SafetyMonitor(cfg)
    seen = []
    for k in range(101):  # 10 s: depth 0.3 m off its reference from t = 2 s on
        t = 0.1 * k
        feed_all(m, t)
        m.on_message(ch.BODY_TRACKING, tracking(t, depth_err=0.3 if t >= 2.0 else 0.0))
        seen += [(round(tr.t, 1), tr.name, tr.active) for tr in m.check(t) if tr.name == "tracking"]
    assert seen == [(7.0, "tracking", True)]  # 5 s after it left the band
    assert "depth +0.30 m off its reference" in next(s for s in m.states() if s.name == "tracking").cause
    assert next(s for s in m.states() if s.name == "tracking").action == "warn"
    m.on_message(ch.BODY_TRACKING, tracking(10.1))
    assert names(m.check(10.1)) == [("tracking", False)]


def test_tracking_counts_only_while_driving_and_restarts_its_time_when_back_in_band() -> None:
    m = SafetyMonitor(FailsafeConfig(tracking=FailsafeRule("warn", 3.0)))
    for k in range(60):  # disarmed, drifting: no alarm
        t = 0.1 * k
        feed_all(m, t)
        m.on_message(ch.BODY_TRACKING, tracking(t, driving=False, speed_err=0.3))
        assert not [tr for tr in m.check(t) if tr.name == "tracking"]
    for k in range(60, 110):  # driving from on its reference: off for 2 s, back once, off again for 2.8 s
        t = 0.1 * k
        feed_all(m, t)
        m.on_message(ch.BODY_TRACKING, tracking(t, heading_err=0.0 if k in (60, 80) else 0.5))
        assert not [tr for tr in m.check(t) if tr.name == "tracking"]
    cut, off = m.control()
    assert off == ["heading +0.50 rad for 3 s"] and cut == []
    since, what = m.off_track(10.9)  # what the seeker reads: off since 8.1 s
    assert since == pytest.approx(2.8) and what == "heading +0.50 rad"
    m.on_message(ch.BODY_TRACKING, tracking(11.0))
    assert m.off_track(11.0) == (0.0, "")


def test_a_restarted_expected_response_counts_the_time_off_again_from_the_robots_state() -> None:
    m = SafetyMonitor(FailsafeConfig(tracking=FailsafeRule("warn", 3.0)))
    for k in range(40):  # driving, 0.3 m/s short of the reference from t = 1 s: off since about 1 s
        t = 0.1 * k
        feed_all(m, t)
        m.on_message(ch.BODY_TRACKING, tracking(t, speed_err=-0.3 if t >= 1.0 else 0.0))
        m.check(t)
    assert m.off_track(3.9)[0] > 2.5
    m.restart_expected()  # the seeker put its best back: judged again from the robot's state
    assert m.off_track(3.9) == (0.0, "")
    seen = []
    for k in range(40, 100):  # still short, closing in on the reference at 0.05 m/s per s
        t = 0.1 * k
        feed_all(m, t)
        m.on_message(ch.BODY_TRACKING, tracking(t, speed_err=min(0.0, -0.3 + 0.05 * (t - 4.0))))
        seen += [tr.name for tr in m.check(t) if tr.name == "tracking" and tr.active]
    assert seen == []  # its way back is within the expected response: no alarm (without the restart: one)


def test_the_control_light_names_what_the_allocation_cuts() -> None:
    from ucat_console.backend.supervisor.console_state import safety_view
    from ucat_console.telemetry.messages import BodyAllocation
    from ucat_console.ui.status_bar import control_light

    m = SafetyMonitor(FailsafeConfig())
    assert control_light(safety_view(m, 0.0), {}).state == "ok"
    m.on_message(ch.BODY_ALLOCATION, BodyAllocation(0.0, 3.0, 6.0, 0.1, 0.0, 4.7, 0.1, ("heave", "surge")))
    light = control_light(safety_view(m, 0.0), {})
    assert light.state == "warn"
    assert "heave: 4.70 of 6.00 N" in light.why and "surge: 0.00 of 3.00 N" in light.why
