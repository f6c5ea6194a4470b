"""What the device emulators (IMU, pressure ADC, DVL) share.

:class:`EmulatorThread` is the worker thread: ``start``/``stop`` (also as a context
manager), a loop that calls the emulator's ``_step`` until stopped and survives I/O
errors and surprises (logged, then a short pause), fault injection (:mod:`.faults`), and
the output held back while the ``slow`` fault is active (:class:`DelayedOutput`).
"""

from __future__ import annotations

import heapq
import itertools
import logging
import math
import threading
from typing import Callable, Generic, Self, TypeVar

from ucat_console.backend.devices.background import BackgroundThread
from ucat_console.backend.devices.faults import Fault, FaultInjectable, FaultSet, FaultSettings

T = TypeVar("T")

_ERROR_PAUSE_S = 0.05


def next_tick(due: float, period: float, now: float) -> float:
    """The next due time of a periodic output sent at ``now`` (due at ``due``).

    One period on, but never more than one period behind ``now``: a stalled emulator
    does not make up the missed outputs in a burst.
    """
    return max(due + period, now - period)


class DelayedOutput(Generic[T]):
    """Items held back until they fall due, released in due order (thread-safe)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._heap: list[tuple[float, int, T]] = []
        self._seq = itertools.count()

    def push(self, due: float, item: T) -> None:
        with self._lock:
            heapq.heappush(self._heap, (due, next(self._seq), item))

    def pop_due(self, now: float) -> list[T]:
        """The items due at ``now``, oldest first, removed from the queue."""
        out: list[T] = []
        with self._lock:
            while self._heap and self._heap[0][0] <= now:
                out.append(heapq.heappop(self._heap)[2])
        return out

    def next_due(self) -> float:
        """When the next item falls due (``inf`` when none waits)."""
        with self._lock:
            return self._heap[0][0] if self._heap else math.inf


class EmulatorThread(BackgroundThread, FaultInjectable):
    """Worker-thread lifecycle and fault handling of one emulator.

    A subclass sets ``_name`` (``"imu emulator"``: log messages and, dashed, the thread
    name), implements ``_step`` (one pass of its loop, waiting at most about 50 ms) and
    may override ``_begin`` (before the first step), ``_open`` (in :meth:`start`, before
    the thread) and ``_close`` (in :meth:`stop`, after it). ``_t0`` is the start time.
    :attr:`time` is the emulated device's present: every output due by then has gone out
    (a step sends what is due by its own start, or later).
    """

    _name = "emulator"
    #: errors of the emulator's own transport: logged as a warning, then the loop goes on
    _io_errors: tuple[type[Exception], ...] = (OSError,)

    def __init__(self, clock: Callable[[], float], fault_settings: FaultSettings) -> None:
        super().__init__()
        self._clock = clock
        self._fault_settings = fault_settings
        self.faults = FaultSet(clock)
        self._t0 = 0.0
        self.time = -math.inf
        self._log = logging.getLogger(type(self).__module__)

    def start(self) -> Self:
        if self._thread is not None:
            return self
        self._open()
        self._t0 = self._clock()
        self._spawn(self._name.replace(" ", "-"))
        return self

    # ------------------------------------------------------------ for subclasses

    def _open(self) -> None:
        """Set up the transport (called by :meth:`start` before the thread runs)."""

    def _begin(self, now: float) -> None:
        """Set up the schedule (called in the thread before the first step)."""

    def _step(self) -> None:
        raise NotImplementedError

    def _held_back(self, now: float, item: T, queue: DelayedOutput[T]) -> bool:
        """While ``slow`` is active, queue ``item`` for ``now + slow_delay_s``; True when queued."""
        if not self.faults.active(Fault.SLOW):
            return False
        queue.push(now + self._fault_settings.slow_delay_s, item)
        return True

    # ------------------------------------------------------------ loop

    def _run(self) -> None:
        self._begin(self._clock())
        while not self._stop.is_set():
            try:
                t = self._clock()
                self._step()
                self.time = t
            except self._io_errors as e:
                if self._stop.is_set():
                    break
                self._log.warning("%s: %s", self._name, e)
                self._stop.wait(_ERROR_PAUSE_S)
            except Exception:
                self._log.exception("%s: unexpected error", self._name)
                self._stop.wait(_ERROR_PAUSE_S)
