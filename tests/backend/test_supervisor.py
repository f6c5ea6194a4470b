"""The supervisor without a browser: arming, access, refused values, failsafes, shutdown.

The loop runs headless (SimulatedClock) in the test's thread through ``Supervisor.step``;
one test runs it in its own thread under a paced clock.
"""

from __future__ import annotations

import math
import threading
from pathlib import Path
from typing import Callable

import pytest
from support import Console, wait_for

from ucat_console.backend.access import LOCAL, AccessDenied
from ucat_console.backend.arming import STOP_RATE
from ucat_console.robot.readings import DepthReading
from ucat_console.backend.sim_robot_io import SimRobotIO
from ucat_console.backend.sessions.reader import SessionReader
from ucat_console.backend.supervisor import CommandRefused, SteadyPacedClock, Supervisor
from ucat_console.backend.robots import robot as registered_robot
from ucat_console.backend.access import AccessConfig
from ucat_console.backend.failsafe_config import FailsafeConfig, FailsafeRule
from ucat_console.config import AppConfig, ConsoleConfig, load_config
from ucat_console.control import FinMpc
from ucat_console.control.baseline import wrap_angle
from ucat_console.control.params import MpcConfig
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.events import Event

TOKEN = "pool-side-token"
PILOT, VIEWER = 1, 2


def make_config(**failsafes: FailsafeRule) -> AppConfig:
    return AppConfig(
        console=ConsoleConfig(supervise_period=0.05, record_tail=1.0),
        access=AccessConfig(token=TOKEN),
        failsafe=FailsafeConfig(**failsafes),
    )


class Events:
    """Every event and status published on the public stream."""

    def __init__(self, sup: Supervisor) -> None:
        self.events: list[Event] = []
        self.status: list = []
        sup.stream.subscribe(lambda c, m: (self.events if c == ch.EVENTS else self.status).append(m),
                             [ch.EVENTS, ch.STATUS])

    def codes(self, source: str) -> list[str]:
        return [e.code for e in self.events if e.source == source]


@pytest.fixture
def sup(make_console: Callable[..., Console]) -> Supervisor:
    s = make_console(make_config()).sup
    s.client_connected(PILOT)
    s.client_connected(VIEWER)
    assert s.take_control(PILOT, TOKEN) is True
    return s


def fins_moved(sup: Supervisor) -> float:
    return max(abs(a) for a in sup.loop.truth().fin_angles)


def test_motors_stay_still_until_arming_is_confirmed(sup: Supervisor) -> None:
    sup.set_setpoints(PILOT, velocity=0.3)
    sup.step(1.5)
    assert not sup.armed
    assert fins_moved(sup) == 0.0  # the fins start at 0 and were never commanded
    nonce = sup.request_arm(PILOT)
    sup.step(1.0)
    assert not sup.armed and fins_moved(sup) == 0.0
    with pytest.raises(CommandRefused):
        sup.confirm_arm(PILOT, "not-the-nonce")
    with pytest.raises(CommandRefused):  # the wrong nonce used the request up
        sup.confirm_arm(PILOT, nonce)
    nonce = sup.request_arm(PILOT)
    sup.confirm_arm(PILOT, nonce)
    assert sup.armed
    sup.step(2.0)
    assert fins_moved(sup) > 0.02  # the fins beat (they never moved before)


def test_a_viewer_can_neither_arm_nor_confirm_the_pilots_request(sup: Supervisor) -> None:
    with pytest.raises(AccessDenied):
        sup.request_arm(VIEWER)
    nonce = sup.request_arm(PILOT)
    with pytest.raises(AccessDenied):
        sup.confirm_arm(VIEWER, nonce)
    assert not sup.armed


def test_a_viewer_can_change_nothing(sup: Supervisor) -> None:
    before = (sup.mode, sup.setpoints, sup.tuning(), sup.armed)
    refused = [
        lambda: sup.set_mode(VIEWER, "baseline"),
        lambda: sup.set_setpoints(VIEWER, velocity=0.1),
        lambda: sup.set_param(VIEWER, "mpc.lam_st", 2.0),
        lambda: sup.revert_tuning(VIEWER),
        lambda: sup.disarm(VIEWER),
        lambda: sup.start_recording(VIEWER),
        lambda: sup.add_marker(VIEWER, "hi"),
        lambda: sup.release(VIEWER),
        lambda: sup.inject_fault(VIEWER, "pressure", "silence"),
        lambda: sup.clear_fault(VIEWER, "pressure"),
    ]
    for fn in refused:
        with pytest.raises(AccessDenied):
            fn()
    sup.step(0.5)
    assert (sup.mode, sup.setpoints, sup.tuning(), sup.armed) == before
    assert sup.loop.mode == before[0]
    assert sup.loop.mpc_config == before[2]["mpc"]
    assert not sup.recorder.recording


