"""The closed loop on the simulated U-CAT: tracking, clocks, mode switches, late plans, telemetry."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from support import FakeClock

from ucat_console.robot.readings import DvlVelocity
from ucat_console.backend.arming import STOP_RATE, ArmingGate
from ucat_console.backend.loop.clock import PacedClock
from ucat_console.backend.loop.closed_loop import ClosedLoop
from ucat_console.backend.loop.commands import SetBlock, SetMode, SetSetpoints
from ucat_console.backend.loop.config import LoopConfig
from ucat_console.backend.loop.planners import BaselineFinPlanner, PlanInputs
from ucat_console.backend.sim_robot_io import SimRobotIO
from ucat_console.config import load_config
from ucat_console.robot.fins import PAPER_TO_ROBOT as PAPER_TO_PLANT_FIN
from ucat_console.robot.fins import ROBOT_TO_PAPER as PLANT_TO_PAPER
from ucat_console.control.allocation import BodySetpoints
from ucat_console.control.params import BaselineConfig, MpcConfig, PidGains, PowerConfig
from ucat_console.control.power import PowerEstimator
from ucat_console.robot.readings import FinFeedbacks
from ucat_console.backend.fin_rig import START_FIN_ANGLE
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.stream import TelemetryStream


class Log:
    """Every message of the stream, by channel."""

    def __init__(self, stream: TelemetryStream) -> None:
        self.by: dict[str, list] = {}
        stream.subscribe(self)

    def __call__(self, channel: str, msg: object) -> None:
        self.by.setdefault(channel, []).append(msg)

    def get(self, channel: str) -> list:
        return self.by.get(channel, [])

    def plans(self) -> list:
        return sorted((m for c, ms in self.by.items() if c.endswith("/plan") for m in ms), key=lambda m: (m.t, m.fin))

    def events(self, code: str) -> list:
        return [e for e in self.get(ch.EVENTS) if e.code == code]


def make_loop(mode: str = "mpc", v: float = 0.2, depth: float = 1.0, clock=None, seed: int = 0,
              **cfg_changes) -> tuple[ClosedLoop, SimRobotIO, Log]:
    io = SimRobotIO(depth=depth, velocity=v, seed=seed)
    io.plant.reset(position_ned=(0.0, 0.0, depth), body_velocity=(v, 0, 0, 0, 0, 0),
                   fin_angles=(START_FIN_ANGLE,) * 4, seed=seed)
    stream = TelemetryStream()
    log = Log(stream)
    loop = ClosedLoop(LoopConfig(mode=mode, planner_seed=seed, **cfg_changes), io, stream, clock,
                      setpoints=BodySetpoints(velocity=v, depth=depth))
    return loop, io, log


# Tracking. The loop machinery is tested with the weights and body layer under which this
# plant is controllable, the shipped sim-tuned's (the paper's defaults and what they do are
# the experiments' subject).
_TUNED = load_config("sim-tuned")
TUNED_MPC = _TUNED.loop.mpc
STRONG_BODY = _TUNED.loop.body


@pytest.mark.parametrize("mode,v,changes", [
    ("mpc", 0.2, {"mpc": TUNED_MPC, "body": STRONG_BODY}),
    ("mpc_sync", 0.2, {"mpc": TUNED_MPC, "body": STRONG_BODY}),
    ("baseline", 0.1, {"body": STRONG_BODY}),
])
def test_loop_holds_depth_and_velocity_after_settling(mode: str, v: float, changes: dict) -> None:
    loop, io, _ = make_loop(mode, v=v, **changes)
    loop.run_until(15.0)
    speeds, depths = [], []
    while loop.time < 25.0 - 1e-9:
        loop.run(0.1)
        tr = io.truth()
        speeds.append(tr.velocity[0])
        depths.append(tr.depth)
    assert abs(np.mean(speeds) - v) < 0.04  # m/s, mean over the last 10 s
    assert np.max(np.abs(np.asarray(depths) - 1.0)) < 0.1  # m, at every sample
    assert loop.late_plans == 0 and loop.plans_made > 20


def test_headless_and_paced_threaded_clocks_give_the_same_trajectory() -> None:
    a, io_a, log_a = make_loop("mpc")
    a.run_until(2.0)
    clock = PacedClock(pace=10.0)
    b, io_b, log_b = make_loop("mpc", clock=clock)
    b.run_until(2.0)
    threads = b.planner_threads
    b.close()
    assert threads == 4 and a.planner_threads == 0
    pa, pb = log_a.plans(), log_b.plans()
    assert len(pa) == len(pb) > 8
    for x, y in zip(pa, pb):
        assert (x.t, x.fin, x.u, x.commands, x.theta0, x.target) == (y.t, y.fin, y.u, y.commands, y.theta0, y.target)
    xa, fa = io_a.plant.state_arrays()
    xb, fb = io_b.plant.state_arrays()
    assert np.array_equal(xa, xb) and np.array_equal(fa[:, :4], fb[:, :4])


def test_a_paced_loop_does_its_callers_work_where_it_waits_and_runs_on_to_the_end_it_is_given() -> None:
    """``between`` runs at each wait of a paced loop and moves the end; the loop does not
    return until the end given last, and runs as a loop run to that end at once does."""
    a, io_a, log_a = make_loop("mpc")
    a.run_until(1.5)
    b, io_b, log_b = make_loop("mpc", clock=FakeClock())
    seen: list[float] = []

    def between(t: float) -> float:
        seen.append(t)
        return min(1.5, t + 0.1)

    b.run_until(0.1, between=between)
    b.close()
    assert b.time == pytest.approx(1.5)
    assert len(seen) > 20 and seen == sorted(seen) and seen[-1] > 1.3
    assert [(p.t, p.fin, p.u) for p in log_a.plans()] == [(p.t, p.fin, p.u) for p in log_b.plans()]
    xa, fa = io_a.plant.state_arrays()
    xb, fb = io_b.plant.state_arrays()
    assert np.array_equal(xa, xb) and np.array_equal(fa[:, :4], fb[:, :4])


def test_a_non_finite_end_from_between_is_refused() -> None:
    # a clock a thousand times slower than the wall: the loop is ahead of it at its first
    # event, however busy the machine, so it waits there and asks ``between`` first
    loop, _, _ = make_loop("baseline", clock=PacedClock(pace=0.001))
    with pytest.raises(ValueError, match="between: expected a finite time"):
        loop.run_until(0.5, between=lambda t: math.nan)
    loop.close()


@pytest.mark.parametrize("first,second", [("mpc", "baseline"), ("mpc", "mpc_sync"), ("mpc_sync", "mpc")])
def test_mode_switch_is_bumpless(first: str, second: str) -> None:
    loop, io, log = make_loop(first)
    sent: list[tuple[float, int, float]] = []
    command = io.command_fin

    def spy(fin: int, target: float, w: float) -> None:
        sent.append((loop.time, fin, target))
        command(fin, target, w)

    io.command_fin = spy  # type: ignore[method-assign]
    loop.run_until(3.0)
    before = {pf: [m for m in log.get(ch.fin_plan(pf))] for pf in range(4)}
    loop.submit(SetMode(second))
    loop.run_until(6.0)
    assert [e.data for e in log.events("mode")] == [{"from": first, "to": second}]
    assert loop.mode == second
    for pf in range(4):
        own = before[pf][-1]
        rear = PLANT_TO_PAPER[pf] in (2, 3)
        # a synchronised rear pair plans from the rear-starboard fin (the pair's first fin)
        ref = before[PAPER_TO_PLANT_FIN[2]][-1] if rear and second == "mpc_sync" else own
        new = [m for m in log.get(ch.fin_plan(pf)) if m.mode == second]
        assert new, f"fin {pf} got no plan of the new controller"
        first_new = new[0]
        # the new controller plans from where the old plan leaves the fin, with its u as u_prev
        assert first_new.theta0 == pytest.approx(ref.commands[2])
        assert first_new.u_prev == ref.u
        # no command of the new controller before the fin has finished its old plan: the first
        # new command starts where the fin is (no jump)
        t_new = min(t for t, fin, _ in sent if fin == pf and t >= first_new.t)
        angle_then = [s.angle for s in log.get(ch.fin_state(pf)) if s.t <= t_new][-1]
        assert abs(angle_then - own.commands[2]) < 0.05
    assert not any(abs(t - 3.0) < 1e-9 for t, _, _ in sent)  # nothing sent at the switch itself


def test_slow_plans_and_late_hand_overs_are_counted_and_published() -> None:
    # plan_latency 0: every solve (which takes a positive time) overruns its hand-over
    loop, _, log = make_loop("mpc", plan_latency=0.0)
    loop.run_until(2.0)
    assert loop.plans_made > 0 and loop.plan_overruns == loop.plans_made
    assert len(log.events("plan_overrun")) == loop.plan_overruns
    assert loop.late_plans == 0  # overruns cost nothing in simulated time
    # a hand-over longer than a stroke: the fin waits idle, the plan is late (never a stall)
    loop, _, log = make_loop("mpc", plan_latency=0.5)
    loop.run_until(6.0)
    assert loop.late_plans > 0
    late_events = log.events("late_plan")
    assert len(late_events) == loop.late_plans
    assert all(e.data["lateness"] > 0.0 for e in late_events)
    late_plans = [p for p in log.plans() if p.late]
    assert len(late_plans) == loop.late_plans  # one physical fin per logical fin in this mode
    assert log.get(ch.STATUS)[-1].late_plans == loop.late_plans


def test_a_plan_nobody_waited_for_is_no_overrun() -> None:
    """A slow plan counts only when the fins needed it: not while the fins are not driven
    (disarmed), and, in real time, not when the loop came to its hand-over after it was done."""
    from ucat_console.backend.loop.closed_loop import kept_waiting

    # plan_latency 0: every solve overruns its hand-over, but nobody drives the fins
    loop, _, log = make_loop("baseline", plan_latency=0.0)
    loop._driving = lambda: False
    loop.run_until(2.0)
    assert loop.plans_made > 0 and loop.plan_overruns == 0 and not log.events("plan_overrun")
    driven, _, log = make_loop("baseline", plan_latency=0.0)  # the same, driven
    driven.run_until(2.0)
    assert driven.plan_overruns == driven.plans_made > 0
    # real time (wall clock, s): a plan done after its deadline, the loop there before it
    assert kept_waiting(done=10.5, arrived=10.0, deadline=10.2) == pytest.approx(0.3)
    assert kept_waiting(done=10.5, arrived=10.3, deadline=10.2) == pytest.approx(0.2)
    # a loop running late came to a plan long done: it kept nobody waiting
    assert kept_waiting(done=10.5, arrived=16.0, deadline=10.2) < 0
    # done before its deadline, whenever the loop came
    assert kept_waiting(done=10.1, arrived=10.0, deadline=10.2) < 0


class _Resyncs(SimRobotIO):
    """The simulated robot, noting when the loop tells it its time is due now."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.resyncs: list[float] = []

    def resync(self, t: float) -> None:
        self.resyncs.append(t)


