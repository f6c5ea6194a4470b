"""Fault injection shared by the device emulators.

Every emulator (IMU, DVL, pressure ADC) can be told, on command, to misbehave the way a
real device does: go silent, corrupt its bytes or checksums, send invalid data, send values
the device could never measure, or answer slowly. What each fault means for one device is
written in that emulator's docstring:

===========  ==========================================================================
silence      nothing is sent and commands are not answered (device unplugged or hung)
corrupt      checksums / framing broken and garbage bytes inserted (noisy line)
invalid      well-formed messages that carry invalid data (NaN samples, lost bottom lock,
             broken current loop)
implausible  well-formed, finite messages whose values are impossible (a saturated
             current, 10^6 g, a zero quaternion, a jump in depth), set by the
             emulator's ``set_implausible``
slow         replies to commands (and, for streaming-only devices, samples) are delayed
===========  ==========================================================================

An emulator holds a :class:`FaultSet` and exposes ``inject(fault, duration=None)`` and
``clear(fault=None)`` through :class:`FaultInjectable`.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass
from enum import Enum
from typing import Callable

from ucat_console.typedconf import Config, param


class Fault(str, Enum):
    """The kinds of fault an emulator can inject."""

    SILENCE = "silence"
    CORRUPT = "corrupt"
    INVALID = "invalid"
    IMPLAUSIBLE = "implausible"
    SLOW = "slow"


def as_fault(fault: Fault | str) -> Fault:
    """``Fault`` from a fault or its name; a clear error for an unknown name."""
    if isinstance(fault, Fault):
        return fault
    try:
        return Fault(str(fault))
    except ValueError:
        known = ", ".join(f.value for f in Fault)
        raise ValueError(f"fault: {fault!r} is not one of {known}") from None


def numbers(name: str, value: object, n: int) -> tuple[float, ...]:
    """``value`` as ``n`` finite numbers (a fault's values); ValueError naming ``name``."""
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != n:  # type: ignore[arg-type]
        raise ValueError(f"{name}: expected {n} numbers, got {value!r}")
    out = []
    for v in value:  # type: ignore[attr-defined]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ValueError(f"{name}: expected {n} finite numbers, got {value!r}")
        out.append(float(v))
    return tuple(out)


@dataclass(frozen=True)
class FaultSettings(Config):
    """How strongly an injected fault acts."""

    slow_delay_s: float = param(
        1.0, lo=0.0, hi=60.0, unit="s", doc="extra delay of replies while 'slow' is active"
    )
    corrupt_every: int = param(
        1, lo=1, hi=1000, doc="while 'corrupt' is active, corrupt one message in this many"
    )


class FaultSet:
    """The faults active now, each with an optional expiry time (thread-safe)."""

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self._clock = clock
        self._lock = threading.Lock()
        self._until: dict[Fault, float | None] = {}

    def inject(self, fault: Fault | str, duration: float | None = None) -> None:
        f = as_fault(fault)
        if duration is not None and not duration > 0.0:
            raise ValueError(f"duration: {duration!r} must be positive seconds or None")
        with self._lock:
            self._until[f] = None if duration is None else self._clock() + float(duration)

    def clear(self, fault: Fault | str | None = None) -> None:
        with self._lock:
            if fault is None:
                self._until.clear()
            else:
                self._until.pop(as_fault(fault), None)

    def active(self, fault: Fault | str) -> bool:
        f = as_fault(fault)
        with self._lock:
            if f not in self._until:
                return False
            until = self._until[f]
            if until is not None and self._clock() >= until:
                del self._until[f]
                return False
            return True

    def snapshot(self) -> frozenset[Fault]:
        return frozenset(f for f in Fault if self.active(f))


class FaultInjectable:
    """Mixin giving an emulator ``inject``/``clear``; it must set ``self.faults``."""

    faults: FaultSet

    def inject(self, fault: Fault | str, duration: float | None = None) -> None:
        """Start a fault, for ``duration`` seconds or until :meth:`clear`."""
        self.faults.inject(fault, duration)

    def clear(self, fault: Fault | str | None = None) -> None:
        """End one fault, or all of them."""
        self.faults.clear(fault)
