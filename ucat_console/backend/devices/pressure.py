"""Gems 3101P pressure transducer (4-20 mA) read through a serial ADC; depth from pressure.

ADC line format (one reading per line, ASCII)::

    I=<current>mA\\r\\n        e.g.  I=12.345mA\\r\\n

``<current>`` is the loop current in mA as a decimal number; ``\\n`` alone also ends a
line. Anything else on a line is a malformed line.

Conversions are the robot's (``robot/units.py``, one definition each, with their inverses
for the emulator and the simulated transducer): gauge pressure
``p = p_min + (I - 4 mA) / 16 mA * span``; depth ``d = (p - p_surface) / (rho g)`` with
standard gravity and ``rho`` configured (997 kg/m^3 fresh water, 1029 salt water).

``p_surface`` starts at ``surface_pressure_pa`` and is set by :meth:`PressureDriver.zero`
(zero-offset calibration at the surface: the mean pressure of the next readings).

A current below ``loop_min_ma`` (3.8 mA) or above ``loop_max_ma`` (20.5 mA) means a
broken or shorted loop: it is reported as a ``broken_loop`` Event (and ``recovered``
when it ends) and never turned into a depth. A current within those but at or below
4 mA or above 20 mA is outside the transducer's span (saturated,
``plausibility.loop_current_problem``): it is dropped too, counted and reported as
``implausible`` (``plausibility.DropCounter``: with the count, at once and then once a
second), and never zeroed on. Other
Events (source ``"pressure"``): ``malformed_line``, ``overlong_line``, ``silence``,
``port_error``, ``reconnected``, ``zeroed``.
"""

from __future__ import annotations

import math
import re
import threading
import time
from dataclasses import dataclass
from typing import Callable, Literal

from ucat_console.backend.devices.lines import LineSplitter, Overlong
from ucat_console.backend.devices.plausibility import DropCounter, loop_current_problem
from ucat_console.robot.readings import DepthReading
from ucat_console.robot.units import LOOP_MAX_MA, LOOP_MIN_MA, RHO_FRESH, current_to_pressure, pressure_to_depth
from ucat_console.backend.devices.serial_link import BAUD_RATES
from ucat_console.backend.devices.serial_reader import SerialReader
from ucat_console.telemetry.events import EventSink
from ucat_console.typedconf import Config, param


SOURCE = "pressure"

_LINE = re.compile(rb"^\s*I=([+-]?(?:\d+(?:\.\d*)?|\.\d+))\s*mA\s*$")


@dataclass(frozen=True)
class PressureConfig(Config):
    """Serial ADC link, transducer scaling, water density and fault limits."""

    port: str = param("/dev/ttyUSB0", doc="serial device of the ADC")
    baud: int = param(115200, choices=BAUD_RATES, unit="baud", doc="serial line rate")
    p_min_pa: float = param(0.0, lo=-1.0e5, hi=1.0e7, unit="Pa", doc="gauge pressure at 4 mA")
    span_pa: float = param(
        1.0e6, lo=0.0, hi=1.0e8, lo_open=True, unit="Pa", doc="pressure span from 4 to 20 mA"
    )
    rho: float = param(
        RHO_FRESH, lo=900.0, hi=1100.0, unit="kg/m3", doc="water density (997 fresh, 1029 salt)"
    )
    surface_pressure_pa: float = param(
        0.0, lo=-1.0e5, hi=1.0e7, unit="Pa", doc="gauge pressure at the surface until zeroed"
    )
    loop_min_ma: float = param(LOOP_MIN_MA, lo=0.0, hi=4.0, unit="mA", doc="lower current: broken loop")
    loop_max_ma: float = param(LOOP_MAX_MA, lo=20.0, hi=30.0, unit="mA", doc="higher current: shorted loop")
    zero_samples: int = param(20, lo=1, hi=10000, doc="readings averaged by the surface zeroing")
    silence_timeout_s: float = param(
        1.0, lo=0.01, hi=60.0, unit="s", doc="report silence after this long without a reading"
    )
    reopen_interval_s: float = param(
        1.0, lo=0.05, hi=60.0, unit="s", doc="retry opening a failed port this often"
    )
    read_timeout_s: float = param(0.05, lo=0.001, hi=1.0, unit="s", doc="serial read timeout")


class AdcLineError(ValueError):
    """An ADC line that is not ``I=<number>mA``."""


def parse_adc_line(line: bytes) -> float:
    """Loop current (mA) from one line without its terminator."""
    m = _LINE.match(line)
    if m is None:
        raise AdcLineError(f"ADC line {line[:40]!r} is not of the form I=<number>mA")
    value = float(m.group(1))
    if not math.isfinite(value):
        raise AdcLineError(f"ADC line {line[:40]!r}: current is not finite")
    return value