def test_a_paced_loop_held_back_beyond_max_lag_skips_ahead_and_records_the_stall() -> None:
    """Held back 0.5 s (its thread did not run), the loop does not replay the missed time:
    its clock makes the present loop time due now, the robot is told, and the stall is an
    event; the loop then runs on in real time to the end it was given."""
    import time as _time

    io = _Resyncs(depth=1.0, velocity=0.2, seed=0)
    stream = TelemetryStream()
    log = Log(stream)
    clock = PacedClock(pace=1.0, early=0.01, max_lag=0.1)
    loop = ClosedLoop(LoopConfig(mode="baseline"), io, stream, clock,
                      setpoints=BodySetpoints(velocity=0.2, depth=1.0))
    held = []

    def between(t: float) -> float:
        if t > 0.3 and not held:
            held.append(t)
            _time.sleep(0.5)  # the loop's thread held back: 0.5 s of wall time pass
        return 1.0

    loop.run_until(1.0, between=between)
    loop.close()
    assert loop.time == pytest.approx(1.0)
    assert io.resyncs[0] == 0.0  # anchored at the start
    stalls = log.events("stall")  # a busy machine may add stalls of its own
    stall = next(e for e in stalls if e.t >= held[0])
    assert stall.level == "warning" and stall.data["late"] >= 0.5 - clock.early
    assert stall.t in io.resyncs  # re-anchored where it skipped
    assert loop.stalls == clock.skips == len(stalls) and clock.skipped >= 0.5 - clock.early
    assert clock.lag <= clock.max_lag  # never left further behind


