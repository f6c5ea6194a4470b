"""The paced clock: which events it waits for (an event due sooner than ``early`` runs at
once, together with the one before it; later ones are waited for), and its bounds."""

from __future__ import annotations

import pytest

from ucat_console.backend.loop.clock import PacedClock
from ucat_console.backend.supervisor.robots import SteadyPacedClock


class Waits:
    """Stands in for the clock's wake-up event: records each wait instead of sleeping."""

    def __init__(self) -> None:
        self.timeouts: list[float] = []

    def wait(self, timeout: float) -> bool:
        self.timeouts.append(timeout)
        return False

    def set(self) -> None:
        pass

    def clear(self) -> None:
        pass


@pytest.mark.parametrize("cls", [PacedClock, SteadyPacedClock])
def test_an_event_due_within_early_runs_at_once_and_a_later_one_is_waited_for(cls) -> None:
    clock = cls(1.0, early=0.05)
    clock.start(0.0)
    waits = clock._wake = Waits()
    clock.wait_until(0.01)  # due in at most 10 ms: run now, with what came before
    assert waits.timeouts == []
    clock.wait_until(30.0)  # due later than early: waited for, never longer than until it is due
    assert len(waits.timeouts) == 1 and clock.early <= waits.timeouts[0] <= 30.0


def test_a_short_wait_sleeps_and_a_long_one_waits_for_an_interrupt() -> None:
    """Up to SLEEP_MAX of wall time the clock sleeps (a cheaper wake-up); a longer wait is on
    the event that ``interrupt()`` sets, so that a stop does not wait for it."""
    from ucat_console.backend.loop.clock import SLEEP_MAX

    clock = PacedClock(1.0)
    clock.start(0.0)
    waits = clock._wake = Waits()
    slept: list[float] = []
    clock._sleep = slept.append
    clock.wait_until(0.5 * SLEEP_MAX)
    assert len(slept) == 1 and 0.0 < slept[0] <= 0.5 * SLEEP_MAX and waits.timeouts == []
    clock.wait_until(30.0)
    assert len(slept) == 1 and len(waits.timeouts) == 1 and waits.timeouts[0] > SLEEP_MAX


def test_an_interrupt_ends_a_long_wait_at_once() -> None:
    import threading

    clock = PacedClock(1.0)
    clock.start(0.0)
    done = threading.Event()
    waiter = threading.Thread(target=lambda: (clock.wait_until(600.0), done.set()))
    waiter.start()
    clock.interrupt()  # before or during the wait: either way it ends (it would last ten minutes)
    assert done.wait(60.0)
    waiter.join()


def test_without_early_every_event_still_ahead_is_waited_for() -> None:
    clock = PacedClock(1.0)
    clock.start(0.0)
    waits = clock._wake = Waits()
    clock.wait_until(30.0)
    clock.wait_until(60.0)
    assert len(waits.timeouts) == 2
    clock.wait_until(-1.0)  # already past: no wait, counted as lag
    assert len(waits.timeouts) == 2 and clock.lag_max >= 1.0


@pytest.mark.parametrize("early", [-0.001, 0.2, float("nan")])
def test_early_out_of_range_is_refused_by_name(early: float) -> None:
    with pytest.raises(ValueError, match="early"):
        PacedClock(1.0, early=early)


def test_the_horizon_is_the_simulated_time_due_within_early_and_lag_is_kept() -> None:
    """The loop runs every event up to :meth:`horizon` at once: events due within ``early``
    of wall time from now (``pace`` times faster in simulated time); how far the loop is
    behind the wall clock when it reports its time counts in ``lag_max``."""
    import math
    import time

    from ucat_console.backend.loop.clock import SimulatedClock

    clock = PacedClock(2.0, early=0.05)
    started = time.perf_counter()
    clock.start(10.0)  # simulated 10 s is due now
    before = time.perf_counter()
    h = clock.horizon(10.0)
    after = time.perf_counter()
    # simulated time due at wall time t is (t - wall0) * pace; the horizon is early later
    assert (before + 0.05 - clock._wall0) * 2.0 <= h <= (after + 0.05 - clock._wall0) * 2.0
    assert h > 10.0 + 0.1 - 1e-9
    assert clock.lag_max <= after - started  # at 10 s the loop was on time
    clock.horizon(9.0)  # a loop still at 9 s is half a second of wall time behind (pace 2)
    assert clock.lag_max >= 0.5
    assert SimulatedClock().horizon(3.0) == math.inf


class FakeWall:
    def __init__(self, now: float) -> None:
        self.now = now

    def __call__(self) -> float:
        return self.now


def test_a_lag_within_max_lag_is_caught_up_and_a_longer_stall_is_skipped_once() -> None:
    """Up to ``max_lag`` behind, the loop catches up (the events due run at once); further
    behind, the clock makes the loop's present due now, counts the stall and hands it to
    the loop once; the time after it is due on the new anchor, nothing is replayed."""
    wall = FakeWall(1000.0)
    clock = PacedClock(1.0, max_lag=0.25)
    clock._now = wall
    assert clock.start(0.0) is True  # loop time 0 is due at 1000.0
    wall.now = 1000.1
    clock.horizon(0.1)
    assert clock.lag == 0.0 and clock.take_skip() == 0.0
    wall.now = 1000.35
    h = clock.horizon(0.2)  # 0.15 s behind: caught up, the events up to the present run now
    assert clock.lag == pytest.approx(0.15) and h == pytest.approx(0.35) and clock.take_skip() == 0.0
    wall.now = 1002.0
    h = clock.horizon(0.25)  # 1.75 s behind: a stall
    assert clock.take_skip() == pytest.approx(1.75) and clock.take_skip() == 0.0  # handed over once
    assert clock.skips == 1 and clock.skipped == pytest.approx(1.75) and clock.lag == 0.0
    assert clock.lag_max == pytest.approx(1.75)
    assert h == pytest.approx(0.25)  # nothing of the missed time runs at once
    assert clock.wall_deadline(0.25) == pytest.approx(1002.0)
    assert clock.wall_deadline(0.5) == pytest.approx(1002.25)  # the next events wait for their time


def test_the_steady_clock_anchors_once_until_a_stall_and_max_lag_is_checked() -> None:
    clock = SteadyPacedClock(1.0, max_lag=0.25)
    assert clock.start(0.0) is True
    assert clock.start(5.0) is False  # a chunk of the same run: no new anchor
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="max_lag"):
            PacedClock(1.0, max_lag=bad)
