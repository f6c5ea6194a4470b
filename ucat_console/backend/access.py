"""Who may act: one pilot at a time, everyone else read-only, the pilot token.

Every page that connects is a *client* (an integer id). At most one client is the pilot.
Taking control needs the pilot token (random, printed at start-up, compared in constant
time); when nobody flies, the right token makes its holder the pilot at once, otherwise
the request waits for the present pilot to hand over explicitly (or to decline). Wrong
tokens are counted: after ``max_failures`` of them within ``lockout`` seconds, token
entry is refused for everyone for ``lockout`` seconds.

:data:`LOCAL` is the console process itself (command line, Ctrl-C, headless runs): it
is always allowed. :class:`AccessControl` holds no other state than who is connected and
who flies; what the pilot may do is the supervisor's business
(:meth:`AccessControl.require_pilot`).
"""

from __future__ import annotations

import logging
import secrets
import threading
import time
from dataclasses import dataclass
from typing import Callable

from ucat_console.config import AccessConfig

log = logging.getLogger(__name__)

#: the console process itself
LOCAL = "local"

Actor = int | str  # a client id, or LOCAL


class AccessDenied(PermissionError):
    """An action refused because of who asked (the message says why)."""


def actor_name(who: Actor) -> str:
    return "console" if who == LOCAL else f"client {who}"


@dataclass(frozen=True)
class AccessState:
    pilot: int | None
    clients: tuple[int, ...]
    pending: int | None  # client asking the pilot for control
    locked_until: float  # monotonic time until which token entry is locked (0: not locked)


class AccessControl:
    def __init__(self, cfg: AccessConfig | None = None, clock: Callable[[], float] = time.monotonic) -> None:
        self.cfg = cfg or AccessConfig()
        self._token = self.cfg.token or secrets.token_urlsafe(16)
        self._clock = clock
        self._lock = threading.RLock()
        self._clients: list[int] = []
        self._pilot: int | None = None
        self._pending: int | None = None
        self._failures: list[float] = []
        self._locked_until = 0.0
        self._listeners: list[Callable[[AccessState], None]] = []

    # ------------------------------------------------------------------ state
    @property
    def token(self) -> str:
        return self._token

    @property
    def pilot(self) -> int | None:
        return self._pilot

    @property
    def pending(self) -> int | None:
        return self._pending

    @property
    def clients(self) -> tuple[int, ...]:
        with self._lock:
            return tuple(self._clients)

    def state(self) -> AccessState:
        with self._lock:
            return AccessState(self._pilot, tuple(self._clients), self._pending, self._locked_until)

    def add_listener(self, fn: Callable[[AccessState], None]) -> None:
        """``fn(state)`` after every change (connect, disconnect, pilot, request)."""
        self._listeners.append(fn)

    def is_pilot(self, who: Actor) -> bool:
        return who == LOCAL or (who is not None and who == self._pilot)

    def require_pilot(self, who: Actor, action: str) -> None:
        """AccessDenied unless ``who`` is the pilot (or the console itself)."""
        if not self.is_pilot(who):
            raise AccessDenied(
                f"{action}: refused, {actor_name(who)} is read-only; only the pilot can do this "
                "(enter the pilot token to take control)"
            )

    # ------------------------------------------------------------------ clients
    def connect(self, client: int) -> None:
        with self._lock:
            if client not in self._clients:
                self._clients.append(client)
        self._changed()

    def disconnect(self, client: int) -> bool:
        """Forget ``client``; True when it was the pilot."""
        with self._lock:
            if client in self._clients:
                self._clients.remove(client)
            was_pilot = self._pilot == client
            if was_pilot:
                self._pilot = None
                log.warning("pilot (client %s) left", client)
            if self._pending == client:
                self._pending = None
        self._changed()
        return was_pilot

    # ------------------------------------------------------------------ control
    def request_control(self, client: int, token: object) -> bool:
        """Ask for control with the pilot token.

        Returns True when ``client`` is now the pilot, False when the request waits for
        the present pilot's hand-over. AccessDenied on a wrong token or while locked.
        """
        with self._lock:
            if client not in self._clients:
                raise AccessDenied(f"take control: client {client} is not connected")
            if self._pilot == client:
                return True
            now = self._clock()
            if now < self._locked_until:
                raise AccessDenied(
                    f"take control: too many wrong tokens; token entry is locked for another "
                    f"{self._locked_until - now:.0f} s"
                )
            if not isinstance(token, str) or not secrets.compare_digest(
                token.strip().encode(), self._token.encode()
            ):
                self._failures = [t for t in self._failures if now - t < self.cfg.lockout] + [now]
                if len(self._failures) >= self.cfg.max_failures:
                    self._locked_until = now + self.cfg.lockout
                    self._failures = []
                    log.warning("token entry locked for %.0f s after wrong tokens", self.cfg.lockout)
                raise AccessDenied("take control: wrong pilot token")
            if self._pilot is None:
                self._pilot = client
                self._pending = None
                granted = True
                log.info("client %s is the pilot", client)
            else:
                self._pending = client
                granted = False
                log.info("client %s asks client %s for control", client, self._pilot)
        self._changed()
        return granted

    def hand_over(self, pilot: Actor, to: int) -> None:
        """The pilot gives control to the client that asked for it."""
        with self._lock:
            if not (pilot == LOCAL or pilot == self._pilot):
                raise AccessDenied(f"hand over: {actor_name(pilot)} is not the pilot")
            if self._pending != to:
                raise AccessDenied(f"hand over: client {to} has not asked for control with the token")
            if to not in self._clients:
                self._pending = None
                raise AccessDenied(f"hand over: client {to} has left")
            self._pilot = to
            self._pending = None
            log.info("control handed over to client %s", to)
        self._changed()

    def decline(self, pilot: Actor) -> None:
        with self._lock:
            if not (pilot == LOCAL or pilot == self._pilot):
                raise AccessDenied(f"decline: {actor_name(pilot)} is not the pilot")
            self._pending = None
        self._changed()

    def release(self, client: Actor) -> None:
        """The pilot gives up control (nobody flies afterwards)."""
        with self._lock:
            if client != self._pilot:
                raise AccessDenied(f"release: {actor_name(client)} is not the pilot")
            self._pilot = None
        self._changed()

    def _changed(self) -> None:
        st = self.state()
        for fn in list(self._listeners):
            try:
                fn(st)
            except Exception:
                log.exception("access listener failed")
