"""Who may act: one pilot at a time, everyone else read-only, the pilot token.

Every page that connects is a *client* (an integer id). At most one client is the pilot.
Control passes only two ways:

* **by the token while nobody flies**: the pilot token (random, printed at start-up,
  compared in constant time, without the spaces around what the page sent) makes its
  holder the pilot at once;
* **by the pilot's hand-over**: while a pilot flies, the right token only asks it; the
  request waits for the pilot to hand over (or decline) and lapses after
  ``handover_timeout`` seconds, judged by the clock given (:meth:`AccessControl.expire`
  tells the listeners; a lapsed request is never taken even before that).

A pilot whose page is gone (closed, or silent: :meth:`AccessControl.disconnect`) flies no
more, and a request made to it lapses with it: nobody takes control by waiting, so the
pilot-gone failsafe always acts (the supervisor's), and the person with the token takes
control back at once.

Wrong tokens are counted per page and per remote address, never for everyone:

* a page that sent ``max_failures`` wrong tokens within ``lockout`` seconds may not try
  again for ``lockout`` seconds (reloading gives a new page, hence the next rule);
* once ``address_max_failures`` wrong tokens came from one address within ``lockout``
  seconds, no page of that address may try until ``lockout`` seconds later, a freshly
  loaded one included (it is told how long): the address's budget of guesses survives new
  pages. Attempts refused while locked are not counted, so the lock ends on time.

The trade-off: a page on the pilot's machine (or, behind a reverse proxy, any page, since
all have the proxy's address) that spends the address's budget keeps a *reloaded* page of
the pilot from taking control until the lock ends; meanwhile the pilot-gone failsafe holds
the robot. The pilot in control needs no token and is never affected, nor are other
addresses. The random token makes guessing hopeless anyway; the budget matters for a short
configured one.

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

from ucat_console.typedconf import Config, param

log = logging.getLogger(__name__)

#: the console process itself
LOCAL = "local"

Actor = int | str  # a client id, or LOCAL
#: the longest name a page may give itself
MAX_NAME = 40


@dataclass(frozen=True)
class AccessConfig(Config):
    """One pilot, everyone else read-only (console.md, Safety and access)."""

    token: str = param("", secret=True,
                       doc="pilot token; empty: a new random token at every start (never recorded or logged)")
    max_failures: int = param(5, lo=1, hi=1000, doc="wrong tokens from one page before its token entry is locked")
    address_max_failures: int = param(
        20, lo=1, hi=100_000,
        doc="wrong tokens from one remote address before every page of that address is locked out "
        "(the pilot in control needs no token and is not affected)",
    )
    lockout: float = param(30.0, lo=0.0, hi=3600.0, unit="s",
                           doc="window for counting wrong tokens, and how long a lock lasts")
    confirm_timeout: float = param(
        20.0, lo=1.0, hi=600.0, unit="s", doc="an arm request must be confirmed within this time"
    )
    handover_timeout: float = param(
        20.0, lo=1.0, hi=600.0, unit="s",
        doc="a request for control the pilot has not handed over within this time lapses; a request "
        "lapses too when the pilot's page goes (it never takes control by itself)",
    )

    def _check(self) -> None:
        if self.token != self.token.strip():
            raise ValueError("token: the fixed token has surrounding spaces, which a page's token box "
                             "never sends; remove them")
        if self.token and len(self.token) < 8:
            raise ValueError(f"token: a fixed token needs at least 8 characters, got {len(self.token)}")


class AccessDenied(PermissionError):
    """An action refused because of who asked (the message says why)."""


def actor_name(who: Actor) -> str:
    return "console" if who == LOCAL else f"client {who}"


@dataclass(frozen=True)
class AccessState:
    pilot: int | None
    clients: tuple[int, ...]
    pending: int | None  # client asking the pilot for control (None once it lapsed)


class _Failures:
    """Wrong-token times of one page or address, and until when it is locked."""

    __slots__ = ("times", "locked_until")

    def __init__(self) -> None:
        self.times: list[float] = []
        self.locked_until = 0.0

    def add(self, now: float, window: float, limit: int) -> bool:
        """Count a failure at ``now``; True when this locks it."""
        self.times = [t for t in self.times if now - t < window] + [now]
        if len(self.times) >= limit:
            self.locked_until = now + window
            self.times = []
            return True
        return False

    def recent(self, now: float, window: float) -> bool:
        return any(now - t < window for t in self.times) or now < self.locked_until


class AccessControl:
    def __init__(self, cfg: AccessConfig | None = None, clock: Callable[[], float] = time.monotonic) -> None:
        self.cfg = cfg or AccessConfig()
        self._token = self.cfg.token or secrets.token_urlsafe(16)
        self._clock = clock
        self._lock = threading.RLock()
        self._clients: list[int] = []
        self._address: dict[int, str] = {}
        self._names: dict[int, str] = {}
        self._pilot: int | None = None
        self._pending: int | None = None
        self._pending_since = 0.0  # when the pending request was made (the clock's time)
        self._page_failures: dict[int, _Failures] = {}
        self._address_failures: dict[str, _Failures] = {}
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
        """The client waiting for the pilot's hand-over (None: none, or its request lapsed)."""
        with self._lock:
            return None if self._lapsed() else self._pending

    @property
    def clients(self) -> tuple[int, ...]:
        with self._lock:
            return tuple(self._clients)

    def state(self) -> AccessState:
        with self._lock:
            return AccessState(self._pilot, tuple(self._clients), self.pending)

    def name(self, client: int) -> str:
        """The name page ``client`` chose ("" when none)."""
        with self._lock:
            return self._names.get(client, "")

    def set_name(self, client: int, name: object) -> None:
        """Page ``client``'s own name, shown to the others when it flies (at most
        :data:`MAX_NAME` printable characters; "" clears it)."""
        if not isinstance(name, str):
            raise ValueError(f"name: expected text, got {type(name).__name__}")
        name = " ".join(name.split())
        if len(name) > MAX_NAME or not name.isprintable():
            raise ValueError(f"name: at most {MAX_NAME} printable characters")
        with self._lock:
            if client not in self._clients:
                raise AccessDenied(f"name: client {client} is not connected")
            if name:
                self._names[client] = name
            else:
                self._names.pop(client, None)
        self._changed()

    def address(self, client: int) -> str:
        """The remote address client ``client`` connected from ("" when not known)."""
        with self._lock:
            return self._address.get(client, "")

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
    def connect(self, client: int, address: str = "") -> None:
        """A page connected (from remote ``address``, when known)."""
        with self._lock:
            if client not in self._clients:
                self._clients.append(client)
            if address:
                self._address[client] = address
        self._changed()

    def disconnect(self, client: int) -> bool:
        """Forget ``client`` (its page closed or went silent); True when it was the pilot.

        A request for control made to the gone pilot lapses: nobody flies afterwards."""
        with self._lock:
            if client in self._clients:
                self._clients.remove(client)
            self._address.pop(client, None)
            self._names.pop(client, None)
            self._page_failures.pop(client, None)
            was_pilot = self._pilot == client
            if was_pilot:
                self._pilot = None
                log.warning("pilot (client %s) left", client)
                if self._pending is not None:
                    log.info("client %s's request for control lapsed with the pilot", self._pending)
            if was_pilot or self._pending == client:
                self._pending = None
        self._changed()
        return was_pilot

    # ------------------------------------------------------------------ requests
    def _lapsed(self) -> bool:
        """(Under the lock.) Whether the pending request is older than ``handover_timeout``."""
        return self._pending is not None and \
            self._clock() - self._pending_since >= self.cfg.handover_timeout

    def _lapse(self) -> int | None:
        """(Under the lock.) Drop a lapsed request; the client whose request it was."""
        if not self._lapsed():
            return None
        lapsed, self._pending = self._pending, None
        log.info("client %s's request for control lapsed: not handed over within %g s", lapsed,
                 self.cfg.handover_timeout)
        return lapsed

    def expire(self) -> int | None:
        """Drop a request the pilot has not handed over within ``handover_timeout`` (the
        listeners are told); the client whose request lapsed, else None. Call it often
        (the supervisor does, every supervision period)."""
        with self._lock:
            lapsed = self._lapse()
        if lapsed is not None:
            self._changed()
        return lapsed

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
            window = self.cfg.lockout
            page = self._page_failures.setdefault(client, _Failures())
            address = self._address.get(client, "")
            by_address = self._address_failures.setdefault(address, _Failures()) if address else None
            if now < page.locked_until:
                raise AccessDenied(
                    f"take control: too many wrong tokens from this page; its token entry is locked "
                    f"for another {page.locked_until - now:.0f} s"
                )
            if by_address is not None and now < by_address.locked_until:
                raise AccessDenied(
                    f"take control: too many wrong tokens from {address}; token entry is locked for "
                    f"every page of that address for another {by_address.locked_until - now:.0f} s"
                )
            if not isinstance(token, str) or len(token) > 1024 or not secrets.compare_digest(
                token.strip().encode(), self._token.encode()
            ):
                if page.add(now, window, self.cfg.max_failures):
                    log.warning("token entry locked for %.0f s for client %s after wrong tokens", window, client)
                if by_address is not None and by_address.add(now, window, self.cfg.address_max_failures):
                    log.warning("token entry locked for %.0f s for every page of %s after wrong tokens",
                                window, address)
                self._prune(now, window)
                raise AccessDenied("take control: wrong pilot token")
            page.times = []
            if self._pilot is None:
                self._pilot = client
                self._pending = None
                granted = True
                log.info("client %s is the pilot", client)
            else:
                self._pending = client
                self._pending_since = now
                granted = False
                log.info("client %s asks client %s for control", client, self._pilot)
        self._changed()
        return granted

    def _prune(self, now: float, window: float) -> None:
        """Forget addresses whose failures have all expired (the table stays small)."""
        for key in [k for k, f in self._address_failures.items() if not f.recent(now, window)]:
            del self._address_failures[key]

    def hand_over(self, pilot: Actor, to: int) -> None:
        """The pilot gives control to the client that asked for it (within ``handover_timeout``)."""
        with self._lock:
            before = (self._pilot, self._pending)
            lapsed = self._lapse()
            if not (pilot == LOCAL or pilot == self._pilot):
                why = f"hand over: {actor_name(pilot)} is not the pilot"
            elif lapsed == to:
                why = (f"hand over: client {to}'s request lapsed after {self.cfg.handover_timeout:g} s; "
                       "it may ask again")
            elif self._pending != to:
                why = f"hand over: client {to} has not asked for control with the token"
            elif to not in self._clients:
                self._pending = None
                why = f"hand over: client {to} has left"
            else:
                self._pilot = to
                self._pending = None
                why = ""
                log.info("control handed over to client %s", to)
            changed = (self._pilot, self._pending) != before
        if changed:
            self._changed()
        if why:
            raise AccessDenied(why)

    def decline(self, pilot: Actor) -> None:
        with self._lock:
            if not (pilot == LOCAL or pilot == self._pilot):
                raise AccessDenied(f"decline: {actor_name(pilot)} is not the pilot")
            self._pending = None
        self._changed()

    def release(self, client: Actor) -> None:
        """The pilot gives up control (nobody flies afterwards; a request made to it lapses)."""
        with self._lock:
            if client != self._pilot:
                raise AccessDenied(f"release: {actor_name(client)} is not the pilot")
            self._pilot = None
            self._pending = None
        self._changed()

    def _changed(self) -> None:
        st = self.state()
        for fn in list(self._listeners):
            try:
                fn(st)
            except Exception:
                log.exception("access listener failed")
