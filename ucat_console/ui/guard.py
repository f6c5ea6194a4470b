# Over 600 lines: every check of what a page sends is in this one module, so that no message reaches viser by another, unchecked path.
"""What the console checks of every page before viser acts on it.

viser trusts its pages: it accepts any websocket (any Origin), applies whatever property an
update message names to whatever handle it names, and counts a page as present for as long
as its TCP connection is open. :class:`PageGuard` stands between the websocket and viser:

* **Handshake.** A websocket upgrade whose ``Origin`` is not the console's own is refused
  with HTTP 403 and one log line (:func:`origin_allowed`): a browser page from elsewhere
  cannot drive the console through the operator's browser. A request without ``Origin``
  (a non-browser client, which could send any header anyway) is let through; the pilot
  token still guards control. Frames over :data:`MAX_FRAME` bytes close the socket.
* **Incoming messages.** Every message a page sends is decoded and admitted or refused
  here, once, before viser sees it (:meth:`PageGuard.admit`): a GUI update may change only
  the ``value`` of an input the console registered for that page (:meth:`PageGuard.allow`),
  with a value of the input's kind and within its size; a pilot-only input only while the
  page is the pilot's; the other message types only where the console uses them (camera,
  commands, heartbeat answers). Everything else, and anything over the page's message
  rate, is refused with one log line (no traceback) and changes nothing.
* **Safety commands first.** An input or command registered with ``urgent=`` (the pilot's
  DISARM button and Esc key, the Space key's stop) is not handed to viser: once admitted,
  its action runs on the guard's own thread (``safety-commands``), so it never waits
  behind the callbacks of other pages in viser's shared thread pool.
* **Liveness.** Every ``heartbeat_period`` each page is asked for a value (viser's
  localStorage request, which only the page's running script answers). A page that has
  not answered for its allowed silence (:meth:`PageGuard.silence_limit`: the pilot's
  ``failsafe.pilot_gone.timeout``, everyone else ``console.page_timeout``) is declared
  gone (``on_gone(client, silent_for)``) and its socket is closed at once: a frozen
  browser, a page that stops reading, or a cut Wi-Fi link is noticed in seconds, not at
  the TCP retransmission timeout. A page that wakes up reconnects as a new page. Only an
  answer to a request the guard sent counts.
* **Slow links.** The heartbeat request (and, while the link is slow, the status bar,
  :meth:`PageGuard.send_first`) is sent as a frame of its own, ahead of the page's queued
  telemetry; the telemetry goes
  only while the page's bytes in flight are under its budget (:mod:`ucat_console.ui.link`),
  so what a heartbeat waits behind is bounded and a page that reads slowly gets its poses
  and plots coalesced (viser keeps the newest value of each) instead of a growing backlog.
  Such a page's status bar says "link slow" (:meth:`PageGuard.link_slow`).

viser does not offer hooks for these, so :mod:`ucat_console.ui.viser_compat` wraps names in
viser's websocket module (the ``websockets`` serve call, the per-connection message consumer
and sender) for every server viser starts for :meth:`PageGuard.serve`, including its tries on
other ports (then refused: :class:`PortTaken`); servers created otherwise are left as viser
makes them.
"""

from __future__ import annotations

import asyncio
import collections
import ipaddress
import logging
import math
import queue
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Iterable
from urllib.parse import urlsplit

import msgspec
import viser

from ucat_console.ui import viser_compat
from ucat_console.ui.viser_compat import (
    CommandTriggerMessage,
    GuiUpdateMessage,
    LocalStorageGetItemRequestMessage,
    LocalStorageGetItemResponseMessage,
    ViewerCameraMessage,
)
from ucat_console.ui.link import PageLink

log = logging.getLogger(__name__)


class PortTaken(OSError):
    """The page's server could not have the port it was given (``port``); viser had served
    on ``got`` instead (stopped)."""

    def __init__(self, port: int, got: int) -> None:
        super().__init__(f"port {port} is in use by another program: the console serves its page only on the port "
                         f"it was given (console.port, --port); free port {port} or give another one (0 lets the "
                         f"system choose)")
        self.port = port
        self.got = got


#: the largest websocket frame a page may send (bytes); larger ones close its socket
MAX_FRAME = 256 * 1024
#: the longest text a page may put in any input (characters)
MAX_TEXT = 4096
#: messages a page may send per second (a token bucket; bursts up to twice this)
MESSAGE_RATE = 120.0
HEARTBEAT_KEY = "ucat-console-heartbeat"
_HB_PREFIX = "ucat-hb-"
_LOG_EVERY = 10.0  # s between log lines for repeated refusals (of one page, of connections)


