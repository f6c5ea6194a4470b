"""Opening a CAN bus from configuration, and how far its reader has heard.

The interface is a python-can backend name picked by a config string (``"socketcan"`` on
the robot, ``"virtual"`` in simulation and tests); nothing above this module knows which one
runs. User-level python-can configuration files are ignored so that only the project's own
configuration decides what is opened.

:class:`HeardBus` wraps an open bus for a reader (python-can's ``Notifier`` thread) and
keeps ``heard_until``: the time up to which every frame that reached the bus has been read
and handed on. A frame's arrival is its python-can timestamp (the kernel's receive time on
``socketcan``, the sender's time on ``virtual``), so a reader held back by a busy machine
reads frames that arrived long ago, and ``heard_until`` stays at their arrival: what sat
unread in the queue has not been heard yet, and is not missing.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable

import can
from can.interfaces import VALID_INTERFACES

logger = logging.getLogger(__name__)

#: python-can backend names accepted as ``interface``
INTERFACES: tuple[str, ...] = tuple(sorted(VALID_INTERFACES))
#: CAN bit rates of CiA 301 (bit/s); the EPOS2 ships at 1 Mbit/s
BITRATES: tuple[int, ...] = (
    10_000, 20_000, 50_000, 125_000, 250_000, 500_000, 800_000, 1_000_000
)


class CanBusError(RuntimeError):
    """The bus could not be opened (missing adapter, permissions, driver not installed)."""


def open_bus(
    interface: str, channel: str, bitrate: int | None = None, *, key: str = "interface",
    stamped: bool = False,
) -> can.BusABC:
    """Open ``can.Bus(interface=..., channel=..., bitrate=..., ignore_config=True)``.

    ``stamped``: frames sent keep the timestamp their sender gave them (python-can's
    ``preserve_timestamps`` of the ``virtual`` interface; an emulated device stamps each
    frame with the time the device sends it); other interfaces stamp frames themselves.

    Raises ValueError naming ``key`` for an unknown interface or bit rate, and CanBusError
    when the backend cannot open the channel.
    """
    if interface not in VALID_INTERFACES:
        raise ValueError(
            f"{key}: {interface!r} is not a CAN interface python-can knows; "
            f"known: {', '.join(INTERFACES)}"
        )
    if bitrate is not None and bitrate not in BITRATES:
        prefix = key.rpartition(".")[0]
        bitrate_key = f"{prefix}.bitrate" if prefix else "bitrate"
        raise ValueError(
            f"{bitrate_key}: {bitrate!r} is not a CAN bit rate; allowed: "
            f"{', '.join(str(b) for b in BITRATES)}"
        )
    kwargs: dict[str, object] = {
        "interface": interface,
        "channel": channel,
        "ignore_config": True,
    }
    if bitrate is not None:
        kwargs["bitrate"] = bitrate
    if stamped and interface == "virtual":
        kwargs["preserve_timestamps"] = True
    try:
        bus = can.Bus(**kwargs)
    except (can.CanError, OSError, ImportError, NotImplementedError) as e:
        raise CanBusError(f"cannot open CAN {interface} channel {channel!r}: {e}") from e
    logger.info("opened CAN %s channel %r", interface, channel)
    return bus


#: s; a frame stamped further back than this, or in the future, is taken to have arrived
#: when it was read (a stamp from another clock, or none)
MAX_FRAME_AGE = 5.0


def arrival_time(stamp: float, now: float, wall: float | None = None) -> float:
    """When a frame stamped ``stamp`` (python-can's timestamp: seconds of ``time.time()``)
    arrived, on the clock that reads ``now`` (``wall``: ``time.time()`` now)."""
    age = (time.time() if wall is None else wall) - stamp
    if not 0.0 <= age <= MAX_FRAME_AGE:
        age = 0.0
    return now - age


class HeardBus(can.BusABC):
    """A bus whose reader's progress is kept: :attr:`heard_until` (on ``clock``).

    Every frame that arrived up to ``heard_until`` has been read and handed to the
    listeners. Frames are read in their order of arrival, so when the reader comes back for
    the next frame, everything that arrived up to the one it handed on has been handed on;
    a read that finds nothing at all means nothing arrived up to its start, as far as the
    devices on the bus had come then: ``bus_time()`` (the time the emulated devices of the
    simulated rig have reached: they run in this process and are held back with it), or
    the present on a real bus.
    """

    def __init__(self, inner: can.BusABC, clock: Callable[[], float] = time.monotonic,
                 bus_time: Callable[[], float] | None = None) -> None:
        self._inner = inner
        self._clock = clock
        self._bus_time = bus_time
        self._read: float | None = None  # arrival of the frame read last, not yet handed on
        self.heard_until = -math.inf
        self.channel_info = inner.channel_info
        super().__init__(channel=inner.channel_info)

    def _heard(self, t: float) -> None:
        if t > self.heard_until:
            self.heard_until = t

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if self._read is not None:  # the reader handed the last frame on and is back
            self._heard(self._read)
            self._read = None
        before = self._bus_time() if self._bus_time is not None else math.inf
        msg = self._inner.recv(timeout)
        now = self._clock()
        if msg is None:
            self._heard(min(now, before))
        else:
            self._read = arrival_time(msg.timestamp, now)
        return msg, True

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self._inner.send(msg, timeout)

    def shutdown(self) -> None:
        try:
            self._inner.shutdown()
        finally:
            super().shutdown()
