"""What the serial drivers share: the line rates a port may be set to, and opening one."""

from __future__ import annotations

import serial

#: standard line rates accepted in configuration
BAUD_RATES = (9600, 19200, 38400, 57600, 115200, 230400, 460800, 921600)

#: what pyserial raises for a port that is missing, gone or misconfigured
SERIAL_ERRORS = (serial.SerialException, OSError, ValueError, TypeError)


def open_serial(port: str, baud: int, timeout_s: float) -> serial.Serial:
    """Open ``port`` (a device path such as ``/dev/ttyACM0`` or a pty) raw, 8N1."""
    return serial.Serial(port, baud, timeout=timeout_s)