class Burst:
    """One log line per burst of a repeated event: the first at once, then at most one every
    ``every`` s, saying how many came since the last line."""

    def __init__(self, every: float = _LOG_EVERY) -> None:
        self.every = every
        self.count = 0  # events so far
        self._last = -math.inf
        self._unlogged = 0

    def note(self, now: float) -> int | None:
        """Count one event at ``now``: None when no line is due, else the number of events not
        logged since the last line (0 for the first of a burst)."""
        self.count += 1
        if now - self._last < self.every:
            self._unlogged += 1
            return None
        more, self._unlogged, self._last = self._unlogged, 0, now
        return more


def _since(more: int) -> str:
    return f" ({more} more since the last line)" if more else ""


# ---------------------------------------------------------------------- message fields
#: the farthest a page's camera may be, or look at, from the origin, and its far plane (m)
MAX_DISTANCE = 1e6
#: the largest canvas a page may report (pixels a side)
MAX_PIXELS = 1 << 16
#: the longest id a page may name (an element's, a command's, a request's; characters)
MAX_ID = 100
#: how far from 1 the length of a page's camera orientation and up direction may be
UNIT_TOLERANCE = 0.01

_Check = Callable[[Any], "str | None"]


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _number(lo: float, hi: float, *, lo_open: bool = False, hi_open: bool = False, unit: str = "") -> _Check:
    def check(v: Any) -> str | None:
        if not _is_number(v):
            return f"expected a number, got {type(v).__name__}"
        if not math.isfinite(v):
            return "not a finite number"
        if v < lo or v > hi or (lo_open and v == lo) or (hi_open and v == hi):
            return (f"{v!r}{unit} outside {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
                    f"{unit}")
        return None
    return check


def _integer(lo: int, hi: int) -> _Check:
    def check(v: Any) -> str | None:
        if not isinstance(v, int) or isinstance(v, bool):
            return f"expected a whole number, got {type(v).__name__}"
        return None if lo <= v <= hi else f"{v} outside [{lo}, {hi}]"
    return check


def _vector(n: int, bound: float = MAX_DISTANCE, *, unit: bool = False) -> _Check:
    """``n`` finite numbers, each within ``bound``; with ``unit`` of length 1 (UNIT_TOLERANCE)."""
    def check(v: Any) -> str | None:
        if not isinstance(v, (list, tuple)) or len(v) != n:
            return f"expected {n} numbers, got {_short(repr(v), 40)}"
        for x in v:
            if not _is_number(x):
                return f"expected {n} numbers, got a {type(x).__name__}"
            if not math.isfinite(x):
                return "not finite numbers"
            if abs(x) > bound:
                return f"{x:g} beyond {bound:g}"
        if unit and abs(math.sqrt(sum(float(x) * x for x in v)) - 1.0) > UNIT_TOLERANCE:
            return "not of length 1"
        return None
    return check


def _text(max_len: int, *, optional: bool = False) -> _Check:
    def check(v: Any) -> str | None:
        if v is None and optional:
            return None
        if not isinstance(v, str):
            return f"expected text, got {type(v).__name__}"
        return None if len(v) <= max_len else f"text of {len(v)} characters, over the limit of {max_len}"
    return check


def _mapping(v: Any) -> str | None:
    if not isinstance(v, dict) or not all(isinstance(k, str) for k in v):
        return f"expected a map of names, got {type(v).__name__}"
    return None


#: every message type a page may send, and the check of each of its fields (viser's
#: client -> server messages the console takes (viser's message classes); what the page's
#: script sends, a browser's numbers as msgpack has them: a whole number as an integer)
FIELDS: dict[str, dict[str, _Check]] = {
    "ViewerCameraMessage": {
        "wxyz": _vector(4, 1.0 + UNIT_TOLERANCE, unit=True),
        "position": _vector(3),
        "look_at": _vector(3),
        "up_direction": _vector(3, 1.0 + UNIT_TOLERANCE, unit=True),
        "fov": _number(0.0, math.pi, lo_open=True, hi_open=True, unit=" rad"),
        "near": _number(0.0, MAX_DISTANCE, lo_open=True, unit=" m"),
        "far": _number(0.0, MAX_DISTANCE, lo_open=True, unit=" m"),
        "image_height": _integer(0, MAX_PIXELS),
        "image_width": _integer(0, MAX_PIXELS),
    },
    "GuiUpdateMessage": {"uuid": _text(MAX_ID), "updates": _mapping},  # the value: by its input's rule
    "CommandTriggerMessage": {"uuid": _text(MAX_ID)},
    "LocalStorageGetItemResponseMessage": {
        "value": _text(MAX_TEXT, optional=True),
        "error": _text(MAX_TEXT, optional=True),
        "request_uuid": _text(MAX_ID),
    },
}