@pytest.mark.parametrize(
    "changes, match",
    [
        ({"mpc.lam_st": 500.0}, "out of range"),
        ({"mpc.lam_st": -0.1}, "out of range"),
        ({"mpc.lam_st": math.nan}, "not a finite"),
        ({"mpc.lam_st": math.inf}, "not a finite"),
        ({"mpc.lam_st": "2.0"}, "expected a number"),
        ({"mpc.lam_st": True}, "expected a number"),
        ({"mpc.lam_st": None}, "expected a number"),
        ({"mpc.n_samples": 2.5}, "integer"),
        ({"mpc.n_samples": 0}, "out of range"),
        ({"mpc.st_low": 0.4}, "st_low"),  # above st_high = 0.35
        ({"mpc.solver": "scipy"}, "not a tunable"),
        ({"mpc.formulation": "closed"}, "formulation.*not allowed"),
        ({"mpc.formulation": 1}, "formulation.*expected a name"),
        ({"mpc.lam_e": -1.0}, "lam_e.*out of range"),
        ({"mpc.lam_c": math.nan}, "lam_c.*not a finite"),
        ({"mpc.rho": 1000.0}, "not a tunable"),
        ({"pid.depth.kp": -1.0}, "out of range"),
        ({"pid.roll.kp": 1.0}, "not a tunable"),
        ({"mpc.lam_f": 2.0, "mpc.lam_st": 500.0}, "out of range"),  # all or nothing
        ({}, "no changes"),
    ],
)
def test_bad_tuning_is_refused_and_changes_nothing(sup: Supervisor, changes: dict, match: str) -> None:
    before = sup.tuning()
    journal = len(sup.journal())
    with pytest.raises(CommandRefused, match=match):
        sup.set_params(PILOT, changes)
    sup.step(0.2)
    assert sup.tuning() == before
    assert sup.loop.mpc_config == before["mpc"]
    assert sup.loop.body.depth_pid.gains == before["pid.depth"]
    assert len(sup.journal()) == journal


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"velocity": 0.6}, "velocity"),  # envelope 0.5 m/s
        ({"depth": -0.5}, "depth"),
        ({"yaw_rate": math.nan}, "yaw_rate"),
        ({"velocity": "fast"}, "velocity"),
        ({"depth": True}, "depth"),
    ],
)
def test_bad_setpoints_are_refused_and_change_nothing(sup: Supervisor, kwargs: dict, match: str) -> None:
    before = sup.setpoints
    with pytest.raises(CommandRefused, match=match):
        sup.set_setpoints(PILOT, **kwargs)
    sup.step(0.2)
    assert sup.setpoints == before and sup.loop.setpoints == before


def test_bad_mode_is_refused(sup: Supervisor) -> None:
    for bad in ("turbo", 1, None):
        with pytest.raises(CommandRefused):
            sup.set_mode(PILOT, bad)
    assert sup.mode == "mpc"


def test_tuning_reaches_the_loop_is_journalled_and_reverts_in_one_step(sup: Supervisor) -> None:
    ev = Events(sup)
    kp0 = sup.loop.body.depth_pid.gains.kp
    sup.set_params(PILOT, {"mpc.lam_st": 2.0, "pid.depth.kp": 7.0})
    sup.step(0.2)
    assert sup.loop.mpc_config.lam_st == 2.0
    assert sup.loop.body.depth_pid.gains.kp == 7.0
    entries = {e.key: e for e in sup.journal()}
    assert (entries["mpc.lam_st"].who, entries["mpc.lam_st"].old, entries["mpc.lam_st"].new) == (
        f"client {PILOT}", 5.0, 2.0)
    assert (entries["pid.depth.kp"].old, entries["pid.depth.kp"].new) == (kp0, 7.0)
    # one event for each tuned block, when the loop applies it, naming who
    tuning = [e for e in ev.events if e.code == "tuning"]
    assert sorted(e.data["block"] for e in tuning) == ["mpc", "pid.depth"]
    assert all(e.source == "loop" and e.data["who"] == f"client {PILOT}" for e in tuning)
    assert "mpc.lam_st 5.0 -> 2.0" in next(e.message for e in tuning if e.data["block"] == "mpc")
    sup.revert_tuning(PILOT)
    sup.step(0.2)
    assert sup.loop.mpc_config.lam_st == 5.0
    assert sup.loop.body.depth_pid.gains.kp == kp0
    assert sup.journal()[-1].new in (5.0, kp0)


def test_formulation_switches_live_and_back(sup: Supervisor) -> None:
    sup.arm(PILOT)
    sup.set_setpoints(PILOT, velocity=0.2)
    sup.step(3.0)
    plans: list = []
    sup.stream.subscribe(lambda c, m: plans.append(m), [ch.fin_plan(0)])
    sup.set_params(PILOT, {"mpc.formulation": "closed_stroke", "mpc.lam_e": 2.0})
    sup.step(3.0)
    assert sup.loop.mpc_config.formulation == "closed_stroke" and sup.loop.mpc_config.lam_e == 2.0
    assert sup.journal()[-1].key in ("mpc.formulation", "mpc.lam_e")
    # the planner in use changed: a closed-stroke plan's cost includes its energy term
    new = [p for p in plans if p.t > plans[0].t + 1.0]
    assert new and all(math.isfinite(p.cost_total) for p in new)
    last = new[-1]
    ref = FinMpc(sup.loop.mpc_config).cost(last.u, last.target, last.v_body, wrap_angle(last.theta0),
                                           last.u_prev)
    assert ref.energy > 0.0 and last.cost_total == pytest.approx(ref.total, rel=1e-9)
    sup.set_params(PILOT, {"mpc.formulation": "paper"})
    sup.step(0.5)
    assert sup.loop.mpc_config.formulation == "paper"


