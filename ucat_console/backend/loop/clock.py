"""The two clocks the same closed loop runs under.

* :class:`SimulatedClock` (headless): simulated time only, as fast as the machine goes,
  planners called inline in the loop's thread.
* :class:`PacedClock` (real time): simulated time paced to the wall clock (``pace`` times
  faster than real time; 1.0 for the console), planners in their own threads.

The loop's trajectory is defined in simulated time alone (a plan requested at ``t`` is
handed over at ``t + plan_latency``), so both clocks give the same trajectory for the same
seed; the paced clock only adds waiting, and detects wall-clock deadlines that were missed.

A stall. When the loop is held back (a busy computer: the loop's thread did not get to run)
it falls behind the wall clock. Up to ``max_lag`` behind, it catches up: the events that
are due run at once, without waiting. Further behind, the paced clock skips ahead: the
loop's present time is due now from then on (the clock is anchored afresh), the skip is
counted (:attr:`PacedClock.skips`, :attr:`PacedClock.skipped`) and handed to the loop
(:meth:`PacedClock.take_skip`), which records it and tells the robot (``RobotIO.resync``).
The missed wall time is not replayed: on a robot, control computed for a moment long past
would act on stale readings, in a burst. Loop time then runs behind the wall clock by
the time skipped.
"""

from __future__ import annotations

import math
import threading
import time
from abc import ABC, abstractmethod


class Clock(ABC):
    """Maps the loop's simulated time to the wall clock."""

    #: True when planners run in their own threads under this clock
    threaded: bool = False
    #: True when events wait for the wall clock: the loop runs the events up to
    #: :meth:`horizon` at once and waits (:meth:`wait_until`) for a later one
    paced: bool = False

    def start(self, t0: float) -> bool:
        """The loop is at simulated time ``t0`` now. True when that anchored the clock
        to the wall clock afresh (the robot is told: ``RobotIO.resync``)."""
        return False

    @abstractmethod
    def wait_until(self, t: float) -> None:
        """Return when simulated time ``t`` is due (at once when headless)."""

    def wall_deadline(self, t: float) -> float:
        """The wall-clock time (``time.perf_counter``) at which simulated ``t`` is due."""
        return math.inf

    def horizon(self, t_done: float) -> float:
        """The latest simulated time whose events may run now (the loop has reached
        ``t_done``); infinite when nothing is paced."""
        return math.inf

    def interrupt(self) -> None:
        """Wake a :meth:`wait_until` in progress (the loop is being stopped)."""

    def take_skip(self) -> float:
        """The wall time the clock skipped since the last call (s; 0: none)."""
        return 0.0


class SimulatedClock(Clock):
    """Headless: no waiting, planners inline."""

    threaded = False

    def wait_until(self, t: float) -> None:
        return None


#: s of wall time: a wait this short sleeps (``time.sleep``), a longer one waits on an event
#: that :meth:`PacedClock.interrupt` sets. On the development machine's virtual CPUs a
#: sleep's wake-up took 65 us of a core, an ``Event.wait``'s 125 us (a condition, a lock and
#: their system calls): the loop waits some 50 times a second. An interrupt finds a sleep
#: at most this long to finish.
SLEEP_MAX = 0.05


class PacedClock(Clock):
    """Real time, ``pace`` times faster than the wall clock (1.0: real time).

    ``early`` (s of wall time): an event due less than this from now runs at once instead
    of being waited for, so that events close together share one wake-up of the loop (each
    wake-up costs CPU, about 0.1 ms of a core on a virtual machine). Only for a robot whose
    readings are computed (the simulator): a device's reading is not there before its time.
    0 waits for every event. Waits up to :data:`SLEEP_MAX` sleep.

    ``max_lag`` (s of wall time): a loop further behind the wall clock than this skips
    ahead (module docstring); infinite: it always catches up."""

    threaded = True
    paced = True

    def __init__(self, pace: float = 1.0, early: float = 0.0, max_lag: float = math.inf) -> None:
        if not math.isfinite(pace) or not 0.0 < pace <= 1000.0:
            raise ValueError(f"pace: {pace!r} is out of range; allowed: (0, 1000]")
        if not math.isfinite(early) or not 0.0 <= early <= 0.1:
            raise ValueError(f"early: {early!r} is out of range; allowed: [0, 0.1] s")
        if not max_lag > 0.0:  # also refuses NaN
            raise ValueError(f"max_lag: {max_lag!r} is out of range; allowed: (0, inf] s")
        self.pace = float(pace)
        self.early = float(early)
        self.max_lag = float(max_lag)
        self._wall0 = time.perf_counter()
        self._wake = threading.Event()
        self._sleep = time.sleep
        self._now = time.perf_counter
        self.lag_max = 0.0  # s of wall time the loop has been behind, at most
        self.lag = 0.0  # s of wall time the loop was behind when it last reported its time
        self.skips = 0  # stalls skipped
        self.skipped = 0.0  # s of wall time skipped in all
        self._unreported = 0.0  # skipped since the last take_skip

    def start(self, t0: float) -> bool:
        self._wall0 = self._now() - t0 / self.pace
        self._wake.clear()
        return True

    def wall_deadline(self, t: float) -> float:
        return self._wall0 + t / self.pace

    def wait_until(self, t: float) -> None:
        delay = self.wall_deadline(t) - self._now()
        if delay > 0.0:
            if delay >= self.early:
                if delay <= SLEEP_MAX:
                    self._sleep(delay)
                else:
                    self._wake.wait(delay)
        else:
            self.lag_max = max(self.lag_max, -delay)

    def horizon(self, t_done: float) -> float:
        """Events due less than ``early`` of wall time from now run now (see the class
        docstring); the loop's lag behind the wall clock at ``t_done`` counts in
        :attr:`lag_max`, and a lag beyond ``max_lag`` makes ``t_done`` due now."""
        now = self._now()
        lag = now - self.wall_deadline(t_done)
        if lag > self.lag_max:
            self.lag_max = lag
        if lag > self.max_lag:
            self._wall0 += lag
            self.skips += 1
            self.skipped += lag
            self._unreported += lag
            lag = 0.0
        self.lag = lag
        return (now + self.early - self._wall0) * self.pace

    def take_skip(self) -> float:
        skipped, self._unreported = self._unreported, 0.0
        return skipped

    def interrupt(self) -> None:
        self._wake.set()
