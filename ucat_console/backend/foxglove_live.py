"""The live robot in Foxglove or Lichtblick: a read-only Foxglove WebSocket server.

:class:`FoxgloveServer` subscribes to a telemetry stream (the supervisor's, live) and
publishes it over the Foxglove WebSocket protocol with the channels, schemas and encoding
of a session file (:mod:`ucat_console.backend.sessions`): every telemetry channel as JSON
with its JSON Schema, and the derived Foxglove channels (transforms, the robot's scene,
the log), so a layout made for recordings (ucat_console/foxglove-layout.json) shows the live robot
unchanged. Message times are the file times a recording would give them (nanoseconds since
the UNIX epoch).

Read-only: the server advertises no capability (no client publishing, parameters or
services), so Foxglove offers no control, and whatever a client sends is ignored; it never
touches the supervisor. Like the console, it binds 127.0.0.1 unless told otherwise. The one
thing a client may fetch is the robot's URDF and its mesh (the SDK's asset handler, for
the layout's URDF layer: ``package://ucat_console/robot/urdf/ucat.urdf``); any other URI
gets nothing.

Messages go out in log-time order on every channel (:class:`foxglove.LogTimes`), as in a
session file.

Subprotocol: the SDK's server speaks ``foxglove.sdk.v1`` (the Foxglove WebSocket protocol
under its new name) and offers no way to also accept the older name
``foxglove.websocket.v1`` (``start_server`` has no subprotocol option in foxglove-sdk 0.30),
so a client that asks for ``foxglove.websocket.v1`` only (Lichtblick releases from before
it learnt the new name) gets HTTP 400; Foxglove and current Lichtblick releases connect.

The stream's callback only appends to a bounded queue; a sender thread encodes and sends
(only for channels someone subscribed to). A full queue drops the oldest messages and
counts them (logged): a slow client never slows the loop. The static transform and the
scene are sent again every ``resend_period`` seconds, so a client that connects later gets
them too.

Uses the ``foxglove-sdk`` package (the ``foxglove`` extra: ``pip install
'ucat-console[foxglove]'``).
"""

from __future__ import annotations

import collections
import logging
import math
import threading
import time
from typing import Any

from ucat_console.backend.sessions import codec, foxglove
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
_IDLE_SLEEP = 0.005  # s, sender poll period when the queue is empty


def _sdk() -> Any:
    try:
        import foxglove as sdk
    except ImportError:
        raise ValueError(
            "--foxglove-port: the Foxglove server needs the package foxglove-sdk "
            "(pip install 'ucat-console[foxglove]')"
        ) from None
    return sdk


def robot_asset(uri: str) -> bytes | None:
    """The robot's URDF or mesh for a ``package://`` URI naming one; None for anything else
    (a client's URI is never turned into a path)."""
    path = urdf.package_file(uri)
    return path.read_bytes() if path is not None else None


class FoxgloveServer:
    """A Foxglove WebSocket server publishing ``stream`` (``stop()`` or a context manager).

    ``epoch_offset`` (s) is added to the messages' ``t`` to make UNIX time, as for the
    recorder; ``geometry`` is the robot drawn in the 3-D panel. ``port`` 0 picks a free one
    (:attr:`port` tells which).
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
    ) -> None:
        sdk = _sdk()
        if not 0 <= port <= 65535:
            raise ValueError(f"--foxglove-port: {port} is not a port number (0-65535)")
        self.epoch_offset = float(epoch_offset)
        self._derived = foxglove.Derived(geometry or foxglove.robot_geometry())
        self._context = sdk.Context()
        try:
            self._server = sdk.start_server(
                name="ucat-console", host=host, port=port, context=self._context,
                capabilities=[],  # read-only: no publishing, parameters or services
                asset_handler=robot_asset,
            )
        except Exception as e:  # the address is taken or cannot be bound
            raise ValueError(f"--foxglove-port: cannot listen on {host}:{port} ({e})") from None
        self.host = host
        self._channels: dict[str, Any] = {}
        try:
            schemas = {cls: sdk.Schema(name=schema_name(cls), encoding=SCHEMA_ENCODING,
                                       data=json_schema_bytes(cls))
                       for cls in set(CHANNELS.values())}
            for topic, cls in CHANNELS.items():
                self._channels[topic] = sdk.Channel(
                    topic, schema=schemas[cls], message_encoding=MESSAGE_ENCODING,
                    context=self._context)
            for topic, name in foxglove.DERIVED:
                self._channels[topic] = sdk.Channel(
                    topic, schema=sdk.Schema(name=name, encoding=SCHEMA_ENCODING,
                                             data=foxglove.official_schema_bytes(name)),
                    message_encoding=MESSAGE_ENCODING, context=self._context)
        except BaseException:
            self._server.stop()
            raise
        self._log_time = foxglove.LogTimes()
        self._queue: collections.deque = collections.deque(maxlen=queue_size)
        self.dropped = 0
        self.sent = 0
        self._resend_period = resend_period
        self._stopping = False
        self._last_ns = codec.to_ns(time.time())
        self._unsubscribe = stream.subscribe(self._on_message)
        self._thread = threading.Thread(target=self._run, name="foxglove-server", daemon=True)
        self._thread.start()
        log.info("Foxglove server on %s", self.url)

    # ------------------------------------------------------------------ properties
    @property
    def port(self) -> int:
        return self._server.port

    @property
    def url(self) -> str:
        """The WebSocket address to open in Foxglove or Lichtblick."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"ws://{host}:{self.port}"

    @property
    def app_url(self) -> str:
        """The Foxglove web app's address that opens this server."""
        return self._server.app_url() or ""

    # ------------------------------------------------------------------ lifecycle
    def stop(self) -> None:
        """Stop publishing, close the server (idempotent)."""
        if self._stopping:
            return
        self._stopping = True
        self._unsubscribe()
        self._thread.join()
        for channel in self._channels.values():
            channel.close()
        self._server.stop()
        if self.dropped:
            log.warning("Foxglove server: %d messages dropped (clients too slow)", self.dropped)

    def __enter__(self) -> FoxgloveServer:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.stop()

    # ------------------------------------------------------------------ publisher side
    def _on_message(self, channel: str, msg: Any) -> None:
        q = self._queue
        if len(q) == q.maxlen:
            self.dropped += 1
        q.append((channel, msg))

    # ------------------------------------------------------------------ sender thread
    def _send(self, topic: str, data: bytes, ns: int) -> None:
        self._channels[topic].log(data, log_time=self._log_time(topic, ns))
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
        out = self._channels[channel]
        if out.has_sinks():
            self._send(channel, codec.encode(msg), ns)
        for topic, data in self._derived.derive(channel, msg, ns):
            if self._channels[topic].has_sinks():
                self._send(topic, data, ns)