def test_mode_switch_reaches_the_loop_and_is_an_event(sup: Supervisor) -> None:
    ev = Events(sup)
    sup.set_mode(PILOT, "baseline")
    sup.step(0.5)
    assert sup.loop.mode == "baseline"
    modes = [e for e in ev.events if e.code == "mode"]  # one event, the loop's, naming who
    assert len(modes) == 1 and modes[0].source == "loop" and modes[0].data["who"] == f"client {PILOT}"
    assert sup.journal()[-1].key == "mode"


def test_status_messages_carry_arming_pilot_and_failsafes(sup: Supervisor) -> None:
    ev = Events(sup)
    sup.step(1.2)  # the loop publishes its status at 1 Hz
    assert ev.status and all(s.armed is False and s.pilot == str(PILOT) for s in ev.status)
    sup.arm(PILOT)
    sup.step(1.2)
    assert ev.status[-1].armed is True


def test_pilot_page_gone_holds_depth_and_stops_after_its_timeout(make_console: Callable[..., Console]) -> None:
    sup = make_console(make_config(pilot_gone=FailsafeRule("hold", 2.0))).sup
    try:
        ev = Events(sup)
        for c in (PILOT, VIEWER):
            sup.client_connected(c)
        sup.take_control(PILOT, TOKEN)
        sup.set_setpoints(PILOT, velocity=0.3, yaw_rate=0.1, depth=0.8)
        sup.arm(PILOT)
        sup.step(3.0)
        t_gone = sup.loop.time
        sup.client_disconnected(PILOT)
        sup.step(1.9)
        assert sup.safety.active() == ()
        assert sup.setpoints.velocity == 0.3
        sup.step(0.3)
        assert sup.safety.active() == ("pilot_gone",)
        (trig,) = [e for e in ev.events if e.source == "failsafe" and e.code == "pilot_gone"]
        assert trig.t - t_gone >= 2.0 - 1e-9
        assert trig.data["action"] == "hold"
        depth_now = sup.loop.truth().depth
        sp = sup.setpoints
        assert sp.velocity == 0.0 and sp.yaw_rate == 0.0
        assert abs(sp.depth - depth_now) < 0.2  # held where the robot is, not the old 0.8 target
        assert sup.armed  # hold keeps the fins working
        # latched: the cause (no pilot) is still there
        sup.step(2.0)
        assert sup.safety.active() == ("pilot_gone",)
        # a new pilot: the cause clears, and the setpoints are the pilot's again
        with pytest.raises(CommandRefused, match="pilot_gone"):
            sup.set_setpoints(LOCAL, velocity=0.1)
        sup.take_control(VIEWER, TOKEN)
        sup.step(0.1)
        assert sup.safety.active() == ()
        assert "cleared" in ev.codes("failsafe")
        sup.set_setpoints(VIEWER, velocity=0.1)
        assert sup.setpoints.velocity == 0.1
    finally:
        sup.stop()


@pytest.mark.parametrize("then", ["disarm", "surface"])
def test_a_gone_pilots_hold_escalates_after_its_time_unless_a_pilot_comes_back(
        make_console: Callable[..., Console], then: str) -> None:
    """ArduSub's GCS failsafe disarms a robot whose pilot is gone; here the hold comes first,
    and after ``escalate_after`` of it the robot disarms (or surfaces, as configured)."""
    sup = make_console(make_config(pilot_gone=FailsafeRule("hold", 2.0, then, 10.0))).sup
    try:
        ev = Events(sup)
        for c in (PILOT, VIEWER):
            sup.client_connected(c)
        sup.take_control(PILOT, TOKEN)
        sup.set_setpoints(PILOT, velocity=0.3, depth=0.8)
        sup.arm(PILOT)
        sup.step(1.0)
        t_gone = sup.loop.time
        sup.client_disconnected(PILOT)
        sup.step(2.2)  # held
        assert sup.safety.active() == ("pilot_gone",) and sup.armed and sup.setpoints.velocity == 0.0
        held_depth = sup.setpoints.depth
        sup.step(9.5)  # 9.7 s of hold: not yet
        assert sup.armed and sup.setpoints.depth == held_depth
        sup.step(0.6)
        [trig, esc] = [e for e in ev.events if e.source == "failsafe" and e.code == "pilot_gone"]
        assert trig.data["action"] == "hold" and esc.data["action"] == then and esc.data["escalated"]
        assert esc.t - t_gone >= 2.0 + 10.0 - 1e-9
        assert f"escalated after 10 s of hold: {then}" in esc.message
        if then == "disarm":
            assert not sup.armed and "disarmed" in ev.codes("supervisor")
        else:
            assert sup.armed and sup.setpoints.depth == 0.0 and sup.setpoints.velocity == 0.0
        # a pilot comes back: cleared; gone again later, it holds first again
        sup.take_control(VIEWER, TOKEN)
        sup.step(0.1)
        assert sup.safety.active() == ()
        sup.step(0.5)
        sup.client_disconnected(VIEWER)
        sup.step(2.2)
        assert [e.data["action"] for e in ev.events if e.source == "failsafe" and e.code == "pilot_gone"][-1] == "hold"
    finally:
        sup.stop()


