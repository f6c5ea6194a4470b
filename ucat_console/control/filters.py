"""Small streaming filters: a running median (DVL velocity, depth) and a first-order low-pass."""

from __future__ import annotations

import math
from collections import deque

from ucat_console.control.argcheck import finite, in_range


class MedianFilter:
    """Median of the last ``window`` samples (all samples while fewer have arrived)."""

    def __init__(self, window: int) -> None:
        if isinstance(window, bool) or not isinstance(window, int) or window < 1:
            raise ValueError(f"window: {window!r} is out of range; allowed: an integer >= 1")
        self.window = window
        self._buf: deque[float] = deque(maxlen=window)

    def reset(self) -> None:
        self._buf.clear()

    def __len__(self) -> int:
        return len(self._buf)

    @property
    def value(self) -> float | None:
        """Current median, or None before the first sample."""
        n = len(self._buf)
        if n == 0:
            return None
        s = sorted(self._buf)
        mid = n // 2
        return s[mid] if n % 2 else 0.5 * (s[mid - 1] + s[mid])

    def push(self, x: float) -> float:
        """Add a sample and return the median."""
        self._buf.append(finite("x", x))
        value = self.value
        assert value is not None
        return value


class LowPass:
    """First-order low-pass with time constant ``tau`` (s), exact for piecewise-constant input.

    ``y <- y + (1 - exp(-dt / tau)) (x - y)``; ``tau = 0`` passes the input through. The
    first sample initialises the output.
    """

    def __init__(self, tau: float) -> None:
        self.tau = in_range("tau", tau, 0.0, unit="s")
        self.reset()

    def reset(self) -> None:
        self.value: float | None = None
        self._t: float | None = None

    def update(self, x: float, t: float) -> float:
        x = finite("x", x)
        t = finite("t", t)
        if self.value is None or self._t is None:
            self.value, self._t = x, t
            return x
        dt = t - self._t
        if dt < 0.0:
            raise ValueError(f"t: {t!r} is earlier than the last sample at {self._t!r}")
        self._t = t
        if self.tau == 0.0:
            self.value = x
        else:
            self.value += (1.0 - math.exp(-dt / self.tau)) * (x - self.value)
        return self.value
