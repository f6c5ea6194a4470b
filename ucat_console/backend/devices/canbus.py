"""Opening a CAN bus from configuration.

The interface is a python-can backend name picked by a config string (``"socketcan"`` on
the robot, ``"virtual"`` in simulation and tests); nothing above this module knows which one
runs. User-level python-can configuration files are ignored so that only the project's own
configuration decides what is opened.
"""

from __future__ import annotations

import logging

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
    interface: str, channel: str, bitrate: int | None = None, *, key: str = "interface"
) -> can.BusABC:
    """Open ``can.Bus(interface=..., channel=..., bitrate=..., ignore_config=True)``.

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
    try:
        bus = can.Bus(**kwargs)
    except (can.CanError, OSError, ImportError, NotImplementedError) as e:
        raise CanBusError(f"cannot open CAN {interface} channel {channel!r}: {e}") from e
    logger.info("opened CAN %s channel %r", interface, channel)
    return bus