def test_tuning_changes_apply_from_the_next_plan_and_are_events() -> None:
    loop, _, log = make_loop("mpc")
    loop.run_until(1.0)
    loop.submit(SetBlock("mpc", loop.mpc_config.replace(lam_st=2.0)))
    depth = loop.pid_gains("depth")
    loop.submit(SetBlock("pid.depth", depth.replace(kp=6.0)))
    loop.run_until(3.0)
    ev = log.events("tuning")
    assert [e.data["changes"] for e in ev] == [{"lam_st": [5.0, 2.0]}, {"kp": [depth.kp, 6.0]}]
    after = [p for p in log.plans() if p.t > 1.0 + 0.03]
    assert after
    for p in after:  # J = lam_f c_force + lam_St c_St + lam_a c_amp + lam_d c_diff with the new lam_St
        assert p.cost_total == pytest.approx(
            1.5 * p.cost_force + 2.0 * p.cost_strouhal + 1.0 * p.cost_amplitude + 1.0 * p.cost_smoothness)
    assert loop.body.depth_pid.gains.kp == 6.0


def test_bad_setpoints_and_commands_are_refused() -> None:
    loop, _, _ = make_loop("mpc")
    with pytest.raises(ValueError, match="velocity"):
        loop.submit(SetSetpoints(velocity=0.6))  # envelope 0.5 m/s
    with pytest.raises(ValueError, match="depth"):
        loop.submit(SetSetpoints(depth=-1.0))
    with pytest.raises(ValueError, match="mode"):
        SetMode("turbo")
    with pytest.raises(ValueError, match="block: 'pid.pitch'"):
        SetBlock("pid.pitch", PidGains())
    with pytest.raises(ValueError, match="depth"):
        SimRobotIO(depth=-0.5)
    assert loop.setpoints == BodySetpoints(velocity=0.2, depth=1.0)