def test_a_pilot_back_before_the_escalation_stops_it(make_console: Callable[..., Console]) -> None:
    sup = make_console(make_config(pilot_gone=FailsafeRule("hold", 2.0, "disarm", 10.0))).sup
    try:
        for c in (PILOT, VIEWER):
            sup.client_connected(c)
        sup.take_control(PILOT, TOKEN)
        sup.arm(PILOT)
        sup.step(1.0)
        sup.client_disconnected(PILOT)
        sup.step(8.0)
        assert sup.safety.active() == ("pilot_gone",)
        sup.take_control(VIEWER, TOKEN)
        sup.step(20.0)
        assert sup.armed and sup.safety.active() == ()
    finally:
        sup.stop()


def test_the_default_pilot_gone_rule_holds_then_disarms_after_30_s(make_console: Callable[..., Console]) -> None:
    sup = make_console(AppConfig(access=AccessConfig(token=TOKEN))).sup
    try:
        sup.client_connected(PILOT)
        sup.take_control(PILOT, TOKEN)
        sup.arm(PILOT)
        sup.step(0.5)
        sup.client_disconnected(PILOT)
        sup.step(2.0 + 29.5)
        assert sup.armed and sup.safety.active() == ("pilot_gone",)
        sup.step(1.0)
        assert not sup.armed
    finally:
        sup.stop()


def test_motor_fault_disarms_and_blocks_arming_until_cleared(sup: Supervisor) -> None:
    ev = Events(sup)
    sup.arm(PILOT)
    sup.step(0.5)
    sup.report_event(Event(0.0, "epos2.2", "fault", "node in fault state", "error"))
    sup.step(0.1)
    assert not sup.armed
    assert "motor" in ev.codes("failsafe")
    assert "disarmed" in ev.codes("supervisor")
    with pytest.raises(CommandRefused, match="motor"):
        sup.request_arm(PILOT)
    sup.report_event(Event(0.0, "epos2.2", "fault_cleared", "fault cleared", "info"))
    sup.step(0.1)
    sup.arm(PILOT)
    assert sup.armed


class NaNDepthRobot(SimRobotIO):
    """The simulator, whose pressure sensor returns NaN after 1 s."""

    def advance_to(self, t: float):
        out = []
        for r in super().advance_to(t):
            if isinstance(r, DepthReading) and r.t > 1.0:
                r = DepthReading(r.t, math.nan, math.nan)
            out.append(r)
        return out


def test_invalid_sensor_values_never_reach_the_loop_and_trigger_the_failsafe(
        make_console: Callable[..., Console]) -> None:
    cfg = make_config(depth=FailsafeRule("disarm", 0.5))
    sup = make_console(cfg,
                     robot_factory=lambda c, ev: (NaNDepthRobot(c.plant, depth=0.5), lambda: None)).sup
    try:
        sup.arm(LOCAL)
        sup.step(1.3)
        assert sup.armed and sup.safety.active() == ()
        sup.step(0.5)
        assert sup.safety.active() == ("depth",)
        assert not sup.armed
        assert sup.fault == ""  # the loop kept running
        assert sup.gate.dropped_readings > 0
        with pytest.raises(CommandRefused, match="depth"):
            sup.arm(LOCAL)
    finally:
        sup.stop()


def test_hand_over_and_release(sup: Supervisor) -> None:
    assert sup.take_control(VIEWER, TOKEN) is False
    sup.hand_over(PILOT, VIEWER)
    assert sup.access.pilot == VIEWER
    with pytest.raises(AccessDenied):
        sup.set_mode(PILOT, "baseline")
    sup.arm(VIEWER)
    with pytest.raises(CommandRefused, match="disarm first"):
        sup.release(VIEWER)
    sup.disarm(VIEWER)
    sup.release(VIEWER)
    assert sup.access.pilot is None


def test_arming_records_and_stop_disarms_and_closes_the_file(
        tmp_path: Path, make_console: Callable[..., Console]) -> None:
    sup = make_console(make_config()).sup
    sup.client_connected(PILOT)
    sup.take_control(PILOT, TOKEN)
    sup.arm(PILOT)
    assert sup.recorder.recording
    sup.add_marker(PILOT, "first lap")
    sup.step(1.0)
    paths = sup.recorder.paths
    sup.stop()
    assert not sup.armed and not sup.recorder.recording
    with SessionReader(paths[0], tmp_path) as r:
        events = [(e.source, e.code) for e in r.events()]
        assert ("supervisor", "armed") in events
        assert ("operator", "marker") in events
        assert ("supervisor", "disarmed") in events
        assert r.message_counts()[ch.BODY_STATE] > 20


def test_automatic_recording_stops_after_the_tail(sup: Supervisor) -> None:
    sup.arm(PILOT)
    sup.step(0.5)
    sup.disarm(PILOT)
    sup.step(0.5)
    assert sup.recorder.recording
    sup.step(1.0)  # record_tail = 1 s: the recorder is told to stop (it closes in its own thread)
    assert _stopped(sup)
    assert sup.recorder.paths[0].stat().st_size > 0


def _stopped(sup: Supervisor) -> bool:
    """Whether the recording stopped (the recorder closes in its own thread: waited for)."""
    wait_for(lambda: not sup.recorder.recording, what="the recording stopped")
    return not sup.recorder.recording


