"""Arming in two steps: a request, then its confirmation by the same pilot in time.

:class:`ArmRequests` owns the one open request: :meth:`ArmRequests.request` returns a
nonce that the same actor passes to :meth:`ArmRequests.confirm` within the timeout; a
request is confirmed at most once, and is dropped when its actor's page goes or the robot
is disarmed.
"""

from __future__ import annotations

import secrets
import threading
import time
from dataclasses import dataclass

from ucat_console.backend.access import Actor
from ucat_console.backend.loop.commands import CommandRefused


@dataclass(frozen=True)
class _Request:
    nonce: str
    who: Actor
    expires: float


class ArmRequests:
    def __init__(self, timeout: float) -> None:
        self.timeout = float(timeout)
        self._lock = threading.Lock()
        self._request: _Request | None = None

    def request(self, who: Actor) -> str:
        nonce = secrets.token_hex(8)
        with self._lock:
            self._request = _Request(nonce, who, time.monotonic() + self.timeout)
        return nonce

    def cancel(self, who: Actor) -> None:
        with self._lock:
            if self._request is not None and self._request.who == who:
                self._request = None

    def clear(self) -> None:
        with self._lock:
            self._request = None

    def confirm(self, who: Actor, nonce: object) -> None:
        """CommandRefused unless ``nonce`` confirms ``who``'s open request in time (it is used up)."""
        with self._lock:
            req = self._request
            if req is None or req.who != who:
                raise CommandRefused("arm: nothing to confirm; press Arm first")
            self._request = None  # one confirmation attempt per request
        if not isinstance(nonce, str) or not secrets.compare_digest(nonce, req.nonce):
            raise CommandRefused("arm: the confirmation does not match the request; press Arm again")
        if time.monotonic() > req.expires:
            raise CommandRefused("arm: the confirmation came too late; press Arm again")
