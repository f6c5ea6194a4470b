"""Line framing for text protocols (DVL JSON over TCP, the pressure ADC over serial).

Lines end with ``\\n`` or ``\\r\\n``; a line may arrive in any number of pieces. A line
longer than the limit is dropped up to its end and reported once as :class:`Overlong`.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Overlong:
    """A line exceeded the length limit and was dropped (``nbytes`` dropped so far)."""

    nbytes: int


class LineSplitter:
    """Incremental splitter: ``feed(bytes)`` returns complete lines without terminators."""

    def __init__(self, max_line_bytes: int = 65536) -> None:
        if max_line_bytes < 1:
            raise ValueError(f"max_line_bytes: {max_line_bytes!r} must be at least 1")
        self._max = max_line_bytes
        self._buf = bytearray()
        self._discarding = False

    def reset(self) -> None:
        self._buf.clear()
        self._discarding = False

    @property
    def pending(self) -> int:
        """Bytes of an incomplete line held back."""
        return len(self._buf)

    def feed(self, data: bytes) -> list[bytes | Overlong]:
        out: list[bytes | Overlong] = []
        start = 0
        n = len(data)
        while start < n:
            nl = data.find(b"\n", start)
            end = n if nl < 0 else nl
            chunk = data[start:end]
            if self._discarding:
                pass
            else:
                self._buf += chunk
                if len(self._buf) > self._max:
                    out.append(Overlong(len(self._buf)))
                    self._buf.clear()
                    self._discarding = True
            if nl < 0:
                break
            # end of line
            if not self._discarding:
                line = bytes(self._buf)
                if line.endswith(b"\r"):
                    line = line[:-1]
                if line:
                    out.append(line)
            self._buf.clear()
            self._discarding = False
            start = nl + 1
        return out