def test_an_automatic_recording_runs_on_until_the_fault_has_cleared(
        tmp_path: Path, make_console: Callable[..., Console]) -> None:
    """A drive fault disarms the robot; the recording goes on while it lasts and for the
    tail after it cleared, so the file holds the clearing."""
    sup = make_console(make_config()).sup  # record_tail 1 s
    try:
        sup.client_connected(PILOT)
        sup.take_control(PILOT, TOKEN)
        sup.arm(PILOT)
        sup.step(0.5)
        sup.report_event(Event(0.0, "epos2.2", "fault", "node in fault state", "error"))
        sup.step(0.1)
        assert not sup.armed and sup.safety.active() == ("motor",)
        sup.step(5.0)  # far past the tail: the fault lasts
        assert sup.recorder.recording
        sup.report_event(Event(0.0, "epos2.2", "fault_cleared", "fault cleared", "info"))
        sup.step(0.5)
        assert sup.safety.active() == () and sup.recorder.recording  # the tail after the clearing
        paths = sup.recorder.paths
        sup.step(1.0)
        assert _stopped(sup)
    finally:
        sup.stop()
    with SessionReader(paths[0], tmp_path) as r:
        events = [(e.source, e.code) for e in r.events()]
    assert ("epos2.2", "fault") in events and ("supervisor", "disarmed") in events
    assert ("epos2.2", "fault_cleared") in events and ("failsafe", "cleared") in events


def test_a_fault_that_never_clears_records_no_longer_than_the_tail_max(make_console: Callable[..., Console]) -> None:
    cfg = make_config().replace(console=ConsoleConfig(supervise_period=0.05, record_tail=1.0, record_tail_max=4.0))
    sup = make_console(cfg).sup
    try:
        sup.client_connected(PILOT)
        sup.take_control(PILOT, TOKEN)
        sup.arm(PILOT)
        sup.step(0.5)
        sup.report_event(Event(0.0, "epos2.2", "fault", "node in fault state", "error"))
        sup.step(3.5)
        assert not sup.armed and sup.recorder.recording
        sup.step(0.6)  # 4 s after the disarm
        assert _stopped(sup) and sup.safety.active() == ("motor",)
    finally:
        sup.stop()
    with pytest.raises(ValueError, match="record_tail_max"):
        ConsoleConfig(record_tail=10.0, record_tail_max=5.0)


def test_the_loop_runs_in_its_own_thread_and_commands_cross_over(make_console: Callable[..., Console]) -> None:
    sup = make_console(make_config(), clock=SteadyPacedClock(pace=10.0)).sup
    sup.client_connected(PILOT)
    sup.take_control(PILOT, TOKEN)
    sup.start()
    try:
        sup.arm(PILOT)  # applied by the loop's thread between chunks
        assert sup.armed
        sup.set_param(PILOT, "mpc.lam_a", 2.0)
        wait_for(lambda: sup.loop.mpc_config.lam_a == 2.0, what="the tuning applied by the loop's thread")
        assert sup.loop.mpc_config.lam_a == 2.0
        assert sup.loop.planner_threads >= 1
    finally:
        sup.stop()
    assert not sup.armed and not sup.running


def test_arming_after_a_wait_swims_as_arming_at_once_and_power_counts_only_armed(
        tmp_path: Path, make_console: Callable[..., Console]) -> None:
    """At the pool the robot waits disarmed before the pilot arms: the strokes the loop ran
    meanwhile were never executed, and must not hold the fins once armed."""
    cfg = load_config("sim-tuned")  # swims from rest (README "Findings")
    cfg = cfg.replace(loop=cfg.loop.replace(mode="baseline"))

    def swim(wait: float) -> float:
        sup = make_console(cfg, sessions_dir=tmp_path / str(wait)).sup
        ev = Events(sup)
        power: list = []
        sup.stream.subscribe(lambda c, m: power.append(m), [ch.POWER])
        try:
            sup.step(wait)  # at rest, disarmed: the DVL's noise is no distance travelled
            assert sup.loop.distance == 0.0
            assert all(p.energy == 0.0 for p in power)
            sup.set_setpoints(LOCAL, velocity=0.2)
            sup.arm(LOCAL)
            sup.step(10.0)
            assert "restarted" in ev.codes("loop")
            swum, armed = sup.loop.distance, power[-1]
            assert armed.energy > 0.0 and armed.mean_total > 0.0
            sup.disarm(LOCAL)
            sup.step(3.0)  # the fins stop and rest: neither is the robot's propulsion
            assert sup.loop.distance == swum
            assert (power[-1].energy, power[-1].mean_total) == pytest.approx(
                (armed.energy, armed.mean_total), rel=0.02)  # the last armed span
            return swum
        finally:
            sup.stop()

    at_once, after_wait = swim(0.0), swim(5.0)
    assert at_once > 0.4
    assert after_wait > 0.8 * at_once


