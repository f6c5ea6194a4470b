"""Argument checks for the functional core: bad numbers raise ValueError naming the argument.

Every public function of ``control/`` that takes a number from outside (a device reading, a
setpoint, a config value passed by hand) checks it here, so a NaN or an impossible value is
reported where it enters instead of turning silently into a wrong force.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray


def finite(name: str, value: float) -> float:
    """``value`` as a float; ValueError naming ``name`` when it is not a finite number."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a finite number, got {value!r}") from None
    if not math.isfinite(x):
        raise ValueError(f"{name}: {value!r} is not finite; allowed: a finite number")
    return x


def in_range(
    name: str,
    value: float,
    lo: float | None = None,
    hi: float | None = None,
    *,
    lo_open: bool = False,
    unit: str = "",
) -> float:
    """Finite ``value`` with ``lo <= value <= hi`` (``lo < value`` when ``lo_open``)."""
    x = finite(name, value)
    bad = (lo is not None and (x <= lo if lo_open else x < lo)) or (hi is not None and x > hi)
    if bad:
        left = "(" if lo_open else "["
        lo_s = "-inf" if lo is None else repr(lo)
        hi_s = "inf" if hi is None else repr(hi)
        u = f" {unit}" if unit else ""
        raise ValueError(f"{name}: {value!r} is out of range; allowed: {left}{lo_s}, {hi_s}]{u}")
    return x


def finite_array(name: str, values: ArrayLike, *, ndim: int | None = None) -> NDArray[np.float64]:
    """A float array of ``values``; ValueError naming ``name`` when empty or not finite."""
    try:
        a = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected an array of numbers") from None
    if ndim is not None and a.ndim != ndim:
        raise ValueError(f"{name}: expected a {ndim}-D array, got shape {a.shape}")
    if a.size == 0:
        raise ValueError(f"{name}: empty; at least one value is needed")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: contains non-finite values; allowed: finite numbers")
    return a
