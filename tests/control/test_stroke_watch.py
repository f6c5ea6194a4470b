"""The compiled stroke-end detection against the Python watch it replaced, on random inputs,
and the loop's feedback pass against feeding the executors fin by fin."""

from __future__ import annotations

import math

import numpy as np
import pytest

from control.reference_kernels import ReferenceFinWatch
from ucat_console.control.executor import CycleComplete, FinExecutor, SendToServo
from ucat_console.control.params import ExecutorConfig
from ucat_console.control.stroke_watch import (
    BACKWARDS,
    NOTHING,
    STOPPED,
    TIMEOUT,
    StrokeWatches,
    feedback_kernel,
)

CFG = ExecutorConfig()
CODES = {None: NOTHING, "stopped": STOPPED, "timeout": TIMEOUT}


@pytest.mark.parametrize("seed", range(20))
def test_the_compiled_watch_is_the_python_one_on_random_strokes(seed):
    rng = np.random.default_rng(seed)
    ref = ReferenceFinWatch(0, CFG)
    table = StrokeWatches(CFG, 1)
    t = 0.0
    ends = 0
    for _ in range(400):
        op = rng.integers(0, 10)
        if op == 0:  # a stroke, from a known start or not
            theta_from = None if rng.random() < 0.3 else float(rng.normal())
            theta_ref = float(rng.normal())
            w_ref = float(rng.choice([0.05, rng.uniform(0.1, 8.0)]))
            ref.start(t, theta_from, theta_ref, w_ref)
            table.start(0, t, theta_from, theta_ref, w_ref)
        else:  # a feedback sample (sometimes repeated, sometimes without an angle), then a check
            if rng.random() > 0.05:
                t += float(rng.uniform(0.0, 0.02))
            w_fb = float(rng.normal(0.0, 2.0))
            theta_fb = None if rng.random() < 0.1 else float(rng.normal())
            ref.feed(t, w_fb, theta_fb)
            table.feed(0, t, w_fb, theta_fb)
            t_now = t + float(rng.uniform(0.0, 0.005))
            predict = bool(rng.random() < 0.9)
            a, b = ref.check(t_now, predict), table.check(0, t_now, predict)
            assert CODES[a] == b
            ends += b != NOTHING
        assert table.done(0) == ref.done
        assert table.angle(0) == ref.theta_fb
        if ref.active:
            assert table.started(0) == ref.t_start and table.planned(0) == ref.planned
    assert ends > 5  # the run did end strokes


def test_a_sample_older_than_the_last_is_refused():
    table = StrokeWatches(CFG, 1)
    table.feed(0, 1.0, 0.0, None)
    with pytest.raises(ValueError, match="earlier than the last feedback"):
        table.feed(0, 0.5, 0.0, None)


def _sync_pair_run(batched: bool):
    """A synchronised pair (fins 2, 3) and a single fin (0), fed the same samples either fin
    by fin through FinExecutor.on_feedback or through the compiled pass."""
    table = StrokeWatches(CFG, 4)
    pair = FinExecutor.synced(CFG, (2, 3), watches=table)
    single = FinExecutor(CFG, 0, watches=table)
    owners = {0: single, 2: pair, 3: pair}
    members = np.full((4, 2), -1, dtype=np.int64)
    for ex in (pair, single):
        ex.take_over()
        for f in ex.fins:
            members[f, :len(ex.rows)] = ex.rows
    out = []
    for ex in (pair, single):
        out += ex.load([0.6, 3.0, -0.6, 3.0], 0.0, theta_start=0.0)
    fins = np.array([3, 0, 2], dtype=np.int64)  # not in row order: the order matters
    found = np.zeros(2, dtype=np.int64)
    theta = np.zeros(4)
    cmd = {f: (0.6, 3.0) for f in (0, 2, 3)}
    for step in range(1, 400):
        t = step * 0.01
        # each fin moves towards its target at its rate, fin 3 a little slower
        rates = np.zeros(3)
        for k, f in enumerate(fins):
            target, w = cmd[f]
            w = w * (0.8 if f == 3 else 1.0)
            d = target - theta[f]
            dv = math.copysign(min(abs(d), w * 0.01), d)
            theta[f] += dv
            rates[k] = dv / 0.01
        angles = theta[fins].copy()
        if batched:
            k = 0
            while True:
                k = feedback_kernel(table.table, members, fins, t, rates, angles, t, k,
                                    table.w_th, table.min_time, found)
                assert k >= 0
                if k == fins.shape[0]:
                    break
                ex = owners[int(fins[k])]
                out += ex.stroke_checked(t, found[:len(ex.fins)].tolist())
                k += 1
        else:
            for k, f in enumerate(fins):
                out += owners[int(f)].on_feedback(t, float(rates[k]), t, fin=int(f), theta_fb=float(angles[k]))
        for a in out[-4:]:
            if type(a) is SendToServo:
                cmd[a.fin] = (a.theta_ref, a.w_ref)
    return out


def test_the_compiled_pass_acts_as_the_executors_fed_fin_by_fin():
    by_fin, batched = _sync_pair_run(False), _sync_pair_run(True)
    assert batched == by_fin
    assert sum(type(a) is CycleComplete for a in batched) == 2  # both executors ended their plans


def test_the_pass_reports_an_old_sample_with_its_position():
    table = StrokeWatches(CFG, 2)
    members = np.array([[0, -1], [1, -1]], dtype=np.int64)
    fins = np.array([0, 1], dtype=np.int64)
    found = np.zeros(2, dtype=np.int64)
    table.feed(1, 2.0, 0.0, None)
    k = feedback_kernel(table.table, members, fins, 1.0, np.zeros(2), np.zeros(2), 1.0, 0,
                        table.w_th, table.min_time, found)
    assert k == BACKWARDS - 1
