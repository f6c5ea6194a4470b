"""The leak detector: a digital input on the robot's computer, and its emulator.

:class:`LeakInput` reads a GPIO's value file (the sysfs ``/sys/class/gpio/gpioN/value``,
or any file a gpiod-style exporter keeps at "0" or "1") every ``period_s`` in a thread of
its own and reports, as Events of source ``leak``:

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
import threading
from dataclasses import dataclass
from pathlib import Path

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


class LeakInput:
    """Reads the input in a thread; see the module docstring. ``clock()`` stamps the events
    (the loop's time)."""

    def __init__(self, cfg: LeakConfig, path: str, on_event: EventSink, clock) -> None:
        self.cfg = cfg
        self.path = Path(path)
        self._on_event = on_event
        self._clock = clock
        self.wet: bool | None = None  # None: not read yet, or unreadable
        self._unreadable = False
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

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
        was, self.wet, self._unreadable = self.wet, wet, False
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

    def start(self) -> None:
        self.read()
        self._thread = threading.Thread(target=self._run, name="leak-input", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(self.cfg.period_s):
            self.read()

    def stop(self) -> None:
        self._stop.set()
        t, self._thread = self._thread, None
        if t is not None:
            t.join(timeout=2.0)


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