def test_telemetry_rates_and_replayable_baseline_plans() -> None:
    loop, _, log = make_loop("baseline")
    loop.run_until(2.0)
    # ticks at 0, 1/50, ..., 2.0 s: 101 body states, 4 fin states each; power at 10 Hz: 21
    assert len(log.get(ch.BODY_STATE)) == 101
    assert all(len(log.get(ch.fin_state(i))) == 101 for i in range(4))
    assert len(log.get(ch.POWER)) == 21
    assert len(log.get(ch.BODY_COMMAND)) == 101
    assert len(log.get(ch.IMU)) == 201 and len(log.get(ch.DEPTH)) == 41
    # a FinPlan carries every planner input: the baseline replays it exactly
    planner = BaselineFinPlanner(MpcConfig(), BaselineConfig())
    plans = log.plans()
    assert plans
    for p in plans:
        out = planner(PlanInputs(p.t, (PLANT_TO_PAPER[p.fin],), p.target, p.v_body, p.theta0, p.u_prev, p.lag))
        assert out.u == p.u and out.commands == p.commands
    assert PAPER_TO_PLANT_FIN[PLANT_TO_PAPER[2]] == 2
    assert math.isfinite(log.get(ch.POWER)[-1].energy) and log.get(ch.POWER)[-1].energy > 0.0


