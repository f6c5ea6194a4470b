"""The live robot in Foxglove or Lichtblick: a read-only Foxglove WebSocket server.

:class:`FoxgloveServer` subscribes to a telemetry stream (the supervisor's, live) and
publishes it over the Foxglove WebSocket protocol with the channels, schemas and encoding
of a session file (:mod:`ucat_console.backend.sessions`): every telemetry channel as JSON
with its JSON Schema, and the derived Foxglove channels (transforms, the robot's scene,
the log), so a layout made for recordings (ucat_console/foxglove-layout.json) shows the live robot
unchanged. Message times are the file times a recording would give them (nanoseconds since
the UNIX epoch).

Read-only: the server advertises no capability but ``assets`` (no client publishing,
parameters or services), so Foxglove offers no control, and whatever else a client sends
is answered with an error status and ignored; it never touches the supervisor. Like the
console, it binds 127.0.0.1 unless told otherwise. The one thing a client may fetch is the
robot's URDF and its mesh (for the layout's URDF layer:
``package://ucat_description/urdf/ucat.urdf``, and the URI layouts saved before used); any
other URI gets nothing.

Origin: any web page open on the operator's computer may open a websocket to a port of
that computer, and its browser names the page's origin in the handshake. The server takes
a handshake without an ``Origin`` (a client that is not a browser), from ``file://``
(a desktop app's own pages: Lichtblick's, Foxglove's), from a page served by this machine
(``http(s)://localhost``, ``127.0.0.1`` or ``[::1]``, any port: a Lichtblick served
locally), or from an origin listed in ``[foxglove] allowed_origins`` (the Foxglove web
app: ``https://app.foxglove.dev``); any other, ``null`` included (what a sandboxed frame
sends), is refused with HTTP 403 and a log line (one per origin a minute)
(:func:`origin_allowed`).

The protocol is spoken here, on the ``websockets`` server the console's web server also
runs on, because foxglove-sdk's server (0.30) offers no way to check a handshake: the
subprotocol ``foxglove.sdk.v1`` (the Foxglove WebSocket protocol under its current name;
a client that offers only the old name ``foxglove.websocket.v1`` gets HTTP 400, as from
foxglove-sdk), ``serverInfo`` and ``advertise`` on connection, ``subscribe`` /
``unsubscribe``, message data (opcode 1: subscription id, log time, the JSON message) and
``fetchAsset`` (opcode 4 answers).

Messages go out in log-time order on every channel (:class:`foxglove.LogTimes`), as in a
session file.

The stream's callback only appends to a bounded queue; a sender thread encodes and frames
(only for channels someone subscribed to) and hands each client's frames to that client's
own bounded backlog, which the server's event loop writes out. A full queue or backlog
drops the oldest messages and counts them (logged): a slow client never slows the loop or
the other clients. The static transform and the scene are sent again every
``resend_period`` seconds, so a client that connects later gets them too.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import http
import ipaddress
import json
import logging
import math
import struct
import threading
import time
from typing import Any, Iterable
from urllib.parse import urlsplit

from websockets.asyncio.server import Server, ServerConnection, serve
from websockets.exceptions import ConnectionClosed

from ucat_console.backend.sessions import codec, foxglove, images
from ucat_console.backend.sessions.schema import (
    MESSAGE_ENCODING,
    SCHEMA_ENCODING,
    json_schema_bytes,
    schema_name,
)
from ucat_console.robot import urdf
from ucat_console.telemetry.channels import CHANNELS
from ucat_console.telemetry.stream import TelemetryStream

log = logging.getLogger(__name__)

DEFAULT_PORT = 8765  # the Foxglove apps' default for a WebSocket connection
SUBPROTOCOL = "foxglove.sdk.v1"
_IDLE_SLEEP = 0.005  # s, sender poll period when the queue is empty
_MESSAGE_DATA = struct.Struct("<BIQ")  # opcode 1, subscription id, log time (ns)
_ASSET_RESPONSE = struct.Struct("<BIBI")  # opcode 4, request id, status (0 ok, 1 error), error length
_MAX_CLIENT_MESSAGE = 64 * 1024  # B: a subscription to every channel is a few kilobytes
_U32 = 2**32
_LOG_ORIGIN_EVERY = 60.0  # s between log lines for refused handshakes from one origin
_CLOSE_TIMEOUT = 2.0  # s a client that stopped reading may hold up stop()


def robot_asset(uri: str) -> bytes | None:
    """The robot's URDF or mesh for a ``package://`` URI naming one; None for anything else
    (a client's URI is never turned into a path)."""
    path = urdf.package_file(uri)
    return path.read_bytes() if path is not None else None


def origin_allowed(origin: str | None, allowed: Iterable[str] = ()) -> bool:
    """Whether a handshake with this ``Origin`` may read the telemetry (module docstring):
    none, ``file://``, a loopback http(s) origin, or one of ``allowed`` (exact, ignoring case
    and a trailing ``/``)."""
    if origin is None:
        return True
    o = origin.strip().lower().rstrip("/")
    if o == "file:" or o in {a.strip().lower().rstrip("/") for a in allowed}:
        return True
    try:
        parts = urlsplit(o)
        parts.port  # noqa: B018 (a port that is not a number raises here)
    except ValueError:
        return False
    if parts.scheme not in ("http", "https") or parts.path or parts.query or parts.username is not None:
        return False
    host = parts.hostname or ""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class _Client:
    """One connected client: its subscriptions and its backlog of frames to send."""

    def __init__(self, ws: ServerConnection, loop: asyncio.AbstractEventLoop, backlog: int) -> None:
        self.ws = ws
        self.loop = loop
        #: channel id -> subscription id (replaced whole, read by the sender thread)
        self.subs: dict[int, int] = {}
        self.frames: collections.deque[bytes] = collections.deque(maxlen=backlog)
        self.dropped = 0
        self.wake = asyncio.Event()
        self._signalled = False

    def push(self, frame: bytes) -> None:
        """Queue a frame (the sender thread); the oldest goes when the backlog is full."""
        if len(self.frames) == self.frames.maxlen:
            self.dropped += 1
        self.frames.append(frame)
        if not self._signalled:
            self._signalled = True
            self.loop.call_soon_threadsafe(self.wake.set)

    async def write(self) -> None:
        """Send the backlog as it fills (the event loop), until the connection closes."""
        try:
            while True:
                await self.wake.wait()
                self.wake.clear()
                self._signalled = False
                while self.frames:
                    await self.ws.send(self.frames.popleft())
        except ConnectionClosed:
            pass


class FoxgloveServer:
    """A Foxglove WebSocket server publishing ``stream`` (``stop()`` or a context manager).

    ``epoch_offset`` (s) is added to the messages' ``t`` to make UNIX time, as for the
    recorder; ``geometry`` is the robot drawn in the 3-D panel. ``port`` 0 picks a free one
    (:attr:`port` tells which). ``allowed_origins``: the web origins besides this machine's
    whose pages may connect (:func:`origin_allowed`). ``backlog``: the frames waiting for one
    client before the oldest are dropped.
    """

    def __init__(
        self,
        stream: TelemetryStream,
        *,
        host: str = "127.0.0.1",
        port: int = DEFAULT_PORT,
        epoch_offset: float = 0.0,
        geometry: foxglove.RobotGeometry | None = None,
        queue_size: int = 10_000,
        resend_period: float = 1.0,
        allowed_origins: Iterable[str] = (),
        backlog: int = 1024,
    ) -> None:
        if not 0 <= port <= 65535:
            raise ValueError(f"--foxglove-port: {port} is not a port number (0-65535)")
        self.epoch_offset = float(epoch_offset)
        self.allowed_origins = tuple(allowed_origins)
        self._derived = foxglove.Derived(geometry or foxglove.robot_geometry())
        self._backlog = backlog
        self._channels: dict[str, dict[str, Any]] = {}  # topic -> its advertisement
        for topic, cls in CHANNELS.items():
            if images.is_image(cls):  # a Foxglove well-known message (sessions/images.py)
                self._advertise(topic, images.TYPES[cls], images.schema_bytes())
            else:
                self._advertise(topic, schema_name(cls), json_schema_bytes(cls))
        for topic, name in foxglove.DERIVED:
            self._advertise(topic, name, foxglove.official_schema_bytes(name))
        self._ids = {c["id"] for c in self._channels.values()}
        self._session_id = str(time.time_ns() // 1_000_000)
        self._clients: tuple[_Client, ...] = ()  # replaced whole (the event loop); read by the sender
        self._origin_logged: dict[str, float] = {}
        self.refused = 0  # handshakes refused for their origin
        self.host = host

        self._loop = asyncio.new_event_loop()
        self._loop_thread = threading.Thread(target=self._loop.run_forever, name="foxglove-ws", daemon=True)
        self._loop_thread.start()
        try:
            self._server: Server = asyncio.run_coroutine_threadsafe(self._listen(host, port), self._loop).result()
        except Exception as e:  # the address is taken or cannot be bound
            self._end_loop()
            raise ValueError(f"--foxglove-port: cannot listen on {host}:{port} ({e})") from None
        self._port = self._server.sockets[0].getsockname()[1]

        self._log_time = foxglove.LogTimes()
        self._queue: collections.deque = collections.deque(maxlen=queue_size)
        self._dropped = 0  # the stream's queue full (the publisher's thread)
        self._dropped_gone = 0  # the backlogs of clients gone (the event loop)
        self.sent = 0
        self._resend_period = resend_period
        self._stopping = False
        self._last_ns = codec.to_ns(time.time())
        self._unsubscribe = stream.subscribe(self._on_message)
        self._thread = threading.Thread(target=self._run, name="foxglove-server", daemon=True)
        self._thread.start()
        log.info("Foxglove server on %s", self.url)

    def _advertise(self, topic: str, name: str, schema: bytes) -> None:
        self._channels[topic] = {
            "id": len(self._channels) + 1, "topic": topic, "encoding": MESSAGE_ENCODING,
            "schemaName": name, "schemaEncoding": SCHEMA_ENCODING, "schema": schema.decode(),
        }

    # ------------------------------------------------------------------ properties
    @property
    def port(self) -> int:
        return self._port

    @property
    def url(self) -> str:
        """The WebSocket address to open in Foxglove or Lichtblick."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"ws://{host}:{self.port}"

    @property
    def dropped(self) -> int:
        """Messages dropped: the stream's queue full, or a client's backlog."""
        return self._dropped + self._dropped_gone + sum(c.dropped for c in self._clients)

    # ------------------------------------------------------------------ lifecycle
    def stop(self) -> None:
        """Stop publishing, close the connections and the server (idempotent)."""
        if self._stopping:
            return
        self._stopping = True
        self._unsubscribe()
        self._thread.join()
        dropped = self.dropped
        try:
            asyncio.run_coroutine_threadsafe(self._close(), self._loop).result(timeout=30.0)
        finally:
            self._end_loop()
        if dropped:
            log.warning("Foxglove server: %d messages dropped (clients too slow)", dropped)

    def __enter__(self) -> FoxgloveServer:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.stop()

    def _end_loop(self) -> None:
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._loop_thread.join()
        self._loop.close()

    # ------------------------------------------------------------------ the event loop
    async def _listen(self, host: str, port: int) -> Server:
        return await serve(self._session, host, port, subprotocols=[SUBPROTOCOL],  # type: ignore[list-item]
                           process_request=self._handshake, compression=None,
                           max_size=_MAX_CLIENT_MESSAGE, server_header=None, close_timeout=_CLOSE_TIMEOUT)

    async def _close(self) -> None:
        self._server.close()
        await self._server.wait_closed()

    def _handshake(self, connection: ServerConnection, request: Any) -> Any:
        """None to go on with a websocket upgrade, else the 403 response refusing its origin."""
        origin = request.headers.get("Origin")
        if origin_allowed(origin, self.allowed_origins):
            return None
        self.refused += 1
        now = time.monotonic()
        if now - self._origin_logged.get(origin, -math.inf) >= _LOG_ORIGIN_EVERY:
            if len(self._origin_logged) > 1000:
                self._origin_logged.clear()
            self._origin_logged[origin] = now
            log.warning("Foxglove server: refused a connection from Origin %r (remote %s): not this "
                        "machine's; add it to foxglove.allowed_origins to let its pages read the telemetry",
                        codec.short(origin), connection.remote_address)
        return connection.respond(http.HTTPStatus.FORBIDDEN,
                                  "Forbidden: pages of this origin may not read the telemetry\n")

    async def _session(self, ws: ServerConnection) -> None:
        client = _Client(ws, self._loop, self._backlog)
        writer = asyncio.create_task(client.write())
        try:
            await ws.send(json.dumps({"op": "serverInfo", "name": "ucat-console", "capabilities": ["assets"],
                                      "metadata": {}, "sessionId": self._session_id}))
            await ws.send(json.dumps({"op": "advertise", "channels": list(self._channels.values())}))
            self._clients = (*self._clients, client)
            async for message in ws:
                answer = self._answer(client, message)
                if answer is not None:
                    await ws.send(answer)
        except ConnectionClosed:
            pass
        finally:
            self._clients = tuple(c for c in self._clients if c is not client)
            self._dropped_gone += client.dropped
            writer.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await writer

    def _answer(self, client: _Client, message: str | bytes) -> str | bytes | None:
        """Act on a client's message; what to send back (an error status, an asset)."""
        if isinstance(message, bytes):
            return _status("binary messages are not taken: the server is read-only")
        try:
            m = json.loads(message)
            op = m["op"]
            if op == "subscribe":
                self._subscribe(client, m["subscriptions"])
            elif op == "unsubscribe":
                gone = set(m["subscriptionIds"])
                client.subs = {c: s for c, s in client.subs.items() if s not in gone}
            elif op == "fetchAsset":
                return self._asset(m["uri"], m["requestId"])
            else:
                return _status(f"{codec.short(op)}: not taken, the server is read-only")
        except (ValueError, KeyError, TypeError) as e:
            return _status(f"invalid message: {type(e).__name__}: {codec.short(str(e))}")
        return None

    def _subscribe(self, client: _Client, subscriptions: list[dict[str, int]]) -> None:
        subs = dict(client.subs)
        for s in subscriptions:
            sid, cid = s["id"], s["channelId"]
            if not isinstance(sid, int) or not 0 <= sid < _U32 or cid not in self._ids:
                raise ValueError(f"subscription {codec.short(s)}: no such channel, or a bad id")
            subs[cid] = sid
        client.subs = subs

    def _asset(self, uri: object, request_id: object) -> bytes:
        if not isinstance(request_id, int) or not 0 <= request_id < _U32:
            raise ValueError(f"requestId {codec.short(request_id)}: not a 32-bit id")
        data = robot_asset(uri) if isinstance(uri, str) else None
        error = b"" if data is not None else b"not found"
        return _ASSET_RESPONSE.pack(4, request_id, 0 if data is not None else 1, len(error)) + error + (data or b"")

    # ------------------------------------------------------------------ publisher side
    def _on_message(self, channel: str, msg: Any) -> None:
        q = self._queue
        if len(q) == q.maxlen:
            self._dropped += 1
        q.append((channel, msg))

    # ------------------------------------------------------------------ sender thread
    def _send(self, topic: str, data: bytes | Any, ns: int) -> None:
        """Frame ``data`` (bytes, or the message to encode) for every client subscribed to ``topic``."""
        cid = self._channels[topic]["id"]
        targets = [(c, sid) for c in self._clients if (sid := c.subs.get(cid)) is not None]
        if not targets:
            return
        if images.is_image(type(data)):
            data = images.encode(data, ns)
        elif not isinstance(data, bytes):
            data = codec.encode(data)
        log_time = self._log_time(topic, ns)
        for c, sid in targets:
            c.push(_MESSAGE_DATA.pack(1, sid, log_time) + data)
        self.sent += 1

    def _run(self) -> None:
        popleft = self._queue.popleft
        next_resend = 0.0
        while not self._stopping:
            now = time.monotonic()
            if now >= next_resend:
                next_resend = now + self._resend_period
                for topic, data in self._derived.opening(self._last_ns):
                    self._send(topic, data, self._last_ns)
            try:
                channel, msg = popleft()
            except IndexError:
                time.sleep(_IDLE_SLEEP)
                continue
            try:
                self._publish(channel, msg)
            except Exception:  # a message that cannot be encoded: the recorder counts those
                log.exception("Foxglove server: cannot send a %s message", channel)

    def _publish(self, channel: str, msg: Any) -> None:
        t = msg.t
        if isinstance(t, (int, float)) and math.isfinite(t):
            self._last_ns = codec.to_ns(t, self.epoch_offset)
        ns = self._last_ns  # no usable time: the last one seen, as the recorder does
        self._send(channel, msg, ns)
        for topic, data in self._derived.derive(channel, msg, ns):
            self._send(topic, data, ns)


def _status(message: str) -> str:
    """A status message of level error."""
    return json.dumps({"op": "status", "level": 2, "message": message})
