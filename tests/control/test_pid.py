"""PID: limits, integral, anti-windup bound, derivative on measurement, bumpless preset."""

from __future__ import annotations

import math

import pytest

from ucat_console.control.params import PidGains
from ucat_console.control.pid import Pid


def test_proportional_and_limit():
    pid = Pid(PidGains(kp=2.0, limit=10.0))
    assert pid.update(1.5, 0.0) == pytest.approx(3.0)
    pid = Pid(PidGains(kp=100.0, limit=1.0))
    assert pid.update(1.0, 0.0) == 1.0
    assert pid.saturated
    assert pid.update(-1.0, 0.1) == -1.0


def test_integral_accumulates_error_times_time():
    pid = Pid(PidGains(kp=0.0, ki=2.0, limit=5.0))
    out = 0.0
    for i in range(6):  # error 1 from t = 0 to t = 0.5
        out = pid.update(1.0, 0.1 * i)
    # integral = ki * 1 * 0.5 = 1.0
    assert out == pytest.approx(1.0)


def test_anti_windup_leaves_saturation_at_once():
    g = PidGains(kp=0.1, ki=1.0, kd=0.0, limit=1.0)
    pid = Pid(g)
    dt = 0.01
    t = 0.0
    for _ in range(5000):  # error +2 for 50 s, saturated after 0.4 s
        pid.update(2.0, t)
        t += dt
    assert pid.output == 1.0
    # The integral may only grow while kp e + I <= limit: I <= 1 - 0.1 * 2 = 0.8.
    # Without anti-windup it would be about 2 * 50 = 100.
    assert pid.integral <= 0.8 + 1e-9
    # The error changes sign: at most 0.8 - 0.02 (one step of ki e dt) - 0.2 (kp e) = 0.58.
    out = pid.update(-2.0, t)
    assert out <= 0.58 + 1e-9
    assert not pid.saturated


def test_integral_is_bounded_by_the_limit():
    # with kp = 0 the output saturates only through the integral, which stays within the limit
    pid = Pid(PidGains(kp=0.0, ki=10.0, limit=0.5))
    for i in range(1000):
        pid.update(1.0, 0.01 * i)
    assert pid.integral <= 0.5 + 1e-12
    # one step of error -1 pulls the output below the limit: 0.5 - 10 * 0.01 = 0.4
    assert pid.update(-1.0, 10.0) == pytest.approx(0.4)


def test_derivative_on_measurement_has_no_setpoint_kick():
    pid = Pid(PidGains(kp=1.0, kd=0.5, limit=100.0))
    pid.update((0.0, 0.0), 0.0)
    # setpoint step 0 -> 1 with constant measurement: output is kp * 1, no derivative kick
    assert pid.update((1.0, 0.0), 0.1) == pytest.approx(1.0)


def test_derivative_acts_on_measurement_rate():
    pid = Pid(PidGains(kp=1.0, kd=0.5, limit=100.0))
    pid.update((0.2, 0.0), 0.0)
    # measurement rises at 2 /s, error is zero at t = 0.1: output = -kd * 2 = -1
    assert pid.update((0.2, 0.2), 0.1) == pytest.approx(-1.0)


def test_error_form_differentiates_error():
    pid = Pid(PidGains(kp=0.0, kd=0.5, limit=100.0))
    pid.update(0.0, 0.0)
    # error rises by 1 in 0.1 s: derivative of -(-e) -> kd * 10 = 5
    assert pid.update(1.0, 0.1) == pytest.approx(5.0)


def test_preset_is_bumpless():
    pid = Pid(PidGains(kp=1.0, ki=1.0, limit=2.0))
    assert pid.update((1.0, 0.5), 0.0) == pytest.approx(0.5)
    pid.preset(0.9)
    # same time, same inputs: no new integration, output equals the preset value
    assert pid.update((1.0, 0.5), 0.0) == pytest.approx(0.9)
    # 0.1 s later: + ki * 0.5 * 0.1
    assert pid.update((1.0, 0.5), 0.1) == pytest.approx(0.95)


def test_reset_forgets_everything():
    pid = Pid(PidGains(kp=1.0, ki=1.0, limit=2.0))
    pid.update(1.0, 0.0)
    pid.update(1.0, 1.0)
    pid.reset()
    assert pid.integral == 0.0
    assert pid.update(0.5, 5.0) == pytest.approx(0.5)


def test_bad_input():
    pid = Pid(PidGains(kp=1.0))
    with pytest.raises(ValueError, match="error"):
        pid.update(math.nan, 0.0)
    with pytest.raises(ValueError, match="measurement"):
        pid.update((1.0, math.inf), 0.0)
    pid.update(0.0, 1.0)
    with pytest.raises(ValueError, match="t"):
        pid.update(0.0, 0.5)


def test_the_compiled_step_is_the_reference_pid_on_random_inputs():
    """``pid_step`` compiled (as the loop's core runs it) against the Python PID the loop
    ran before (``reference_kernels``), bit for bit, on random gains, errors and times
    with repeated times and saturation."""
    import numpy as np
    from numba import njit

    from control.reference_kernels import ReferencePid
    from ucat_console.control.pid import NPID, PID_KD, PID_KI, PID_KP, PID_LIMIT, pid_reset, pid_step

    step = njit(lambda s, e, y, t: pid_step(s, e, y, t))
    rng = np.random.default_rng(5)
    for case in range(40):
        g = PidGains(kp=float(rng.uniform(0, 50)), ki=float(rng.uniform(0, 5)), kd=float(rng.uniform(0, 1)),
                     limit=float(rng.uniform(0.1, 3)))
        ref = ReferencePid(g)
        s = np.zeros(NPID)
        s[PID_KP], s[PID_KI], s[PID_KD], s[PID_LIMIT] = g.kp, g.ki, g.kd, g.limit
        pid_reset(s)
        t = 0.0
        for _ in range(200):
            t += float(rng.choice([0.0, 0.02, 0.02, 0.013]))
            sp, y = float(rng.normal(0, 2)), float(rng.normal(0, 2))
            assert step(s, sp - y, y, t) == ref.update((sp, y), t)
            assert s[0] == ref.integral and bool(s[2]) == ref.saturated
