"""The reader thread the serial drivers (IMU, pressure ADC) share.

:class:`SerialReader` opens the configured port, runs a reader thread that hands every
chunk of bytes to the driver's ``_handle``, reports a failed port (``port_error``),
reopens it every ``reopen_interval_s`` (``reconnected``), watches for ``silence`` (after
each read, as far as heard: ``reporting.SilenceWatch``; ``device_time`` for an emulator) and
delivers readings to the driver's callback without letting a failing callback stop the
thread. A driver supplies a parser with ``reset()``, ``_handle`` and its own events.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Callable, Generic, Protocol, TypeVar

import serial

from ucat_console.backend.devices.background import BackgroundThread
from ucat_console.backend.devices.reporting import EventReporter, SilenceWatch
from ucat_console.backend.devices.serial_link import SERIAL_ERRORS, open_serial
from ucat_console.telemetry.events import EventSink

R = TypeVar("R")


class SerialPortConfig(Protocol):
    """The configuration fields a :class:`SerialReader` reads."""

    @property
    def port(self) -> str: ...
    @property
    def baud(self) -> int: ...
    @property
    def read_timeout_s(self) -> float: ...
    @property
    def reopen_interval_s(self) -> float: ...
    @property
    def silence_timeout_s(self) -> float: ...


class _Resettable(Protocol):
    def reset(self) -> None: ...


class SerialReader(BackgroundThread, Generic[R]):
    """Port, reader thread, reconnection and silence of a serial driver delivering ``R``."""

    config: SerialPortConfig
    _parser: _Resettable

    def __init__(
        self,
        config: SerialPortConfig,
        source: str,
        on_reading: Callable[[R], None],
        on_event: EventSink,
        clock: Callable[[], float] = time.monotonic,
        silence_nouns: tuple[str, str] = ("message", "messages"),
        device_time: Callable[[], float] | None = None,
    ) -> None:
        super().__init__()
        self.config = config
        self._on_reading = on_reading
        self._clock = clock
        self._source = source
        self._log = logging.getLogger(type(self).__module__)
        self.events = EventReporter(source, on_event, clock)
        self._silence = SilenceWatch(self.events, clock, config.silence_timeout_s, *silence_nouns,
                                     device_time=device_time)
        self._serial: serial.Serial | None = None
        self._serial_lock = threading.Lock()  # writes and open/close
        self.readings = 0

    # ------------------------------------------------------------ lifecycle

    def start(self) -> bool:
        """Open the port and start the reader; False (and an Event) when the port fails.

        The reader keeps trying to open the port, so a late device is picked up.
        """
        if self._thread is not None:
            raise RuntimeError(f"{type(self).__name__} already started")
        opened = self._open()
        self._silence.reset()
        self._spawn(f"{self._source}-reader")
        return opened

    # ------------------------------------------------------------ port

    def _open(self) -> bool:
        cfg = self.config
        try:
            ser = open_serial(cfg.port, cfg.baud, cfg.read_timeout_s)
        except SERIAL_ERRORS as e:
            self.events.throttled("port_error", f"cannot open {cfg.port}: {e}", "error", port=cfg.port)
            return False
        with self._serial_lock:
            self._serial = ser
        self._parser.reset()
        return True

    def _close(self) -> None:
        with self._serial_lock:
            ser, self._serial = self._serial, None
        if ser is not None:
            try:
                ser.close()
            except SERIAL_ERRORS:
                pass

    def _reopened(self) -> None:
        """Called by the reader thread after it reopened a lost port."""

    # ------------------------------------------------------------ reader

    def _run(self) -> None:
        next_open = 0.0
        while not self._stop.is_set():
            with self._serial_lock:
                ser = self._serial
            if ser is None:
                now = self._clock()
                if now >= next_open:
                    next_open = now + self.config.reopen_interval_s
                    if self._open():
                        self.events.emit("reconnected", f"reopened {self.config.port}", "info")
                        self._reopened()
                        continue
                self._stop.wait(min(0.05, self.config.reopen_interval_s))
                self._silence.reading()
                self._silence.check()
                continue
            self._silence.reading()
            try:
                data = ser.read(max(1, ser.in_waiting))
            except SERIAL_ERRORS as e:
                self.events.emit("port_error", f"read from {self.config.port} failed: {e}", "error")
                self._close()
                next_open = self._clock() + self.config.reopen_interval_s
                continue
            if data:
                try:
                    self._handle(data)
                except Exception:  # never let a surprise stop the reader
                    self._log.exception("%s: unexpected error while handling input", self._source)
                    self.events.throttled("internal_error", "unexpected error handling input", "error")
            self._silence.check()

    def _handle(self, data: bytes) -> None:
        raise NotImplementedError

    def _deliver(self, reading: R) -> None:
        """Count a reading and hand it to the callback (a failing callback is logged)."""
        self.readings += 1
        try:
            self._on_reading(reading)
        except Exception:
            self._log.exception("%s: reading callback failed", self._source)
