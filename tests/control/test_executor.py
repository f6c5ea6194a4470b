"""Execution module (Algorithm 2) driven by a simulated trapezoidal-profile servo."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ucat_console.control.executor import (
    CycleComplete,
    FinExecutor,
    LatePlan,
    PlanRequest,
    SendToServo,
    StrokeTimeout,
)
from ucat_console.control.params import ExecutorConfig

CFG = ExecutorConfig()  # w_th 0.3 rad/s, min stroke 0.02 s, timeout 3x planned, >= 0.1 s
FB_DT = 0.01  # feedback at 100 Hz
SIM_DT = 1e-4


class TrapezoidServo:
    """Profile-position servo: accelerate at ``accel`` up to the profile rate, brake to stop
    exactly at the target. ``dead_time`` delays the start of every move."""

    def __init__(self, theta: float = 0.0, accel: float = 64.0, dead_time: float = 0.0):
        self.theta = theta
        self.w = 0.0
        self.accel = accel
        self.dead_time = dead_time
        self.target = theta
        self.w_ref = 1.0
        self.t_cmd = -math.inf
        self.stop_times: list[float] = []
        self._moving = False

    def command(self, t: float, theta_ref: float, w_ref: float) -> None:
        self.target, self.w_ref, self.t_cmd = theta_ref, w_ref, t

    def step(self, t: float, dt: float) -> None:
        if t < self.t_cmd + self.dead_time:
            return
        err = self.target - self.theta
        if abs(err) < 1e-9 and abs(self.w) < 1e-9:
            if self._moving:
                self.stop_times.append(t)
                self._moving = False
            self.theta, self.w = self.target, 0.0
            return
        self._moving = True
        w_des = math.copysign(min(self.w_ref, math.sqrt(2.0 * self.accel * abs(err))), err)
        dw = max(-self.accel * dt, min(self.accel * dt, w_des - self.w))
        self.w += dw
        step = self.w * dt
        if abs(step) >= abs(err) or (abs(err) < 1e-6 and abs(self.w) < self.accel * dt):
            self.theta, self.w = self.target, 0.0
        else:
            self.theta += step


def run(executor, servos, t_end, t0=0.0, on_actions=None, stuck=()):
    """Step the servos, feed feedback to the executor every FB_DT, obey SendToServo.

    Returns the list of (t, action) in order."""
    log = []
    t = t0
    next_fb = t0 + FB_DT
    n = int(round((t_end - t0) / SIM_DT))
    for _ in range(n):
        t += SIM_DT
        for fin, s in servos.items():
            if fin not in stuck:
                s.step(t, SIM_DT)
        if t >= next_fb - 1e-12:
            next_fb += FB_DT
            for fin, s in servos.items():
                acts = executor.on_feedback(t, s.w, t, fin=fin, theta_fb=s.theta)
                for a in acts:
                    log.append((t, a))
                    if isinstance(a, SendToServo):
                        servos[a.fin].command(t, a.theta_ref, a.w_ref)
                if on_actions is not None:
                    on_actions(t, acts)
    return log


def start(executor, servos, commands, t, theta_start=0.0):
    acts = executor.load(commands, t, theta_start=theta_start)
    for a in acts:
        if isinstance(a, SendToServo):
            servos[a.fin].command(t, a.theta_ref, a.w_ref)
    return acts


def of(log, kind):
    return [(t, a) for t, a in log if isinstance(a, kind)]


def test_stroke_completion_near_the_stop_and_one_signal():
    ex = FinExecutor(CFG, fins=0)
    servo = TrapezoidServo()
    acts = start(ex, {0: servo}, [0.6, 3.0, -0.6, 3.0], 0.0)
    assert [type(a) for a in acts] == [SendToServo]
    assert acts[0].theta_ref == 0.6 and acts[0].w_ref == 3.0
    log = run(ex, {0: servo}, 1.2)
    sends = of(log, SendToServo)
    assert len(sends) == 1
    t_send2, second = sends[0]
    assert second.theta_ref == -0.6 and second.stroke == 1
    # the servo stopped at 0.6 at stop_times[0] (about 0.247 s: 0.047 s ramps, 0.153 s cruise)
    t_stop1 = servo.stop_times[0]
    assert t_stop1 == pytest.approx(0.247, abs=0.01)
    assert abs(t_send2 - t_stop1) <= 0.02
    # the last stroke was sent: the planner is asked once for the next cycle from -0.6
    requests = of(log, PlanRequest)
    assert len(requests) == 1 and requests[0][1].theta_start == -0.6
    assert requests[0][0] == t_send2
    # completion signal exactly once, near the second stop, although feedback keeps coming
    done = of(log, CycleComplete)
    assert len(done) == 1
    t_done, signal = done[0]
    assert signal.idle
    assert abs(t_done - servo.stop_times[1]) <= 0.02
    assert ex.waiting and ex.cycles_done == 1 and ex.strokes_done == 2
    assert ex.timeouts == 0 and ex.late_plans == 0


def test_late_plan_counted_with_its_lateness():
    ex = FinExecutor(CFG, fins=0)
    servo = TrapezoidServo()
    start(ex, {0: servo}, [0.3, 2.0, -0.3, 2.0], 0.0)
    log = run(ex, {0: servo}, 0.8)
    (t_idle, _), = of(log, CycleComplete)
    assert ex.idle_since == t_idle
    acts = ex.load([0.3, 2.0, -0.3, 2.0], t_idle + 0.05)
    late = [a for a in acts if isinstance(a, LatePlan)]
    assert len(late) == 1 and late[0].lateness == pytest.approx(0.05)
    assert ex.late_plans == 1 and ex.lateness_max == pytest.approx(0.05)
    # the late plan starts on arrival
    assert any(isinstance(a, SendToServo) and a.theta_ref == 0.3 for a in acts)
    assert ex.running


def test_plan_ready_in_time_is_not_late_and_starts_at_completion():
    ex = FinExecutor(CFG, fins=0)
    servo = TrapezoidServo()
    plans = iter([[0.4, 2.0, -0.4, 2.0], [0.5, 2.0, -0.5, 2.0]])

    def planner(t, acts):
        for a in acts:
            if isinstance(a, PlanRequest):
                plan = next(plans, None)
                if plan is not None:
                    ex.load(plan, t + 0.002)  # planned during the last stroke

    start(ex, {0: servo}, [0.3, 2.0, -0.3, 2.0], 0.0)
    log = run(ex, {0: servo}, 2.5, on_actions=planner)
    done = of(log, CycleComplete)
    assert [a.idle for _, a in done] == [False, False, True]
    assert ex.late_plans == 0 and ex.plans_loaded == 3
    # each next plan's first stroke is sent in the same step as the completion signal
    sends = of(log, SendToServo)
    first_strokes = [(t, a) for t, a in sends if a.stroke == 0]
    assert [a.theta_ref for _, a in first_strokes] == [0.4, 0.5]
    assert [t for t, _ in first_strokes] == [t for t, _ in done[:2]]


def test_newer_pending_plan_supersedes_older():
    ex = FinExecutor(CFG, fins=0)
    ex.load([0.3, 2.0, -0.3, 2.0], 0.0, theta_start=0.0)
    assert ex.load([0.1, 2.0, -0.1, 2.0], 0.01) == []
    assert ex.load([0.2, 2.0, -0.2, 2.0], 0.02) == []
    assert ex.superseded_plans == 1 and ex.has_pending


def test_stuck_servo_times_out_and_loop_continues():
    ex = FinExecutor(CFG, fins=0)
    servo = TrapezoidServo()
    start(ex, {0: servo}, [0.6, 3.0, -0.6, 3.0], 0.0)
    # planned duration 0.6 / 3 = 0.2 s, timeout 3 x 0.2 = 0.6 s
    log = run(ex, {0: servo}, 1.0, stuck=(0,))
    timeouts = of(log, StrokeTimeout)
    assert len(timeouts) == 1
    t_to, to = timeouts[0]
    assert 0.6 <= t_to <= 0.6 + FB_DT + 1e-9
    assert to.planned == pytest.approx(0.2)
    assert ex.timeouts == 1
    sends = of(log, SendToServo)
    assert sends and sends[0][0] == t_to and sends[0][1].theta_ref == -0.6


def test_tick_times_out_without_feedback():
    ex = FinExecutor(CFG, fins=0)
    ex.load(np.array([0.6, 3.0, -0.6, 3.0]), 0.0, theta_start=0.0)  # plans may be arrays
    assert ex.tick(0.59) == []
    acts = ex.tick(0.61)
    assert isinstance(acts[0], StrokeTimeout)
    assert isinstance(acts[1], SendToServo) and acts[1].theta_ref == -0.6


def test_no_false_completion_while_the_servo_has_not_started():
    # the servo reacts 50 ms after each command, far beyond min_stroke_time (20 ms)
    ex = FinExecutor(CFG, fins=0)
    servo = TrapezoidServo(dead_time=0.05)
    start(ex, {0: servo}, [0.6, 3.0, -0.6, 3.0], 0.0)
    log = run(ex, {0: servo}, 0.6)
    (t_send2, _), = of(log, SendToServo)
    t_stop1 = servo.stop_times[0]
    assert t_stop1 == pytest.approx(0.297, abs=0.01)
    assert abs(t_send2 - t_stop1) <= 0.02
    assert ex.timeouts == 0


def test_sync_pair_starts_each_stroke_together():
    ex = FinExecutor.synced(CFG, (2, 3))
    fast, slow = TrapezoidServo(accel=64.0), TrapezoidServo(accel=16.0)
    servos = {2: fast, 3: slow}
    acts = start(ex, servos, [0.5, 2.0, -0.5, 2.0], 0.0)
    assert sorted(a.fin for a in acts if isinstance(a, SendToServo)) == [2, 3]
    state_at_send = {}

    def watch(t, acts):
        if any(isinstance(a, SendToServo) for a in acts) and not state_at_send:
            state_at_send.update(theta=slow.theta, w=slow.w)

    log = run(ex, servos, 1.5, on_actions=watch)
    sends = of(log, SendToServo)
    assert sorted(a.fin for _, a in sends) == [2, 3]
    (t_a, a), (t_b, b) = sends
    assert t_a == t_b and a.theta_ref == b.theta_ref == -0.5
    # the fast fin stopped long before (about 0.28 s); the pair waited for the slow one
    # (about 0.375 s: 0.125 s ramps at 16 rad/s2, 0.125 s cruise), which is at its target
    # and braking through the threshold when the next stroke starts
    assert fast.stop_times[0] == pytest.approx(0.281, abs=0.01)
    assert t_a > fast.stop_times[0] + 0.05
    assert t_a == pytest.approx(0.375, abs=0.025)
    assert state_at_send["theta"] == pytest.approx(0.5, abs=0.005)
    assert abs(state_at_send["w"]) < CFG.w_threshold
    done = of(log, CycleComplete)
    assert len(done) == 1 and done[0][1].fins == (2, 3)


def test_bad_input():
    ex = FinExecutor(CFG, fins=0)
    with pytest.raises(ValueError, match=r"commands\[1\]"):
        ex.load([0.3, 0.0, -0.3, 2.0], 0.0)
    with pytest.raises(ValueError, match=r"commands\[2\]"):
        ex.load([0.3, 2.0, math.nan, 2.0], 0.0)
    with pytest.raises(ValueError, match="commands"):
        ex.load([0.3, 2.0, -0.3], 0.0)
    ex.on_feedback(1.0, 0.0, 1.0)
    with pytest.raises(ValueError, match="t_fb"):
        ex.on_feedback(0.5, 0.0, 1.0)
    with pytest.raises(ValueError, match="t_now"):
        ex.on_feedback(2.0, 0.0, 1.5)
    with pytest.raises(ValueError, match="fin"):
        FinExecutor.synced(CFG, (2, 3)).on_feedback(0.0, 0.0, 0.0)
