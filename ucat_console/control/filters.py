"""Small streaming filters: a running median (DVL velocity, depth) and a first-order low-pass."""

from __future__ import annotations

import math

import numpy as np
from numba.extending import register_jitable

from ucat_console.control.argcheck import finite, in_range


# layout of a median filter's numbers (a slice of a float array): the count, the next
# slot, the ring of the last ``window`` samples, and room to sort them
MED_N = 0
MED_NEXT = 1
MED_RING = 2


@register_jitable
def median_size(window: int) -> int:
    """Numbers a median filter of ``window`` samples takes (:func:`median_push`)."""
    return MED_RING + 2 * window


@register_jitable
def median_clear(buf: np.ndarray, base: int) -> None:
    buf[base + MED_N] = 0.0
    buf[base + MED_NEXT] = 0.0


@register_jitable
def median_value(buf: np.ndarray, base: int, window: int) -> float:
    """Median of the filter at ``buf[base:]`` (NaN before the first sample): the samples
    sorted (insertion sort in the filter's own room), the middle one or the mean of the
    middle pair."""
    n = int(buf[base + MED_N])
    if n == 0:
        return math.nan
    ring = base + MED_RING
    room = ring + window
    for i in range(n):
        x = buf[ring + i]
        k = i
        while k > 0 and buf[room + k - 1] > x:
            buf[room + k] = buf[room + k - 1]
            k -= 1
        buf[room + k] = x
    mid = n // 2
    if n % 2:
        return buf[room + mid]
    return 0.5 * (buf[room + mid - 1] + buf[room + mid])


@register_jitable
def median_push(buf: np.ndarray, base: int, window: int, x: float) -> None:
    """Add sample ``x`` to the filter at ``buf[base:]`` (the oldest leaves a full window)."""
    i = int(buf[base + MED_NEXT])
    buf[base + MED_RING + i] = x
    buf[base + MED_NEXT] = float((i + 1) % window)
    n = buf[base + MED_N]
    if n < window:
        buf[base + MED_N] = n + 1.0


class MedianFilter:
    """Median of the last ``window`` samples (all samples while fewer have arrived). Its
    numbers are a slice of ``buf`` from ``base`` (``median_size(window)`` long): its own, or
    those of a table another owner shares (the closed loop's compiled core)."""

    def __init__(self, window: int, buf: np.ndarray | None = None, base: int = 0) -> None:
        if isinstance(window, bool) or not isinstance(window, int) or window < 1:
            raise ValueError(f"window: {window!r} is out of range; allowed: an integer >= 1")
        self.window = window
        self.buf = np.zeros(median_size(window)) if buf is None else buf
        self.base = base
        self.reset()

    def reset(self) -> None:
        median_clear(self.buf, self.base)

    def __len__(self) -> int:
        return int(self.buf[self.base + MED_N])

    @property
    def value(self) -> float | None:
        """Current median, or None before the first sample."""
        v = median_value(self.buf, self.base, self.window)
        return None if math.isnan(v) else float(v)

    def push(self, x: float) -> float:
        """Add a sample and return the median."""
        median_push(self.buf, self.base, self.window, finite("x", x))
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
