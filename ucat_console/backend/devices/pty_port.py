"""The device end of a pseudo-terminal pair, used by the serial emulators.

The driver opens :attr:`PtyPort.path` with pyserial exactly as it opens ``/dev/ttyACM0``
on the robot. The emulator keeps the slave end open (in raw mode) so the pair survives the
driver closing and reopening the port. Writes never block: when nobody reads and the
pty's buffer is full the bytes are lost, as on a real serial line.
"""

from __future__ import annotations

import errno
import os
import select
import tty


class PtyPort:
    """Master side of a raw pty pair; :attr:`path` is the serial port for the driver."""

    def __init__(self) -> None:
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        os.set_blocking(self._master, False)
        self.path: str = os.ttyname(self._slave)
        self._closed = False

    def fileno(self) -> int:
        return self._master

    def wait_readable(self, timeout: float) -> bool:
        if self._closed:
            return False
        r, _, _ = select.select([self._master], [], [], max(0.0, timeout))
        return bool(r)

    def read(self, n: int = 4096) -> bytes:
        """Bytes written by the driver (empty when there are none)."""
        try:
            return os.read(self._master, n)
        except (BlockingIOError, InterruptedError):
            return b""
        except OSError as e:
            if e.errno == errno.EIO:  # no reader on the slave side right now
                return b""
            raise

    def write(self, data: bytes) -> int:
        """Write what fits; returns the number of bytes accepted."""
        if self._closed:
            return 0
        view = memoryview(data)
        done = 0
        while done < len(view):
            try:
                done += os.write(self._master, view[done:])
            except (BlockingIOError, InterruptedError):
                break
            except OSError as e:
                if e.errno == errno.EIO:
                    break
                raise
        return done

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        for fd in (self._master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass
