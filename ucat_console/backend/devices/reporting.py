"""How a driver turns device faults into typed :class:`Event` messages.

One :class:`EventReporter` per driver stamps events with the driver's clock and source
name, limits repeated events of one code (a noisy line must not flood the stream; the next
event carries how many were suppressed), reports lasting conditions (silence, broken
loop) once when they start and once when they end, and never lets a failing sink stop the
reader thread. A :class:`SilenceWatch` turns "nothing arrived for a while" into such a
condition, judged on what the reader could have heard: a reader that was held back reads
what waited for it before it looks at the silence, and a device that runs in this process
(an emulator of the simulated rig) is silent only for as long as it has run (its
``device_time``), not for as long as a busy machine held it back.
"""

from __future__ import annotations

import logging
import math
import threading
from typing import Any, Callable

from ucat_console.telemetry.events import Event, EventSink

log = logging.getLogger(__name__)

#: what a device event says happened to a sensor's readings (the failsafes' labels): the
#: codes the IMU, DVL and pressure drivers and the plausibility checks report, each once here
READING_FAULTS = {
    "silence": "silent",
    "checksum": "garbled", "garbage": "garbled", "malformed": "garbled",  # IMU (MIP)
    "malformed_json": "garbled", "overlong_line": "garbled", "malformed_line": "garbled",  # DVL, ADC
    "invalid_data": "invalid", "broken_loop": "invalid", "bottom_lock_lost": "invalid",
    "implausible": "implausible",  # readings dropped by the plausibility checks (plausibility.py)
    "port_error": "port error", "connect_failed": "unreachable",
}

_LOG_LEVELS = {
    "debug": logging.DEBUG,
    "info": logging.INFO,
    "warning": logging.WARNING,
    "error": logging.ERROR,
    "fatal": logging.CRITICAL,
}


class EventReporter:
    """Typed, timestamped, rate-limited events for one source (``"imu"``, ``"dvl"`` ...)."""

    def __init__(
        self,
        source: str,
        sink: EventSink,
        clock: Callable[[], float],
        min_interval_s: float = 1.0,
    ) -> None:
        self.source = source
        self._log = logging.getLogger(f"ucat_console.backend.devices.{source}")
        self._sink = sink
        self._clock = clock
        self._min_interval = float(min_interval_s)
        self._lock = threading.Lock()
        self._last: dict[str, float] = {}
        self._suppressed: dict[str, int] = {}
        self._conditions: set[str] = set()

    def emit(self, code: str, message: str, level: str = "warning", /, **data: Any) -> Event:
        """Send one event now."""
        event = Event(
            t=self._clock(), source=self.source, code=code, message=message, level=level,
            data=dict(data),
        )
        self._log.log(_LOG_LEVELS.get(level, logging.WARNING), "%s: %s", code, message)
        try:
            self._sink(event)
        except Exception:  # a broken sink must not stop a reader thread
            log.exception("%s: event sink failed on %s", self.source, code)
        return event

    def throttled(self, code: str, message: str, level: str = "warning", /, **data: Any) -> bool:
        """Send an event unless one of this code went out less than ``min_interval_s`` ago.

        Returns True when the event was sent; suppressed events are counted and the count
        travels with the next one as ``data["suppressed"]``.
        """
        now = self._clock()
        with self._lock:
            last = self._last.get(code)
            if last is not None and now - last < self._min_interval:
                self._suppressed[code] = self._suppressed.get(code, 0) + 1
                return False
            self._last[code] = now
            suppressed = self._suppressed.pop(code, 0)
        if suppressed:
            data["suppressed"] = suppressed
        self.emit(code, message, level, **data)
        return True

    def condition(
        self, code: str, active: bool, message: str, level: str = "warning", /, **data: Any
    ) -> None:
        """Report a lasting condition on its edges: ``code`` when it starts, ``recovered`` when it ends."""
        with self._lock:
            was = code in self._conditions
            if active == was:
                return
            if active:
                self._conditions.add(code)
            else:
                self._conditions.discard(code)
        if active:
            self.emit(code, message, level, **data)
        else:
            self.emit("recovered", message, "info", fault=code, **data)

    def is_active(self, code: str) -> bool:
        with self._lock:
            return code in self._conditions


class SilenceWatch:
    """The ``silence`` condition of one input: nothing valid arrived for ``timeout_s``.

    ``received`` marks an arrival (and ends a reported silence with ``recovered``);
    ``check`` reports the start of a silence while the watch is armed. ``noun``/``nouns``
    name what arrives (``"packet"``, ``"packets"``) in the event messages.

    The silence runs from the last arrival up to what the reader has heard: the present,
    or, with ``device_time`` (the time an in-process device has run to, on ``clock``), the
    device's time when the reader's latest read began (:meth:`reading`): what the device
    sent by then was waiting for that read.
    """

    def __init__(
        self,
        events: EventReporter,
        clock: Callable[[], float],
        timeout_s: float,
        noun: str,
        nouns: str,
        armed: bool = True,
        device_time: Callable[[], float] | None = None,
    ) -> None:
        self._events = events
        self._device_time = device_time
        self._heard = math.inf
        self._clock = clock
        self.timeout_s = float(timeout_s)
        self._noun = noun
        self._nouns = nouns
        self.armed = armed
        self._last = 0.0

    def reset(self) -> None:
        """Count the silence from now (a port opened, a connection made)."""
        self._last = self._clock()

    def arm(self) -> None:
        """Count from now and report silence from here on."""
        self.reset()
        self.armed = True

    def disarm(self) -> None:
        self.armed = False

    def reading(self) -> None:
        """A read of the input begins (call it before each read)."""
        if self._device_time is not None:
            self._heard = self._device_time()

    def received(self, now: float) -> None:
        self._last = now
        if self._events.is_active("silence"):
            self._events.condition("silence", False, f"{self._nouns} arrive again")

    def check(self) -> float:
        """Report silence when armed and quiet too long; returns the seconds since the last
        arrival, as far as heard (class docstring)."""
        quiet = min(self._clock(), self._heard) - self._last
        if self.armed and quiet > self.timeout_s:
            self._events.condition(
                "silence", True, f"no {self._noun} for more than {self.timeout_s:g} s",
                "error", timeout_s=self.timeout_s,
            )
        return quiet
