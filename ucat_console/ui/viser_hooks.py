"""The two places where the console's page guard is hooked into viser.

viser has no hook for a websocket handshake check or for its incoming messages, so
:func:`install` replaces two names in viser's websocket module (once, for the process):

* the ``websockets`` serve call: for a server made by :func:`guarded_server`, every
  websocket upgrade goes through the guard's handshake check first, and frames are
  limited to :data:`ucat_console.ui.guard.MAX_FRAME` bytes;
* the per-connection message consumer: for such a server, every message is decoded here
  and handed to viser only when the guard admits it (an undecodable one is refused, not
  a traceback that closes the connection).

Servers made any other way are left exactly as viser makes them.
"""

from __future__ import annotations

import threading
import types
from typing import Any

import viser
import viser.infra._infra as vinfra
from websockets.exceptions import ConnectionClosed
from websockets.frames import CloseCode

_PENDING: list[Any] = []
_PENDING_LOCK = threading.Lock()
_GUARDS: dict[Any, Any] = {}  # websockets Server -> its guard
_INSTALLED = False


def guarded_server(guard: Any, **kwargs: Any) -> viser.ViserServer:
    """A ViserServer (``kwargs`` as for viser) whose handshakes and messages ``guard`` checks."""
    install()
    with _PENDING_LOCK:  # the serve call happens inside the constructor, in viser's thread
        _PENDING.append(guard)
        try:
            return viser.ViserServer(**kwargs)
        finally:
            if guard in _PENDING:
                _PENDING.remove(guard)


def install() -> None:
    """Wrap viser's serve call and message consumer once (idempotent)."""
    global _INSTALLED
    if _INSTALLED:
        return
    real_ws = vinfra.websockets
    real_serve = real_ws.asyncio.server.serve
    real_consumer = vinfra._message_consumer

    def guarded_serve(handler: Any, host: Any, port: Any, **kwargs: Any) -> Any:
        guard = _PENDING.pop() if _PENDING else None
        if guard is None:
            return real_serve(handler, host, port, **kwargs)
        http = kwargs.get("process_request")

        def process_request(connection: Any, request: Any) -> Any:
            if request.headers.get("Upgrade", "").lower() == "websocket":
                refusal = guard.handshake_refusal(connection, request)
                if refusal is not None:
                    return refusal
            return http(connection, request) if http is not None else None

        kwargs["process_request"] = process_request
        kwargs["max_size"] = guard.max_frame
        serving = real_serve(handler, host, port, **kwargs)
        _GUARDS[serving.server] = guard
        return serving

    async def guarded_consumer(websocket: Any, handle_message: Any, message_class: Any) -> None:
        guard = _GUARDS.get(getattr(websocket, "server", None))
        if guard is None:
            return await real_consumer(websocket, handle_message, message_class)
        while True:
            try:
                raw = await websocket.recv()
            except ConnectionClosed as e:
                if e.sent is not None and e.sent.code == CloseCode.MESSAGE_TOO_BIG:
                    guard.refuse(guard.client_of(websocket),
                                 f"a frame over the limit of {guard.max_frame} bytes: its socket is closed")
                raise
            client = guard.client_of(websocket)
            if not isinstance(raw, bytes):
                guard.refuse(client, "a text frame (the console speaks binary messages only)")
                continue
            try:
                message = message_class.deserialize(raw)
            except Exception as e:  # not a viser message
                guard.refuse(client, f"an undecodable message ({type(e).__name__})")
                continue
            if guard.admit(client, message):
                handle_message(message)

    server_ns = types.SimpleNamespace(**{k: getattr(real_ws.asyncio.server, k)
                                         for k in dir(real_ws.asyncio.server) if not k.startswith("__")})
    server_ns.serve = guarded_serve
    asyncio_ns = types.SimpleNamespace(server=server_ns)
    vinfra.websockets = _ModuleView(real_ws, asyncio=asyncio_ns)
    vinfra._message_consumer = guarded_consumer
    _INSTALLED = True


class _ModuleView:
    """A module with some attributes replaced (the rest read from the module itself)."""

    def __init__(self, module: Any, **replaced: Any) -> None:
        self._module = module
        self._replaced = replaced

    def __getattr__(self, name: str) -> Any:
        if name in self._replaced:
            return self._replaced[name]
        return getattr(self._module, name)