def format_adc_line(current_ma: float) -> bytes:
    """One ADC line for a current (what the ADC sends)."""
    return f"I={current_ma:.4f}mA\r\n".encode()


@dataclass(frozen=True)
class AdcIssue:
    kind: Literal["malformed_line", "overlong_line"]
    detail: str


class AdcLineParser:
    """Incremental: ``feed(bytes)`` returns currents (mA) and :class:`AdcIssue`."""

    def __init__(self, max_line_bytes: int = 256) -> None:
        self._lines = LineSplitter(max_line_bytes)

    def reset(self) -> None:
        self._lines.reset()

    def feed(self, data: bytes) -> list[float | AdcIssue]:
        out: list[float | AdcIssue] = []
        for line in self._lines.feed(data):
            if isinstance(line, Overlong):
                out.append(AdcIssue("overlong_line", f"line of more than {line.nbytes - 1} bytes dropped"))
                continue
            try:
                out.append(parse_adc_line(line))
            except AdcLineError as e:
                out.append(AdcIssue("malformed_line", str(e)))
        return out


# ---------------------------------------------------------------- driver


class PressureDriver(SerialReader[DepthReading]):
    """Reads the ADC, converts to depth and delivers :class:`DepthReading`.

    ``start``/``stop`` and the reader thread come from :class:`SerialReader`.
    """

    config: PressureConfig

    def __init__(
        self,
        config: PressureConfig,
        on_reading: Callable[[DepthReading], None],
        on_event: EventSink,
        clock: Callable[[], float] = time.monotonic,
        device_time: Callable[[], float] | None = None,
    ) -> None:
        super().__init__(config, SOURCE, on_reading, on_event, clock, ("ADC line", "ADC lines"), device_time)
        self._parser = AdcLineParser()
        self._lock = threading.Lock()  # zeroing
        self._surface = config.surface_pressure_pa
        self._zero_samples: list[float] | None = None
        self._zero_target = 0
        self._zero_done = threading.Event()
        self._implausible = DropCounter(
            lambda n, why: self.events.emit("implausible", f"{n} ADC {'line' if n == 1 else 'lines'} dropped "
                                            f"as implausible: {why}", "error", dropped=n, reason=why))

    @property
    def surface_pressure_pa(self) -> float:
        return self._surface

    def zero(self, samples: int | None = None, timeout_s: float = 5.0) -> float | None:
        """Zero-offset calibration at the surface: mean pressure of the next readings.

        Returns the new surface pressure, or None (and an Event) when not enough valid
        readings arrive within ``timeout_s``; the old zero then stays.
        """
        n = self.config.zero_samples if samples is None else int(samples)
        if n < 1:
            raise ValueError(f"samples: {n!r} must be at least 1")
        with self._lock:
            self._zero_target = n
            self._zero_samples = []
            self._zero_done.clear()
        finished = self._zero_done.wait(timeout_s)
        with self._lock:
            got, self._zero_samples = self._zero_samples or [], None
        if not finished or len(got) < n:
            self.events.emit(
                "zero_failed", f"surface zeroing got {len(got)} of {n} readings in {timeout_s:g} s",
                "warning",
            )
            return None
        p = sum(got) / len(got)
        self._surface = p
        self.events.emit("zeroed", f"surface pressure set to {p:.1f} Pa", "info", surface_pressure_pa=p)
        return p

    # ------------------------------------------------------------ input

    def _handle(self, data: bytes) -> None:
        for item in self._parser.feed(data):
            now = self._clock()
            if isinstance(item, AdcIssue):
                self.events.throttled(item.kind, item.detail)
                continue
            self._silence.received(now)
            self._current(item, now)
        self._implausible.flush(self._clock())

    def _current(self, current_ma: float, now: float) -> None:
        cfg = self.config
        broken = not cfg.loop_min_ma <= current_ma <= cfg.loop_max_ma
        self.events.condition(
            "broken_loop", broken,
            f"loop current {current_ma:.3f} mA outside [{cfg.loop_min_ma}, {cfg.loop_max_ma}] mA"
            if broken else f"loop current back in range ({current_ma:.3f} mA)",
            "error", current_ma=current_ma,
        )
        if broken:
            return
        p = current_to_pressure(current_ma, cfg.p_min_pa, cfg.span_pa)
        depth = pressure_to_depth(p, self._surface, cfg.rho)
        problem = loop_current_problem(current_ma, depth)
        if problem:
            self._implausible.note(1, problem, now)
            return
        self._implausible.passed()
        with self._lock:
            if self._zero_samples is not None and len(self._zero_samples) < self._zero_target:
                self._zero_samples.append(p)
                if len(self._zero_samples) >= self._zero_target:
                    self._zero_done.set()
        reading = DepthReading(t=now, depth_m=depth, pressure_pa=p)
        self._deliver(reading)