def test_the_planners_are_compiled_before_the_robot_starts(make_console: Callable[..., Console], monkeypatch) -> None:
    """A compile holds the interpreter for minutes: the drives' heartbeats must not be
    supervised yet (their loss would be reported as a fault)."""
    from ucat_console.backend.supervisor import supervisor as supervisor_module

    order: list[str] = []
    warm_up = supervisor_module.warm_up

    def spy(cfg, formulations=None):
        order.append("planners")
        assert cfg.mpc == cfg_in.loop.mpc and cfg.baseline == cfg_in.loop.baseline
        return warm_up(cfg, formulations)

    def robot(c, ev):
        order.append("robot")
        return SimRobotIO(c.plant), lambda: None

    cfg_in = make_config()
    cfg_in = cfg_in.replace(loop=cfg_in.loop.replace(mpc=MpcConfig(n_samples=200)))
    monkeypatch.setattr(supervisor_module, "warm_up", spy)
    sup = make_console(cfg_in, robot_factory=robot).sup
    sup.stop()
    assert order == ["planners", "robot"]


def robot_like_rig(make_console: Callable[..., Console], **failsafes: FailsafeRule) -> Supervisor:
    """The device rig configured as the robot is: the drives are powered only while armed."""
    cfg = load_config("sim-devices")
    cfg = cfg.replace(access=AccessConfig(token=TOKEN), devices=cfg.devices.replace(enable_at_start=False),
                      failsafe=cfg.failsafe.replace(**failsafes))
    return make_console(cfg, clock=None).sup


def drive_states(sup: Supervisor) -> set[str]:
    nodes = sup.rig.nodes
    return {nodes[n].state for n in sup.cfg.devices.epos2.node_ids}


def test_arming_powers_the_drives_and_disarming_stops_them_and_turns_them_off(
        make_console: Callable[..., Console]) -> None:
    sup = robot_like_rig(make_console)
    sup.start()
    try:
        wait_for(lambda: sup.loop.time > 1.0, what="the loop running on the rig")
        assert drive_states(sup) == {"switch_on_disabled"}  # unpowered until armed
        sup.set_setpoints(LOCAL, velocity=0.2)
        for _ in range(2):  # and again after a disarm
            sup.arm(LOCAL)
            assert drive_states(sup) == {"operation_enabled"}
            wait_for(lambda: max(abs(a) for a in sup.loop.truth().fin_angles) > 0.2,
                     what="the fins swimming")
            sup.disarm(LOCAL)
            wait_for(lambda: drive_states(sup) == {"switch_on_disabled"},
                     what="every drive stopped and its power stage off")
            wait_for(lambda: max(abs(w) for w in sup.loop.truth().fin_rates) < 1e-3,
                     what="the fins at rest")
    finally:
        sup.stop()


def test_arming_is_refused_when_a_drive_is_in_fault_until_the_fault_is_reset(
        make_console: Callable[..., Console]) -> None:
    sup = robot_like_rig(make_console, motor=FailsafeRule("disarm", 60.0))  # the drive, not the failsafe, refuses
    sup.start()
    try:
        sup.client_connected(PILOT)
        assert sup.take_control(PILOT, TOKEN)
        wait_for(lambda: sup.loop.time > 1.0, what="the loop running on the rig")
        sup.inject_fault(PILOT, "epos2", "emcy", fin=0)
        wait_for(lambda: "fault" in drive_states(sup), what="the emulated drive in fault")
        with pytest.raises(CommandRefused, match="not every fin drive reached operation enabled"):
            sup.arm(PILOT)
        assert not sup.armed and not sup.recorder.recording
        assert drive_states(sup) == {"fault", "switch_on_disabled"}  # none left powered
        # the pool-side recovery: reset the drive's fault (disarmed), then arm
        sup.client_connected(VIEWER)
        with pytest.raises(AccessDenied):
            sup.reset_drive_faults(VIEWER)
        sup.reset_drive_faults(PILOT)
        assert drive_states(sup) == {"switch_on_disabled"}  # reset, and off until armed
        sup.arm(PILOT)
        assert sup.armed and drive_states(sup) == {"operation_enabled"}
        for armed_refuses in (sup.reset_drive_faults, sup.zero_depth):
            with pytest.raises(CommandRefused, match="disarm first"):
                armed_refuses(PILOT)
    finally:
        sup.stop()


class StallingRobot(SimRobotIO):
    """The simulator, until its link stalls at 0.5 s for as long as ``release`` is unset."""

    def __init__(self, *a, **kw) -> None:
        super().__init__(*a, **kw)
        self.stalled = threading.Event()
        self.release = threading.Event()

    def advance_to(self, t: float):
        if t > 0.5 and not self.release.is_set():
            self.stalled.set()
            self.release.wait()
        return super().advance_to(t)


def test_a_command_the_loop_cannot_take_in_time_is_refused_and_never_done(
        make_console: Callable[..., Console], monkeypatch) -> None:
    robot = StallingRobot()
    sup = make_console(make_config(),
                     robot_factory=lambda c, ev: (robot, lambda: None)).sup
    sup.loop_wait = 0.3  # how long a command waits for the loop's thread
    sup.start()
    try:
        assert robot.stalled.wait(10.0)
        with pytest.raises(CommandRefused, match="nothing was done"):
            sup.arm(LOCAL)
        robot.release.set()
        t = sup.loop.time
        wait_for(lambda: sup.loop.time > t + 1.0, what="the loop going on")
        assert not sup.armed  # the refused arming did not happen later
    finally:
        robot.release.set()
        sup.stop()


