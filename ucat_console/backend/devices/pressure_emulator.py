"""The pressure ADC on a pty: lines ``I=<mA>mA\\r\\n`` for a Gems 3101P at a given depth.

``source(t)`` (``t``: seconds since :meth:`start`) returns the depth in m below the
surface, or None (no line now). The current follows the transducer scaling of a
:class:`PressureConfig` (the same conversion functions the driver uses), plus a sensor
zero offset ``surface_offset_pa`` so the driver's surface zeroing has something to remove.

Faults: ``silence`` sends nothing; ``corrupt`` sends garbled lines; ``invalid`` sends a
broken-loop current (0 mA); ``slow`` delays every line by ``slow_delay_s``.
"""

from __future__ import annotations

import collections
import logging
import threading
import time
from dataclasses import dataclass
from typing import Callable

from ucat_console.backend.devices.faults import Fault, FaultInjectable, FaultSet, FaultSettings
from ucat_console.backend.devices.pressure import (
    PressureConfig,
    depth_to_pressure,
    format_adc_line,
    pressure_to_current,
)
from ucat_console.backend.devices.pty_port import PtyPort
from ucat_console.control.params import _Config
from ucat_console.typedconf import param

log = logging.getLogger(__name__)

BROKEN_LOOP_MA = 0.0


@dataclass(frozen=True)
class PressureEmulatorConfig(_Config):
    """Line rate and sensor offset of the emulated ADC."""

    rate_hz: float = param(20.0, lo=0.5, hi=500.0, unit="Hz", doc="ADC lines per second")
    surface_offset_pa: float = param(
        0.0, lo=-1.0e5, hi=1.0e5, unit="Pa", doc="gauge pressure the sensor reads at the surface"
    )
    faults: FaultSettings = FaultSettings()


class PressureEmulator(FaultInjectable):
    """Serial ADC emulator over a pty; the driver opens :attr:`port`."""

    def __init__(
        self,
        source: Callable[[float], float | None],
        config: PressureEmulatorConfig = PressureEmulatorConfig(),
        transducer: PressureConfig = PressureConfig(),
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.config = config
        self.transducer = transducer
        self._source = source
        self._clock = clock
        self.faults = FaultSet(clock)
        self._pty = PtyPort()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._t0 = 0.0
        self._delayed: collections.deque[tuple[float, bytes]] = collections.deque()
        self._lines = 0

    @property
    def port(self) -> str:
        return self._pty.path

    def current_for_depth(self, depth_m: float) -> float:
        """The loop current (mA) the transducer drives at ``depth_m``."""
        tr = self.transducer
        p = depth_to_pressure(depth_m, self.config.surface_offset_pa, tr.rho)
        return pressure_to_current(p, tr.p_min_pa, tr.span_pa)

    def start(self) -> "PressureEmulator":
        if self._thread is not None:
            return self
        self._t0 = self._clock()
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="pressure-emulator", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        self._pty.close()

    def __enter__(self) -> "PressureEmulator":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _run(self) -> None:
        period = 1.0 / self.config.rate_hz
        next_line = self._clock()
        while not self._stop.is_set():
            try:
                now = self._clock()
                if now >= next_line:
                    self._sample(now)
                    next_line = max(next_line + period, now - period)
                while self._delayed and self._delayed[0][0] <= now:
                    self._write(self._delayed.popleft()[1])
                if self._pty.wait_readable(0.0):
                    self._pty.read()  # the ADC ignores input
                wake = next_line if not self._delayed else min(next_line, self._delayed[0][0])
                self._stop.wait(max(0.0, min(0.05, wake - self._clock())))
            except OSError as e:
                if self._stop.is_set():
                    break
                log.warning("pressure emulator: pty error %s", e)
                self._stop.wait(0.05)
            except Exception:
                log.exception("pressure emulator: unexpected error")
                self._stop.wait(0.05)

    def _sample(self, now: float) -> None:
        depth = self._source(now - self._t0)
        if depth is None:
            return
        current = BROKEN_LOOP_MA if self.faults.active(Fault.INVALID) else self.current_for_depth(depth)
        line = format_adc_line(current)
        self._lines += 1
        if self.faults.active(Fault.CORRUPT) and self._lines % self.config.faults.corrupt_every == 0:
            line = b"I=1\xff2.3#A" + line[len(line) // 2 :]
        if self.faults.active(Fault.SLOW):
            self._delayed.append((now + self.config.faults.slow_delay_s, line))
            return
        self._write(line)

    def _write(self, line: bytes) -> None:
        if self.faults.active(Fault.SILENCE):
            return
        self._pty.write(line)
