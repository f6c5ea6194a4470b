"""The pressure ADC on a pty: lines ``I=<mA>mA\\r\\n`` for a Gems 3101P at a given depth.

``source(t)`` (``t``: seconds since :meth:`start`) returns the depth in m below the
surface, or None (no line now). The current follows the transducer scaling of a
:class:`PressureConfig` (the same conversion functions the driver uses), plus a sensor
zero offset ``surface_offset_pa`` so the driver's surface zeroing has something to remove.

Faults: ``silence`` sends nothing; ``corrupt`` sends garbled lines; ``invalid`` sends a
broken-loop current (0 mA); ``implausible`` sends well-formed lines of a current the
transducer never gives for a depth (default 20.4 mA, beyond its span), or of the depth a
jump deeper than it is (:meth:`PressureEmulator.set_implausible`); ``slow`` delays every
line by ``slow_delay_s``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

from ucat_console.backend.devices.emulator_base import DelayedOutput, EmulatorThread, next_tick
from ucat_console.backend.devices.faults import Fault, FaultSettings, numbers
from ucat_console.backend.devices.pressure import PressureConfig, format_adc_line
from ucat_console.backend.devices.pty_port import PtyPort
from ucat_console.robot.units import depth_to_pressure, pressure_to_current
from ucat_console.typedconf import Config, param

BROKEN_LOOP_MA = 0.0
#: what the ``implausible`` fault sends unless told otherwise: above the 20 mA span
IMPLAUSIBLE_MA = 20.4


@dataclass(frozen=True)
class PressureEmulatorConfig(Config):
    """Line rate and sensor offset of the emulated ADC."""

    rate_hz: float = param(20.0, lo=0.5, hi=500.0, unit="Hz", doc="ADC lines per second")
    surface_offset_pa: float = param(
        0.0, lo=-1.0e5, hi=1.0e5, unit="Pa", doc="gauge pressure the sensor reads at the surface"
    )
    faults: FaultSettings = FaultSettings()


class PressureEmulator(EmulatorThread):
    """Serial ADC emulator over a pty; the driver opens :attr:`port`."""

    _name = "pressure emulator"

    def __init__(
        self,
        source: Callable[[float], float | None],
        config: PressureEmulatorConfig = PressureEmulatorConfig(),
        transducer: PressureConfig = PressureConfig(),
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        super().__init__(clock, config.faults)
        self.config = config
        self.transducer = transducer
        self._source = source
        self._pty = PtyPort()
        self._delayed: DelayedOutput[bytes] = DelayedOutput()  # lines held back by 'slow'
        self._period = 1.0 / config.rate_hz
        self._next_line = 0.0
        self._lines = 0
        self._implausible: tuple[float | None, float] = (IMPLAUSIBLE_MA, 0.0)  # (current, jump)

    @property
    def port(self) -> str:
        return self._pty.path

    def current_for_depth(self, depth_m: float) -> float:
        """The loop current (mA) the transducer drives at ``depth_m``."""
        tr = self.transducer
        p = depth_to_pressure(depth_m, self.config.surface_offset_pa, tr.rho)
        return pressure_to_current(p, tr.p_min_pa, tr.span_pa)

    def set_implausible(self, current_ma: float | None = None, jump_m: float | None = None) -> None:
        """What the ``implausible`` fault sends: lines of ``current_ma`` (mA, finite), or
        the depth ``jump_m`` (m) deeper than it is; neither: 20.4 mA."""
        if current_ma is not None and jump_m is not None:
            raise ValueError("current_ma/jump_m: give one of them, not both")
        if jump_m is not None:
            self._implausible = (None, numbers("jump_m", (jump_m,), 1)[0])
        else:
            current = IMPLAUSIBLE_MA if current_ma is None else numbers("current_ma", (current_ma,), 1)[0]
            self._implausible = (current, 0.0)

    def _close(self) -> None:
        self._pty.close()

    def _begin(self, now: float) -> None:
        self._period = 1.0 / self.config.rate_hz
        self._next_line = now

    def _step(self) -> None:
        now = self._clock()
        if now >= self._next_line:
            self._sample(now)
            self._next_line = next_tick(self._next_line, self._period, now)
        for line in self._delayed.pop_due(now):
            self._write(line)
        if self._pty.wait_readable(0.0):
            self._pty.read()  # the ADC ignores input
        wake = min(self._next_line, self._delayed.next_due())
        self._stop.wait(max(0.0, min(0.05, wake - self._clock())))

    def _sample(self, now: float) -> None:
        depth = self._source(now - self._t0)
        if depth is None:
            return
        if self.faults.active(Fault.INVALID):
            current = BROKEN_LOOP_MA
        elif self.faults.active(Fault.IMPLAUSIBLE):
            fixed, jump = self._implausible
            current = self.current_for_depth(depth + jump) if fixed is None else fixed
        else:
            current = self.current_for_depth(depth)
        line = format_adc_line(current)
        self._lines += 1
        if self.faults.active(Fault.CORRUPT) and self._lines % self.config.faults.corrupt_every == 0:
            line = b"I=1\xff2.3#A" + line[len(line) // 2 :]
        if not self._held_back(now, line, self._delayed):
            self._write(line)

    def _write(self, line: bytes) -> None:
        if self.faults.active(Fault.SILENCE):
            return
        self._pty.write(line)