def test_every_stroke_publishes_its_strouhal_number_with_the_corridor() -> None:
    mpc = MpcConfig(st_low=0.2, st_high=0.4)
    loop, _, log = make_loop("baseline", mpc=mpc)
    loop.run_until(4.0)
    for fin in range(4):
        strokes = log.get(ch.fin_strouhal(fin))
        plans = [p for p in log.plans() if p.fin == fin]
        # two strokes per planned cycle: the plans started so far, each with its first
        # stroke sent and all but the last with both
        assert 2 * len(plans) - 1 <= len(strokes) <= 2 * len(plans)
        for s in strokes:
            assert (s.fin, s.st_low, s.st_high, s.st_opt) == (fin, 0.2, 0.4, mpc.st_opt)
            # St = 2 f A / V of a stroke: half a cycle of |d| / w seconds, amplitude |d| L_f / 2
            f = 1.0 / (2.0 * abs(s.stroke) / s.rate)
            a = abs(s.stroke) * mpc.fin_length / 2.0
            assert s.st == pytest.approx(2.0 * f * a / max(s.v_body, mpc.v_floor), rel=1e-9)
        # the strokes' rates are the plan's: w_1, w_2 of each cycle
        rates = [p.commands[i] for p in plans for i in (1, 3)]
        assert [s.rate for s in strokes] == rates[:len(strokes)]


class LateDvlRobot(SimRobotIO):
    """The simulator whose DVL reports only from ``dvl_from`` s on, without bottom lock
    when ``lock`` is False (as a DVL still connecting, or too close to the surface)."""

    def __init__(self, dvl_from: float, lock: bool, **kw) -> None:
        super().__init__(**kw)
        self.dvl_from, self.lock = dvl_from, lock
        self.first_dvl_t: float | None = None

    def advance_to(self, t: float):
        out = []
        for r in super().advance_to(t):
            if isinstance(r, DvlVelocity):
                if r.t < self.dvl_from:
                    continue
                if not self.lock:
                    r = dataclasses.replace(r, valid=False)
                if self.first_dvl_t is None:
                    self.first_dvl_t = r.t
            out.append(r)
        return out


@pytest.mark.parametrize("lock", [True, False], ids=["bottom-lock", "no-bottom-lock"])
def test_the_first_plans_wait_for_the_first_dvl_report(lock: bool) -> None:
    io = LateDvlRobot(0.6, lock, depth=0.5, seed=3)
    stream = TelemetryStream()
    log = Log(stream)
    loop = ClosedLoop(LoopConfig(mode="baseline"), io, stream, setpoints=BodySetpoints(velocity=0.2, depth=1.0))
    loop.run(3.0)
    plans = log.plans()
    assert io.first_dvl_t is not None and plans
    # no fin moved on a command made before the DVL had reported
    assert min(p.t for p in plans) >= io.first_dvl_t
    assert all(s.angle_cmd == 0.0 for c in (ch.fin_state(f) for f in range(4))
               for s in log.get(c) if s.t < io.first_dvl_t)
    # and from then on the fins stroke, on the depth loop's command even without bottom lock
    assert any(s.angle_cmd != 0.0 for s in log.get(ch.fin_state(0)) if s.t > io.first_dvl_t)
    assert max(abs(p.target[1]) for p in plans) > 0.05
    if not lock:
        assert all(c.force_x == 0.0 for c in log.get(ch.BODY_COMMAND))  # no speed measured: no surge command