def field_problem(fields: Any) -> str | None:
    """Why a page's decoded message (its msgpack map, as sent) is not one the console takes:
    a type not in :data:`FIELDS`, a field missing or unknown, or a field of the wrong type,
    not finite or out of its range; None when every field is fine."""
    if not isinstance(fields, dict):
        return f"not a message (a {type(fields).__name__}, not a map)"
    name = fields.get("type")
    checks = FIELDS.get(name) if isinstance(name, str) else None
    if checks is None:
        return f"a {_short(name)}, which the console does not take"
    missing = [k for k in checks if k not in fields]
    extra = [str(k) for k in fields if k != "type" and k not in checks]
    if missing or extra:
        return f"a {name} with {_short(', '.join(missing + extra))} " + \
            ("missing" if not extra else "unknown" if not missing else "missing or unknown")
    for key, check in checks.items():
        bad = check(fields[key])
        if bad is not None:
            return f"a {name}: {key}: {bad}"
    if name == "ViewerCameraMessage" and fields["far"] <= fields["near"]:
        return f"a {name} whose far plane is not beyond its near plane"
    return None


# ---------------------------------------------------------------------- handshake
def _is_ip_or_localhost(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        ipaddress.ip_address(host.strip("[]"))
        return True
    except ValueError:
        return False


def origin_allowed(origin: str | None, host_header: str | None, allowed: Iterable[str] = ()) -> bool:
    """Whether a websocket handshake with this ``Origin`` may connect.

    Allowed: no Origin (not a browser); an Origin in ``allowed`` (e.g. the address of a
    reverse proxy, ``https://console.example.org``); or the page's own origin, i.e. the
    Origin's host and port are the request's ``Host`` and the host is an IP address or
    ``localhost`` (a host name could be rebound by a hostile DNS server to this machine,
    so names must be listed in ``allowed``).
    """
    if origin is None:
        return True
    origin = origin.strip()
    if origin in {a.rstrip("/") for a in allowed}:
        return True
    try:
        parts = urlsplit(origin)
    except ValueError:
        return False
    if parts.scheme not in ("http", "https") or not parts.netloc or host_header is None:
        return False
    return parts.netloc.lower() == host_header.strip().lower() and _is_ip_or_localhost(
        (parts.hostname or "").lower())


# ---------------------------------------------------------------------- inputs
@dataclass(frozen=True)
class InputRule:
    """Who may set one input's value, and what a value must be."""

    client: int  # the page the input belongs to
    pilot_only: bool
    check: Callable[[Any], str | None]  # None when the value is acceptable, else why not
    name: str
    handle: Any = None  # the input, to show its value again after a refused one
    urgent: Callable[[], None] | None = None  # run on the guard's safety thread, not by viser


def value_check(handle: Any, max_len: int) -> Callable[[Any], str | None]:
    """The check of a value for ``handle`` by its kind (number, text, choice, switch, button)."""
    if isinstance(handle, viser.GuiButtonHandle):
        return lambda v: None if v is True else f"a button's value must be true, got {v!r}"
    if isinstance(handle, viser.GuiCheckboxHandle):
        return lambda v: None if isinstance(v, bool) else f"expected true or false, got {type(v).__name__}"
    if isinstance(handle, viser.GuiDropdownHandle):
        def choice(v: Any) -> str | None:
            if not isinstance(v, str) or len(v) > max_len:
                return "expected one of the options"
            return None if v in handle.options else "not one of the options"
        return choice
    if isinstance(handle, viser.GuiTextHandle):
        def text(v: Any) -> str | None:
            if not isinstance(v, str):
                return f"expected text, got {type(v).__name__}"
            return None if len(v) <= max_len else f"text of {len(v)} characters, over the limit of {max_len}"
        return text
    if isinstance(handle, (viser.GuiNumberHandle, viser.GuiSliderHandle)):
        slider = isinstance(handle, viser.GuiSliderHandle)

        def number(v: Any) -> str | None:
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                return f"expected a number, got {type(v).__name__}"
            if not math.isfinite(v):
                return "not a finite number"
            if slider and not handle.min <= v <= handle.max:
                return f"outside the slider's range [{handle.min:g}, {handle.max:g}]"
            return None
        return number
    raise TypeError(f"no value check for a {type(handle).__name__}")


# ---------------------------------------------------------------------- pages
class _Page:
    """One websocket: its connection, address and liveness."""

    def __init__(self, client: int, conn: Any, ws_conn: Any, address: str, now: float) -> None:
        self.client = client
        self.conn = conn  # viser's WebsockClientConnection (queue_message)
        self.ws = ws_conn  # the websockets ServerConnection (transport)
        self.address = address
        self.connected = now
        self.last_answer = now
        self.answers = 0
        self.seq = 0
        self.gone = False
        self.tokens = 2 * MESSAGE_RATE
        self.refill = now
        self.refused = Burst()  # its refused messages
        self.link = PageLink(now)  # touched in the server's event-loop thread only
        self.room: asyncio.Event | None = None  # set when the page answers (event-loop thread)


class PageGuard:
    """The checks of one console's pages (module docstring).

    ``max_frame``: the largest websocket frame a page may send (bytes).

    ``is_pilot(client)``: whether a page is the pilot's now; ``pilot_timeout()``: the
    pilot's allowed silence (s); ``on_connect(client, address)`` / ``on_gone(client,
    silent_for)``: called when a websocket opens and when a silent page is declared gone;
    ``max_per_address``: the websockets one remote address may have open at once (None: any).
    """

    max_frame = MAX_FRAME

    def __init__(
        self,
        *,
        is_pilot: Callable[[int], bool],
        pilot_timeout: Callable[[], float],
        page_timeout: float,
        heartbeat_period: float,
        allowed_origins: Iterable[str] = (),
        max_per_address: int | None = None,
        on_connect: Callable[[int, str], None] = lambda c, a: None,
        on_disconnect: Callable[[int], None] = lambda c: None,
        on_gone: Callable[[int, float], None] = lambda c, s: None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.is_pilot = is_pilot
        self.pilot_timeout = pilot_timeout
        self.page_timeout = float(page_timeout)
        self.heartbeat_period = float(heartbeat_period)
        self.allowed_origins = tuple(allowed_origins)
        self.max_per_address = max_per_address
        self.on_connect = on_connect
        self.on_disconnect = on_disconnect
        self.on_gone = on_gone
        self.clock = clock
        self._lock = threading.Lock()
        self._pages: dict[int, _Page] = {}
        self._by_ws: dict[Any, int] = {}
        self._inputs: dict[str, InputRule] = {}
        self._commands: dict[str, InputRule] = {}
        self._origin_logged: dict[str, float] = {}
        self._per_address: collections.Counter[str] = collections.Counter()  # open websockets (event loop)
        self._over_cap = Burst()  # websockets closed at once: over the cap of their address
        self._accept_failed = Burst()  # connections the server could not accept (out of file handles)
        self._strangers = Burst()  # messages from a socket that is not a page
        self.refusals: collections.deque[tuple[int | None, str]] = collections.deque(maxlen=1000)
        self.server: viser.ViserServer | None = None
        self.loop: asyncio.AbstractEventLoop | None = None  # the pages' event loop (viser's)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._urgent: queue.SimpleQueue[tuple[int, str, Callable[[], None]] | None] = queue.SimpleQueue()
        self._urgent_thread: threading.Thread | None = None
        self.urgent_runs = 0  # safety commands run
        self._zstd = viser_compat.compressor()  # for the frames sent ahead (event-loop thread)

    # ------------------------------------------------------------------ server
    def serve(self, *, port: int, **kwargs: Any) -> viser.ViserServer:
        """A ViserServer (``kwargs`` as for viser) whose pages pass through this guard, on
        ``port`` (0: one the system chooses, logged). :class:`PortTaken` when the port is
        taken (viser would serve on the next free one: that server, guarded too, is stopped)."""
        server = viser_compat.guarded_server(self, port=port, **kwargs)
        got = server.get_port()
        if port != 0 and got != port:
            server.stop()
            raise PortTaken(port, got)
        if port == 0:
            log.info("the console's page is on port %d (chosen by the system)", got)
        self.server = server
        viser_compat.on_socket_open(server, self._opened)
        viser_compat.on_socket_close(server, self._closed)
        loop = viser_compat.event_loop(server)
        loop.set_exception_handler(self._loop_exception)
        self.start(loop)
        return server

    def start(self, loop: asyncio.AbstractEventLoop | None) -> None:
        """Start the heartbeat and safety-command threads; ``loop``: the pages' event loop."""
        self.loop = loop
        self._thread = threading.Thread(target=self._run, name="page-guard", daemon=True)
        self._thread.start()
        self._urgent_thread = threading.Thread(target=self._run_urgent, name="safety-commands", daemon=True)
        self._urgent_thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._urgent.put(None)
        for t in (self._thread, self._urgent_thread):
            if t is not None and t is not threading.current_thread():
                t.join(timeout=2.0)

    def handshake_refusal(self, connection: Any, request: Any) -> Any:
        """None to go on with a websocket upgrade, else the HTTP response that refuses it."""
        origin = request.headers.get("Origin")
        if origin_allowed(origin, request.headers.get("Host"), self.allowed_origins):
            return None
        now = self.clock()
        if now - self._origin_logged.get(origin, -math.inf) >= 60.0:
            for o in [o for o, t in self._origin_logged.items() if now - t >= 60.0]:
                del self._origin_logged[o]  # a line a minute per origin: older ones are done with
            self._origin_logged[origin] = now
            log.warning("refused a websocket from Origin %r (remote %s): not the console's own origin; "
                        "add it to console.allowed_origins if it is a reverse proxy in front of the console",
                        origin, _address(connection))
        self.refusals.append((None, f"origin {origin}"))
        return connection.respond(403, "Forbidden: this page's origin may not connect to the console\n")

    # ------------------------------------------------------------------ connections (event loop)
    def connection_refusal(self, ws_conn: Any) -> str | None:
        """(Event loop, a websocket just opened, before viser sees it.) The reason to close it
        at once (its address has ``max_per_address`` open already), else None: it is counted
        until :meth:`connection_closed`. Refusals are logged once per burst, with a count."""
        address = _address(ws_conn)
        if self.max_per_address is None or self._per_address[address] < self.max_per_address:
            self._per_address[address] += 1
            return None
        more = self._over_cap.note(self.clock())
        if more is not None:
            log.warning("refused a page from %s: it has %d open, the most one address may have "
                        "(console.max_pages_per_address)%s", address or "?", self.max_per_address, _since(more))
        self.refusals.append((None, f"over the cap of {self.max_per_address} pages from {address}"))
        return f"too many pages from this address (at most {self.max_per_address}: console.max_pages_per_address)"

    def connection_closed(self, ws_conn: Any) -> None:
        """(Event loop.) A websocket :meth:`connection_refusal` let through has closed."""
        address = _address(ws_conn)
        self._per_address[address] -= 1
        if self._per_address[address] <= 0:
            del self._per_address[address]

    @property
    def refused_connections(self) -> int:
        """Websockets closed at once, over the cap of their address."""
        return self._over_cap.count

    @property
    def failed_accepts(self) -> int:
        """Connections the server could not accept (out of file handles, of memory)."""
        return self._accept_failed.count

    def _loop_exception(self, loop: asyncio.AbstractEventLoop, context: dict[str, Any]) -> None:
        """The pages' event loop's exception handler: a connection the server could not accept
        (asyncio's "socket.accept() out of system resource": no file handle left) is one log
        line per burst, with a count, not a traceback each; anything else goes to asyncio."""
        exc = context.get("exception")
        if isinstance(exc, OSError) and str(context.get("message", "")).startswith("socket.accept()"):
            more = self._accept_failed.note(self.clock())
            if more is not None:
                log.error("the console could not accept a connection: %s (the process is out of file handles "
                          "or memory; new pages wait until some close)%s", exc.strerror or exc, _since(more))
            return
        loop.default_exception_handler(context)

    def _opened(self, conn: Any) -> None:
        cid = int(conn.client_id)
        ws_conn = viser_compat.page_socket(self.server, cid) if self.server else None
        self.page_opened(cid, conn, ws_conn)

    def page_opened(self, cid: int, conn: Any, ws_conn: Any) -> None:
        """A websocket opened: ``conn`` viser's connection, ``ws_conn`` the websockets one."""
        page = _Page(cid, conn, ws_conn, _address(ws_conn), self.clock())
        with self._lock:
            self._pages[cid] = page
            if ws_conn is not None:
                self._by_ws[ws_conn] = cid
        try:
            self.on_connect(cid, page.address)
        except Exception:
            log.exception("page %s: connect handling failed", cid)

    def _closed(self, conn: Any) -> None:
        self.page_closed(int(conn.client_id))

    def page_closed(self, cid: int) -> None:
        with self._lock:
            page = self._pages.pop(cid, None)
            if page is not None and page.ws is not None:
                self._by_ws.pop(page.ws, None)
        self.forget_page(cid)
        try:
            self.on_disconnect(cid)
        except Exception:
            log.exception("page %s: disconnect handling failed", cid)

    def client_of(self, ws_conn: Any) -> int | None:
        with self._lock:
            return self._by_ws.get(ws_conn)

    @property
    def rules(self) -> int:
        """Inputs and commands registered for the pages (:meth:`allow`, :meth:`allow_command`)."""
        with self._lock:
            return len(self._inputs) + len(self._commands)

    @property
    def clients(self) -> tuple[int, ...]:
        """Every open websocket's client id (whether or not its page has shown yet)."""
        with self._lock:
            return tuple(self._pages)

    def address(self, client: int) -> str:
        with self._lock:
            p = self._pages.get(client)
            return p.address if p is not None else ""

    def silence(self, client: int) -> float | None:
        """Seconds since the page last answered (None: no such page)."""
        with self._lock:
            p = self._pages.get(client)
            return None if p is None else self.clock() - p.last_answer

    # ------------------------------------------------------------------ inputs
    def allow(self, handle: Any, client: int, *, pilot_only: bool, max_len: int = 200, name: str = "",
              urgent: Callable[[], None] | None = None) -> None:
        """Let page ``client`` set ``handle``'s value (only while it is the pilot's if
        ``pilot_only``); text up to ``max_len`` characters. With ``urgent`` (a button of a
        safety command), an admitted press runs ``urgent()`` on the guard's safety thread
        instead of the handle's viser callbacks."""
        max_len = min(int(max_len), MAX_TEXT)
        rule = InputRule(client, pilot_only, value_check(handle, max_len),
                         name or getattr(handle, "label", "") or type(handle).__name__, handle, urgent)
        with self._lock:
            if client in self._pages:  # a page that has gone keeps no rule
                self._inputs[viser_compat.handle_uuid(handle)] = rule

    def allow_command(self, handle: Any, client: int, *, pilot_only: bool, name: str = "",
                      urgent: Callable[[], None] | None = None) -> None:
        """Let page ``client`` trigger command ``handle`` (``urgent``: as for :meth:`allow`)."""
        rule = InputRule(client, pilot_only, lambda v: None, name or getattr(handle, "name", "command"),
                         urgent=urgent)
        with self._lock:
            if client in self._pages:
                self._commands[viser_compat.handle_uuid(handle)] = rule

    def forget(self, handle: Any) -> None:
        with self._lock:
            self._inputs.pop(viser_compat.handle_uuid(handle), None)
            self._commands.pop(viser_compat.handle_uuid(handle), None)

    def forget_page(self, client: int) -> None:
        """Drop every rule of page ``client`` (it has gone)."""
        with self._lock:
            for table in (self._inputs, self._commands):
                for key in [k for k, r in table.items() if r.client == client]:
                    del table[key]

    # ------------------------------------------------------------------ incoming (event loop)
    def decode(self, client: int | None, raw: Any, deserialize: Callable[[bytes], Any]) -> Any:
        """The message in frame ``raw`` from page ``client`` as viser's ``deserialize`` makes
        it, or None (refused, with its reason): a binary frame holding a msgpack map whose
        type and every field pass :func:`field_problem` before viser reads it."""
        if not isinstance(raw, bytes):
            self.refuse(client, "a text frame (the console speaks binary messages only)")
            return None
        try:
            fields = msgspec.msgpack.decode(raw)
        except Exception as e:  # not msgpack
            self.refuse(client, f"an undecodable message ({type(e).__name__})")
            return None
        why = field_problem(fields)
        if why is not None:
            self.refuse(client, why)
            return None
        try:
            return deserialize(raw)
        except Exception as e:  # fields viser reads otherwise than checked here
            self.refuse(client, f"an undecodable {fields['type']} ({type(e).__name__})")
            return None

    def admit(self, client: int | None, message: Any) -> bool:
        """Whether viser may act on ``message`` (:meth:`decode`'s) from page ``client``
        (module docstring)."""
        with self._lock:
            page = self._pages.get(client) if client is not None else None
            if page is None:
                why = "a message from a socket that is not a page of the console"
            else:
                why = self._why_refused(page, message)
        if why is None:
            return True
        self.refuse(client, why)
        return False

    def _why_refused(self, page: _Page, message: Any) -> str | None:
        now = self.clock()
        tp = type(message)
        if tp is LocalStorageGetItemResponseMessage:
            seq = _heartbeat_seq(message.request_uuid)
            if seq is not None and page.link.answered(seq, now):  # before the rate limit:
                page.last_answer = now  # a busy page never loses its proof of life
                page.answers += 1
                if page.room is not None:
                    page.room.set()  # its telemetry may go on
                return "heartbeat"  # taken here; viser has nothing to do with it
        page.tokens = min(2 * MESSAGE_RATE, page.tokens + (now - page.refill) * MESSAGE_RATE)
        page.refill = now
        if page.tokens < 1.0:
            return f"over the message rate of {MESSAGE_RATE:g}/s"
        page.tokens -= 1.0
        if tp is ViewerCameraMessage:
            return None
        if tp is LocalStorageGetItemResponseMessage:
            return None if _heartbeat_seq(message.request_uuid) is None else \
                "an answer to no heartbeat request of the console"
        if tp is GuiUpdateMessage:
            rule = self._inputs.get(message.uuid) if isinstance(message.uuid, str) else None
            if rule is None:
                return f"an update of {_short(message.uuid)}, which is not an input of this page"
            updates = message.updates
            if not isinstance(updates, dict) or set(updates) != {"value"}:
                props = ", ".join(sorted(map(str, updates))) if isinstance(updates, dict) else repr(updates)
                return f"{rule.name}: only its value may change, not {_short(props)}"
            if rule.client != page.client:
                return f"{rule.name}: an input of another page"
            if rule.pilot_only and not self.is_pilot(page.client):
                return f"{rule.name}: only the pilot's page may use it"
            bad = rule.check(updates["value"])
            if bad is None:
                return None
            if rule.handle is not None:  # the page shows what it typed: show the value in force
                try:
                    viser_compat.show_value(rule.handle)
                except Exception:
                    log.debug("restoring %s failed", rule.name, exc_info=True)
            return f"{rule.name}: {bad}"
        if tp is CommandTriggerMessage:
            rule = self._commands.get(message.uuid) if isinstance(message.uuid, str) else None
            if rule is None or rule.client != page.client:
                return "a command that is not this page's"
            if rule.pilot_only and not self.is_pilot(page.client):
                return f"{rule.name}: only the pilot's page may use it"
            return None
        return f"a {tp.__name__}, which the console does not take"

    def take_urgent(self, client: int | None, message: Any) -> bool:
        """For an admitted message: whether it is a safety command (its rule has ``urgent``),
        now queued for the guard's safety thread; viser is not to see it then."""
        tp = type(message)
        table = self._inputs if tp is GuiUpdateMessage else self._commands if tp is CommandTriggerMessage \
            else None
        if table is None:
            return False
        with self._lock:
            rule = table.get(message.uuid)
        if rule is None or rule.urgent is None:
            return False
        self._urgent.put((client, rule.name, rule.urgent))
        return True

    def _run_urgent(self) -> None:
        while True:
            item = self._urgent.get()
            if item is None:
                return
            client, name, action = item
            try:
                action()
            except Exception:
                log.exception("the safety command %s of page %s failed", name, client)
            self.urgent_runs += 1

    def refuse(self, client: int | None, why: str) -> None:
        """Count and log (one line per burst of a page's refusals) a refused message."""
        if why == "heartbeat":
            return
        self.refusals.append((client, why))
        with self._lock:
            page = self._pages.get(client) if client is not None else None
            more = (page.refused if page is not None else self._strangers).note(self.clock())
        if more is not None:
            log.warning("refused from page %s: %s%s", client, why, _since(more))

    # ------------------------------------------------------------------ liveness (own thread)
    def silence_limit(self, client: int) -> float:
        """How long page ``client`` may go without answering before it is gone."""
        floor = 3.0 * self.heartbeat_period
        if self.is_pilot(client):
            return max(float(self.pilot_timeout()), floor)
        return max(self.page_timeout, floor)

    def _run(self) -> None:
        while not self._stop.wait(self.heartbeat_period):
            try:
                self.tick()
            except Exception:
                log.exception("page heartbeat failed")

    def tick(self) -> None:
        """Ask every page for a heartbeat; declare the ones silent too long gone."""
        now = self.clock()
        with self._lock:
            pages = [p for p in self._pages.values() if not p.gone]
        for p in pages:
            silent = now - p.last_answer
            if silent >= self.silence_limit(p.client):
                self.declare_gone(p.client, silent)
                continue
            self._send_soon(p, None)

    # ------------------------------------------------------------------ frames sent ahead
    def send_first(self, client: int, messages: Any) -> None:
        """Send ``messages`` to page ``client`` (any thread): the status bar, what the pilot
        must see first. While the page's link is slow, as a frame of their own ahead of its
        queued telemetry; otherwise in the page's next batch, as viser sends (a browser
        works per frame: no more frames than the link needs)."""
        with self._lock:
            page = self._pages.get(client)
        if page is None:
            return
        if page.link.slow or page.conn is None:
            self._send_soon(page, tuple(messages))
            return
        for m in messages:
            page.conn.queue_message(m)

    def _send_soon(self, page: _Page, messages: tuple[Any, ...] | None) -> None:
        loop = self.loop
        if loop is None or page.ws is None:
            return
        try:
            asyncio.run_coroutine_threadsafe(self._send(page, messages), loop)
        except RuntimeError:
            pass  # the server's loop has stopped

    async def _send(self, page: _Page, messages: tuple[Any, ...] | None) -> None:
        """(Event-loop thread.) One frame of ``messages`` (None: a heartbeat request) to
        ``page``, counted in its link before it is written."""
        if page.gone or self._pages.get(page.client) is not page:
            return
        now = self.clock()
        seq = None
        if messages is None:
            page.seq += 1
            seq = page.seq
            messages = (LocalStorageGetItemRequestMessage(key=HEARTBEAT_KEY, request_uuid=f"{_HB_PREFIX}{seq}"),)
        data = viser_compat.encode_frame(messages, self._zstd)
        page.link.sent(len(data), now)
        if seq is not None:
            page.link.probe(seq, now)
        try:
            await page.ws.send(data)  # written at once; then it waits for the socket to drain
        except Exception:
            log.debug("a frame to page %s was not sent", page.client, exc_info=True)

    # ------------------------------------------------------------------ telemetry flow (event loop)
    def flow(self, client: int) -> _Page | None:
        """The page whose telemetry :meth:`wait_room` and :meth:`sent` pace (None: not a page)."""
        with self._lock:
            return self._pages.get(client)

    async def wait_room(self, page: _Page) -> None:
        """Return when ``page`` may be sent more telemetry (its bytes in flight under its
        budget); while it may not, one heartbeat request is out to learn when it may."""
        link = page.link
        while not link.room(self.clock()) and not page.gone:
            if link.outstanding == 0:
                await self._send(page, None)
            if page.room is None:
                page.room = asyncio.Event()
            page.room.clear()
            if link.room(self.clock()):
                return
            await page.room.wait()

    def sent(self, page: _Page, nbytes: int) -> None:
        """``nbytes`` of telemetry are being written to ``page`` (event-loop thread)."""
        page.link.sent(nbytes, self.clock())

    def link_slow(self, client: int) -> bool:
        """Whether page ``client``'s telemetry is being thinned for its slow link."""
        with self._lock:
            page = self._pages.get(client)
        return page is not None and page.link.slow

    def link_state(self, client: int) -> dict[str, float] | None:
        """Page ``client``'s link: bytes in flight, budget, last round trip, slow (or None)."""
        with self._lock:
            page = self._pages.get(client)
        if page is None:
            return None
        link = page.link
        return {"in_flight": link.in_flight, "budget": link.budget, "rtt": link.rtt, "slow": link.slow,
                "sent": link.sent_bytes, "answers": link.answers}

    def declare_gone(self, client: int, silent_for: float) -> None:
        """Page ``client`` stopped answering: tell the console, then close its socket."""
        with self._lock:
            page = self._pages.get(client)
            if page is None or page.gone:
                return
            page.gone = True
        log.warning("page %s (%s) has not answered for %.1f s: treated as gone, its socket is closed",
                    client, page.address or "?", silent_for)
        try:
            self.on_gone(client, silent_for)
        finally:
            self.close(client)

    def close(self, client: int) -> None:
        """Drop page ``client``'s TCP connection at once (no closing handshake to wait for)."""
        with self._lock:
            page = self._pages.get(client)
        loop = self.loop
        if page is None or page.ws is None or loop is None:
            return
        try:
            loop.call_soon_threadsafe(page.ws.transport.abort)
        except RuntimeError:
            pass  # the server's loop has stopped


def _heartbeat_seq(uid: object) -> int | None:
    """The request number of a heartbeat request's uuid (None: not a heartbeat's)."""
    if isinstance(uid, str) and uid.startswith(_HB_PREFIX):
        tail = uid[len(_HB_PREFIX):]
        if tail.isdigit() and len(tail) < 19:
            return int(tail)
    return None


def _short(text: object, n: int = 60) -> str:
    s = str(text)
    return s if len(s) <= n else s[:n] + "..."


def _address(ws_conn: Any) -> str:
    try:
        addr = ws_conn.remote_address
    except Exception:
        return ""
    if isinstance(addr, tuple) and addr:
        return str(addr[0])
    return str(addr or "")
