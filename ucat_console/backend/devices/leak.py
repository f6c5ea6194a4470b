"""The leak detector: a digital input on the robot's computer, and its emulator.

:class:`LeakInput` reads a GPIO's value file (the sysfs ``/sys/class/gpio/gpioN/value``,
or any file a gpiod-style exporter keeps at "0" or "1") each time it is asked
(:meth:`LeakInput.reading`: the console's sensor poller asks every ``period_s``, the leak
being the first registered sensor, ``backend.sensors``), returns a :class:`LeakReading` and
reports, as Events of source ``leak``:

* ``water`` (error): the input is at its active level (``active_high``): water at the probe;
* ``dry`` (info): at the other level, at the first read and after ``water`` or ``unreadable``;
* ``unreadable`` (error; once until a read succeeds again): the file cannot be read, or
  holds something else than 0 or 1. An unreadable input is not a dry one: it is reported
  and shown, though it does not count as water.

:class:`LeakEmulator` is a value file of its own (in a temporary folder) that a simulated
robot's leak input reads: :meth:`LeakEmulator.set` writes the level that means water, or
the other one.
"""

from __future__ import annotations

import logging
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

from ucat_console.robot.fields import Doc
from ucat_console.robot.readings import Time
from ucat_console.telemetry.events import Event, EventSink
from ucat_console.typedconf import Config, param

log = logging.getLogger(__name__)

SOURCE = "leak"


@dataclass(frozen=True)
class LeakConfig(Config):
    """The leak detector's digital input."""

    path: str = param(
        "", doc="the input's value file, e.g. /sys/class/gpio/gpio17/value (empty: no leak detector; "
        "a simulated robot then reads an emulated one)",
    )
    active_high: bool = param(True, doc="the level that means water: 1 (true) or 0 (false)")
    period_s: float = param(0.05, lo=0.005, hi=5.0, unit="s", doc="how often the input is read")


@dataclass(frozen=True)
class LeakReading:
    """The leak detector's input as read."""

    t: Time
    water: Annotated[bool, Doc("water at the probe: the input at its active level (the last level read, "
                               "held while the input is unreadable)")]
    readable: Annotated[bool, Doc("the input was read (false: the file cannot be read or holds something "
                                  "else than 0 or 1)")]


class LeakInput:
    """Reads the input when asked; see the module docstring. ``clock()`` stamps the events
    (the loop's time)."""

    def __init__(self, cfg: LeakConfig, path: str, on_event: EventSink, clock) -> None:
        self.cfg = cfg
        self.path = Path(path)
        self._on_event = on_event
        self._clock = clock
        self.wet: bool | None = None  # None: not read yet, or unreadable
        self._water = False  # the last level read
        self._unreadable = False

    def read(self) -> None:
        """Read the input once and report a change."""
        try:
            text = self.path.read_text().strip()
            if text not in ("0", "1"):
                raise ValueError(f"{text[:20]!r} is not 0 or 1")
        except (OSError, ValueError) as e:
            self.wet = None
            if not self._unreadable:
                self._unreadable = True
                self._emit("unreadable", f"leak detector {self.path} unreadable: {e}", "error")
            return
        wet = (text == "1") == self.cfg.active_high
        was, self.wet, self._water, self._unreadable = self.wet, wet, wet, False
        if wet and was is not True:
            self._emit("water", f"leak detector {self.path}: water", "error")
        elif not wet and was is not False:  # the first read, or after water or an unreadable spell
            self._emit("dry", f"leak detector {self.path}: dry", "info")

    def _emit(self, code: str, message: str, level: str) -> None:
        try:
            self._on_event(Event(t=self._clock(), source=SOURCE, code=code, message=message, level=level,
                                 data={"path": str(self.path)}))
        except Exception:
            log.exception("leak event sink failed")

    def reading(self, t: float) -> LeakReading:
        """Read the input once (:meth:`read`) and return it as a reading at time ``t``."""
        self.read()
        return LeakReading(t, self._water, not self._unreadable)


class LeakEmulator:
    """A GPIO value file in a temporary folder, dry until :meth:`set`."""

    def __init__(self, active_high: bool = True) -> None:
        self._dir = tempfile.mkdtemp(prefix="ucat-leak-")
        self.path = Path(self._dir) / "value"
        self.active_high = active_high
        self.set(False)

    def set(self, wet: bool) -> None:
        """Water at the probe (``wet``) or not."""
        tmp = self.path.with_suffix(".tmp")
        tmp.write_text("1\n" if wet == self.active_high else "0\n")
        tmp.replace(self.path)  # a reader never sees a half-written file

    def close(self) -> None:
        shutil.rmtree(self._dir, ignore_errors=True)