class RecordingRobot(SimRobotIO):
    """The simulated robot, keeping every encoder sample it delivers."""

    def __init__(self, **kw) -> None:
        super().__init__(**kw)
        self.samples: list[tuple[float, np.ndarray]] = []

    def advance_to(self, t: float) -> list:
        out = super().advance_to(t)
        for r in out:
            if isinstance(r, FinFeedbacks):
                self.samples.append((r.t, r.position_rad))
        return out


def test_the_power_estimate_uses_the_fins_coefficients_not_the_controllers() -> None:
    """An MPC given other fin coefficients (identified: C_D 3.22) plans with them; the power
    is still the fins' own (PowerConfig), as an estimate over the same encoder samples says."""
    io = RecordingRobot(depth=1.0, velocity=0.2)
    stream = TelemetryStream()
    log = Log(stream)
    identified = TUNED_MPC.replace(c_d=3.22, c_l=1.15)
    loop = ClosedLoop(LoopConfig(mode="mpc", mpc=identified, body=STRONG_BODY), io, stream,
                      setpoints=BodySetpoints(velocity=0.2, depth=1.0))
    loop.run_until(6.0)
    loop.close()
    last = log.get(ch.POWER)[-1]
    fins = [PowerEstimator(PowerConfig()) for _ in range(4)]
    for t, pos in io.samples:
        if t <= last.t + 1e-9:
            for f in range(4):
                fins[f].update(t, float(pos[f]))
    assert last.energy > 0.0
    assert last.energy == pytest.approx(sum(f.energy for f in fins), rel=1e-9)
    assert last.per_fin == pytest.approx(tuple(f.last.p_fin for f in fins), rel=1e-9)


def test_through_the_arming_gate_the_fin_states_carry_what_each_fin_was_sent() -> None:
    """Armed, each fin state's set-point is one its fin was sent. Disarmed, the gate holds
    the executors' strokes back and stops each fin at its measured angle: the fin states
    carry that stop, and the strokes' timeouts (no stroke was sent) are neither counted nor
    published."""
    inner = SimRobotIO(depth=1.0, velocity=0.2, seed=0)
    received: list[tuple[int, float, float]] = []
    command = inner.command_fin

    def spy(fin: int, target: float, rate: float) -> None:
        received.append((fin, target, rate))
        command(fin, target, rate)

    inner.command_fin = spy  # type: ignore[method-assign]
    gate = ArmingGate(inner)
    stream = TelemetryStream()
    log = Log(stream)
    loop = ClosedLoop(LoopConfig(mode="baseline"), gate, stream, driving=lambda: gate.armed,
                      setpoints=BodySetpoints(velocity=0.2, depth=1.0))
    gate.arm()
    loop.run_until(4.0)
    for pf in range(4):
        sent = {(0.0, 0.0)} | {(a, r) for f, a, r in received if f == pf}
        assert {(s.angle_cmd, s.rate_cmd) for s in log.get(ch.fin_state(pf))} <= sent
    assert len(received) > 8

    gate.disarm()
    n, timeouts = len(received), loop.stroke_timeouts
    before = {pf: len(log.get(ch.fin_state(pf))) for pf in range(4)}
    loop.run_until(8.0)
    loop.close()
    stops = {f: (a, r) for f, a, r in received[n:]}
    assert len(received) == n + 4 and sorted(stops) == [0, 1, 2, 3]  # the stops, nothing else
    assert all(r == STOP_RATE for _, r in stops.values())
    assert gate.dropped_commands > 0  # the executors went on with their strokes
    for pf in range(4):
        held = log.get(ch.fin_state(pf))[before[pf]:]
        assert held and {(s.angle_cmd, s.rate_cmd) for s in held} == {stops[pf]}
    assert loop.stroke_timeouts == timeouts
    assert [e for e in log.events("stroke_timeout") if e.t > 4.0] == []
