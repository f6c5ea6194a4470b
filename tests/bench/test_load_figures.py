"""The load benchmark's arithmetic: the lag's recovery and how long the load held."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from ucat_console.bench.load import LOAD_GOAL, lag_figures, load_figures


def test_the_time_at_the_goals_load_counts_the_samples_at_or_above_it_until_the_load_ends() -> None:
    # one sample a second: below the goal for 3 s, at it for 4 s, above the end of the load after
    loads = [(0.0, 2.0), (1.0, 5.0), (2.0, 7.9), (3.0, LOAD_GOAL), (4.0, 9.0), (5.0, 9.5), (6.0, 8.5),
             (7.0, 7.0), (8.0, 9.0), (9.0, 12.0), (10.0, 12.0)]
    figures = load_figures(loads, load_s=9.0)
    assert figures["load_at_goal_s"] == pytest.approx(5.0)  # 3-7 s (4 s) and 8-9 s (1 s)
    assert figures["loadavg_max"] == 12.0
    assert load_figures([], 10.0)["load_at_goal_s"] == 0.0


def test_the_lag_is_back_from_the_last_sample_over_the_goal() -> None:
    lags = [(-2.0, 0.05), (-1.0, 0.9), (0.5, 0.3), (1.5, 0.05), (2.5, 0.2), (3.5, 0.01), (6.0, 0.02)]
    figures = lag_figures(lags)
    assert figures["lag_back_under_goal_after_s"] == 3.5
    assert figures["lag_max_during_s"] == 0.9
    assert figures["lag_max_from_5s_after_s"] == 0.02
    assert math.isnan(lag_figures([(-1.0, 0.1)])["lag_back_under_goal_after_s"])


def test_the_spinning_children_end_when_the_benchmark_is_killed() -> None:
    import signal
    import subprocess
    import sys

    from support import wait_for

    code = ("import time; from ucat_console.bench.load import CpuLoad; load = CpuLoad(2).start(); "
            "print(' '.join(str(p.pid) for p in load._procs), flush=True); time.sleep(600)")
    parent = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        hogs = [int(p) for p in parent.stdout.readline().split()]
        assert len(hogs) == 2
    finally:
        parent.send_signal(signal.SIGKILL)  # no chance to stop its children
        parent.wait()

    def gone(pid: int) -> bool:  # ended (a zombie waiting for init counts: it spins no more)
        try:
            stat = Path(f"/proc/{pid}/stat").read_text()
        except FileNotFoundError:
            return True
        return stat.rsplit(")", 1)[1].split()[0] in ("Z", "X")

    wait_for(lambda: all(gone(pid) for pid in hogs), timeout=30.0, what="the spinning children ended")