def test_a_disarm_acts_at_once_while_a_command_waits_for_a_held_loop(
        make_console: Callable[..., Console]) -> None:
    """A disarm never queues behind another command: with the loop's thread held and an
    arming queued for it, the motors are off at once; the queued arming, given up, never runs."""
    robot = StallingRobot()
    sup = make_console(make_config(), robot_factory=lambda c, ev: (robot, lambda: None)).sup
    ev = Events(sup)
    sup.arm(LOCAL)  # no loop thread yet: at once
    sup.loop_wait = 1.0
    sup.start()
    refused: list[Exception] = []

    def arm_again() -> None:
        try:
            sup.arm(LOCAL)
        except CommandRefused as e:
            refused.append(e)

    other = threading.Thread(target=arm_again)
    try:
        assert robot.stalled.wait(10.0)
        other.start()
        wait_for(lambda: sup.loop.commands.waiting, what="the arming queued for the held loop")
        sup.disarm(LOCAL, "operator")
        assert not sup.armed and "disarmed" in ev.codes("supervisor")
        assert sup.loop.commands.waiting  # the arming still waits: the disarm did not
        other.join(10.0)
        assert refused and "nothing was done" in str(refused[0])
        robot.release.set()
        t = sup.loop.time
        wait_for(lambda: sup.loop.time > t + 1.0, what="the loop going on")
        assert not sup.armed
    finally:
        robot.release.set()
        sup.stop()


class FailingRobot(SimRobotIO):
    """The simulator, until its link breaks at 0.5 s."""

    def advance_to(self, t: float):
        if t > 0.5:
            raise OSError("link to the robot lost")
        return super().advance_to(t)


def test_a_failing_loop_disarms_and_is_reported(make_console: Callable[..., Console]) -> None:
    sup = make_console(make_config(),
                     robot_factory=lambda c, ev: (FailingRobot(c.plant), lambda: None)).sup
    ev = Events(sup)
    sup.arm(LOCAL)
    sup.start()  # as fast as it goes: the robot fails at once
    try:
        wait_for(lambda: not sup.running, what="the loop stopping")
        assert not sup.running
        assert "link to the robot lost" in sup.fault
        assert not sup.armed
        assert "loop_fault" in ev.codes("supervisor")
        with pytest.raises(CommandRefused, match="loop"):
            sup.arm(LOCAL)
    finally:
        sup.stop()


def test_faults_are_injected_only_on_the_simulated_rig(sup: Supervisor) -> None:
    assert sup.rig is None
    with pytest.raises(CommandRefused, match="only the simulated robot behind the device emulators"):
        sup.inject_fault(PILOT, "pressure", "silence")
    with pytest.raises(CommandRefused, match="only the simulated robot"):
        sup.clear_fault(PILOT, "pressure")


def test_the_pilot_rehearses_a_silent_pressure_sensor_on_the_simulated_rig(
        make_console: Callable[..., Console]) -> None:
    cfg = load_config("sim-devices")
    cfg = cfg.replace(access=AccessConfig(token=TOKEN),
                      failsafe=cfg.failsafe.replace(depth=FailsafeRule("hold", 1.0)))
    sup = make_console(cfg, clock=None).sup
    ev = Events(sup)
    sup.start()
    try:
        sup.client_connected(PILOT)
        sup.client_connected(VIEWER)
        assert sup.take_control(PILOT, TOKEN)
        assert sup.rig is not None
        wait_for(lambda: sup.loop.time > 1.0, what="the loop running on the rig")
        assert "depth" not in sup.safety.active()

        # bad entries are refused, naming what is wrong, and inject nothing
        for args, kw, match in [
            (("sonar", "silence"), {}, "sonar"),
            (("pressure", "emcy"), {}, "not a fault of pressure"),
            (("epos2", "emcy"), {"fin": 7}, "fin"),
            (("epos2", "emcy"), {"code": 0x12345}, "16-bit"),
            (("pressure", "silence"), {"duration": -1.0}, "duration"),
            ((["pressure"], "silence"), {}, "names"),
        ]:
            with pytest.raises(CommandRefused, match=match):
                sup.inject_fault(PILOT, *args, **kw)
        assert "fault_injected" not in ev.codes("rig")

        injected = sup.inject_fault(PILOT, "pressure", "silence")
        assert injected.code == "fault_injected" and injected.data["device"] == "pressure"
        wait_for(lambda: "depth" in sup.safety.active(), what="the depth failsafe")
        wait_for(lambda: "fault_injected" in ev.codes("rig"), what="the injection on the events channel")
        wait_for(lambda: "depth" in ev.codes("failsafe"), what="the failsafe on the events channel")

        sup.clear_fault(PILOT, "pressure")
        wait_for(lambda: "depth" not in sup.safety.active(), what="the depth failsafe clearing")
        wait_for(lambda: "fault_cleared" in ev.codes("rig"), what="the clearing on the events channel")
    finally:
        sup.stop()


def test_a_fixed_token_is_in_neither_the_recording_nor_the_log(
        tmp_path: Path, caplog, make_console: Callable[..., Console]) -> None:
    import logging

    secret = "fixed-pilot-token-1234"
    sup = make_console(AppConfig(access=AccessConfig(token=secret))).sup
    try:
        sup.start_recording(LOCAL, "secret check")
        sup.step(0.5)
        with caplog.at_level(logging.INFO):
            logging.getLogger("ucat_console.test").info("a line that quotes the token: %s", secret)
        paths = sup.stop_recording(LOCAL)
    finally:
        sup.stop()
    assert paths and all(secret.encode() not in p.read_bytes() for p in paths)
    with SessionReader(paths[0], tmp_path) as r:
        assert "[access]" in r.config_toml and "token" not in r.config_toml.split("[access]", 1)[1].split("[", 1)[0]
    line = next(r.getMessage() for r in caplog.records if "quotes the token" in r.getMessage())
    assert secret not in line and "<redacted>" in line


def test_a_burst_of_plan_overruns_is_one_event_with_its_count(sup: Supervisor) -> None:
    ev = Events(sup)
    t = sup.loop.time
    for k in range(20):  # the loop's events, as it publishes them
        sup._loop_stream.publish(ch.EVENTS, Event(
            t=t + 0.01 * k, source="loop", code="plan_overrun", message=f"plan {k} late", level="warning",
            data={"fins": [k % 4], "late": 0.001 * k, "solve_time": 0.0005, "plan_latency": 0.02}))
    assert "plan_overrun" not in ev.codes("loop")  # held while the burst goes on
    sup.step(2.0)
    overruns = [e for e in ev.events if e.code == "plan_overrun"]
    assert len(overruns) == 1
    o = overruns[0]
    assert o.data["count"] == 20 and o.data["fins"] == [0, 1, 2, 3]
    assert "20 x plan ready after its hand-over deadline" in o.message and "19.0 ms late" in o.message


def test_disarmed_the_public_fin_states_carry_the_stop_the_gate_sent_and_no_stroke_timeout(
        sup: Supervisor) -> None:
    """The loop publishes what the fins were sent (the arming gate's): after a disarm, the
    stop at each fin's measured angle, though its executor goes on with strokes the gate
    holds back; their timeouts are no events."""
    states: list = []
    sup.stream.subscribe(lambda c, m: states.append(m), [ch.fin_state(pf) for pf in range(4)])
    ev = Events(sup)
    sup.set_setpoints(PILOT, velocity=0.3)
    sup.arm(PILOT)
    sup.step(3.0)
    sup.disarm(PILOT)
    t_disarm, dropped = sup.loop.time, sup.gate.dropped_commands
    sup.step(4.0)
    assert sup.gate.dropped_commands > dropped
    held = [m for m in states if m.t > t_disarm]
    assert held and all((m.angle_cmd, m.rate_cmd) == sup.gate.sent[m.fin] for m in held)
    assert {m.rate_cmd for m in held} == {STOP_RATE}
    assert not [e for e in ev.events if e.code == "stroke_timeout" and e.t > t_disarm]


def test_a_single_overrun_keeps_its_own_message(sup: Supervisor) -> None:
    ev = Events(sup)
    sup._loop_stream.publish(ch.EVENTS, Event(t=sup.loop.time, source="loop", code="plan_overrun",
                                              message="plan for fins [2] ready 3.0 ms after its deadline",
                                              level="warning", data={"fins": [2], "late": 0.003}))
    sup.step(2.0)
    [o] = [e for e in ev.events if e.code == "plan_overrun"]
    assert o.message == "plan for fins [2] ready 3.0 ms after its deadline" and o.data["count"] == 1


def test_only_the_simulated_robot_runs_events_early(make_console: Callable[..., Console]) -> None:
    """A computed reading can run before its time; a device's cannot: a robot other than
    the simulator gets a clock that waits for every event."""
    cfg = make_config().replace(console=ConsoleConfig(supervise_period=0.05, record_tail=1.0, sim_early=0.015))
    for robot, early in (("sim", 0.015), ("sim-devices", 0.0), ("hardware", 0.0)):
        sim = registered_robot("sim").build  # the simulator stands in for every robot's devices
        sup = make_console(cfg.replace(robot=robot), robot_factory=lambda c, ev: sim(c.devices, c.plant, ev),
                           clock=None).sup
        try:
            assert isinstance(sup.clock, SteadyPacedClock) and sup.clock.early == early, robot
        finally:
            sup.stop()


def test_a_paced_supervisor_does_a_chunks_work_every_period_where_the_loop_waits(
        make_console: Callable[..., Console]) -> None:
    """In real time the loop does the supervisor's work between chunks (failsafes, arming,
    commands) where it waits for the clock anyway, without returning from its run: at most
    two periods of loop time apart, and a command queued from another thread still runs."""
    sup = make_console(make_config(), clock=None).sup
    checks: list[float] = []
    check = sup.safety.check
    sup.safety.check = lambda now: checks.append(now) or check(now)  # type: ignore[method-assign]
    runs = []
    run_until = sup.loop.run_until
    sup.loop.run_until = lambda *a, **k: runs.append(a) or run_until(*a, **k)  # type: ignore[method-assign]
    try:
        sup.start()
        wait_for(lambda: sup.loop.time > 1.5, timeout=60.0, what="1.5 s of loop time")
        sup.set_setpoints(LOCAL, velocity=0.15)  # a command, run by the loop's thread
        assert sup.setpoints.velocity == 0.15
    finally:
        sup.stop()
    period = sup.cfg.console.supervise_period
    gaps = [b - a for a, b in zip(checks, checks[1:])]
    assert len(checks) > 20 and max(gaps) <= 2 * period + 0.02
    assert len(runs) < len(checks) / 2  # most chunk ends done inside the loop's run
