"""The places where the console hooks into viser: the page guard's, and those that save CPU.

viser has no hook for a websocket handshake check, for its incoming messages or for pacing
what a page is sent, so :func:`install` replaces names in viser's websocket module (once,
for the process):

* the ``websockets`` serve call: for a server made by :func:`guarded_server`, every
  websocket upgrade goes through the guard's handshake check first, and frames are
  limited to :data:`ucat_console.ui.guard.MAX_FRAME` bytes;
* the per-connection message consumer: for such a server, every message is decoded here
  and handed to viser only when the guard admits it (an undecodable one is refused, not
  a traceback that closes the connection), and not at all when it is one of the pilot's
  safety commands, which the guard runs on its own thread (``PageGuard.take_urgent``);
* the per-page sender (below): for such a server, a page is sent telemetry only while its
  link has room (``PageGuard.wait_room``, :mod:`ucat_console.ui.link`), and a page on a
  slow link gets its batches in parts, thinned (:func:`_send_thinned`). :func:`encode_frame` makes the
  frames the guard sends ahead of the telemetry (heartbeat requests, the status bar).

Servers made any other way are left exactly as viser makes them.

And viser's websocket thread runs on uvloop's event loop (libuv's, in C) instead of
asyncio's own: viser makes its loop with ``asyncio.new_event_loop()``, which :func:`install`
makes uvloop's for viser's websocket module only (the rest of the process keeps asyncio's
loops). With two pages that thread spends a good part of its time in the event loop itself
(its timers, wake-ups and socket writes, some 100 windows a second); ``ucat-console bench
ui`` measured the supervisor at 14 % of a core with asyncio's loop and 12 % with uvloop's,
in the same half hour. Where uvloop is not installed (it has no Windows build) viser keeps
asyncio's loop.

And viser's sender does not wait after a batch: after sending a page a batch, viser waits
1/60 s for more messages before it looks again (``window_duration_sec``, so that messages
queued one by one go out together). The console queues each pass of the live view and of
a review as one batch (``server.atomic()``), so for it that wait only costs a timer
wake-up per page and batch (about 100 a second with two pages) and up to 17 ms of a
pose's latency. :func:`install` makes every message buffer's window duration 0; with two
browser pages (``bench ui``) viser's websocket thread went from 5.6-6.1 % to 2.9-4.0 % of a
core and a pose's p95 latency from 76-104 to 57-73 ms. The window loop still waits for that
duration after each window and each wake-up (``asyncio.wait`` for a flush, with a timeout
of 0: a future, a timer and callbacks every time, about 250 times a second with two pages);
:func:`_window_delay` makes that wait the one turn of the event loop it amounts to.

And pages in step are sent one frame: a broadcast message goes to every page's sender, and
each used to encode the same window (each message's wire form, msgpack of them all,
compressed, with the arrays after it) for its own page, which with two pages was the
largest part of viser's websocket thread's CPU. :func:`install` replaces viser's sender
(``_message_producer``) with :func:`_sharing_producer`, the same loop that keeps the last
few frames of the broadcast buffer by the identity of their messages: a page whose window
holds the same messages as one just sent to another page is sent those bytes. A page that
lags behind gets a window of its own and encodes it; a page's own buffer is never shared.
The frame's ``timestampSec`` (the page paces its updates by it) is then the first page's.

And a frame's messages are put in their wire form by a converter made once per message
class (:func:`_wire_form`) instead of viser's per-value type dispatch: the same dicts and
arrays, checked against viser's own for every message a console session sends.

And (thread safety) every message buffer's event is a :class:`_LoopEvent`, set only in the
event loop's thread: viser set it from whichever thread queued a message, which raced the
loop ("deque mutated during iteration").
"""

from __future__ import annotations

import asyncio
import itertools
import threading
import time
import types
import typing
from typing import Any, Sequence

import msgspec
import numpy as np
import zstandard

import viser
import viser.infra._async_message_buffer as vbuffer
import viser.infra._infra as vinfra
import viser.infra._messages as vmessages
from websockets.exceptions import ConnectionClosed
from websockets.frames import CloseCode

try:
    import uvloop
except ImportError:  # no build for this platform (Windows): viser keeps asyncio's loop
    uvloop = None

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
            server = viser.ViserServer(**kwargs)
        finally:
            if guard in _PENDING:
                _PENDING.remove(guard)
    # named for thread listings (``bench ui``): the thread of the pages' sockets
    thread = getattr(server._websock_server, "_server_thread", None)
    if thread is not None:
        thread.name = "viser-websocket"
    return server


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
            if guard.admit(client, message) and not guard.take_urgent(client, message):
                handle_message(message)

    server_ns = types.SimpleNamespace(**{k: getattr(real_ws.asyncio.server, k)
                                         for k in dir(real_ws.asyncio.server) if not k.startswith("__")})
    server_ns.serve = guarded_serve
    asyncio_ns = types.SimpleNamespace(server=server_ns)
    vinfra.websockets = _ModuleView(real_ws, asyncio=asyncio_ns)
    vinfra._message_consumer = guarded_consumer
    if uvloop is not None:
        vinfra.asyncio = _ModuleView(asyncio, new_event_loop=uvloop.new_event_loop)
    vbuffer.AsyncMessageBuffer.__init__ = _without_window_wait(vbuffer.AsyncMessageBuffer.__init__)
    vinfra._message_producer = _sharing_producer
    vbuffer.asyncio = _ModuleView(asyncio, wait=_window_delay)
    _INSTALLED = True


def _without_window_wait(real_init: Any) -> Any:
    """``AsyncMessageBuffer.__init__`` with a window duration of 0 (module docstring), and
    a :class:`_LoopEvent` for its message event."""

    def __init__(self: Any, *args: Any, **kwargs: Any) -> None:
        real_init(self, *args, **kwargs)
        self.window_duration_sec = 0.0
        self.message_event = _LoopEvent(self.event_loop)

    return __init__


class _LoopEvent(asyncio.Event):
    """An ``asyncio.Event`` whose ``set()`` from another thread than its loop's does nothing.

    Why (thread safety): viser's ``AsyncMessageBuffer.push``, called from whichever thread
    updates the page (the live view's, a callback's), sets its ``message_event`` directly,
    then once more through ``call_soon_threadsafe``. ``asyncio.Event.set`` walks the event's
    deque of waiters and completes their futures, which is not thread-safe: when the loop's
    thread added or removed a waiter meanwhile, the pushing thread got "RuntimeError: deque
    mutated during iteration" (seen in the live view), and a future completed from another
    thread schedules its callbacks without waking the loop. Every such direct ``set()`` is
    followed by the loop-thread one (``push``, ``atomic_end``, ``set_done`` all schedule
    it), so dropping the direct one loses no wake-up; within the loop's thread ``set()`` is
    asyncio's own."""

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        super().__init__()
        self._home = loop

    def set(self) -> None:
        try:
            running = asyncio.get_running_loop()
        except RuntimeError:
            running = None
        if running is self._home:
            super().set()


async def _window_delay(fs: Any, *, timeout: float | None = None) -> tuple[set[Any], set[Any]]:
    """``asyncio.wait`` for viser's window loop, the only caller in its buffer module, which
    waits there for the window duration or a flush, whichever is first. With a window of
    0 (:func:`_without_window_wait`) that wait is one turn of the event loop: here a bare
    yield, without asyncio's timer, future and callbacks for each window (module docstring)."""
    if timeout != 0:
        return await asyncio.wait(fs, timeout=timeout)
    await asyncio.sleep(0)
    done = {f for f in fs if f.done()}
    return done, set(fs) - done


#: the frames each broadcast buffer keeps for its other pages' senders (the last few windows)
_KEPT_FRAMES = 4


def compressor() -> Any:
    """A compressor for :func:`encode_frame` (one per thread that encodes)."""
    return zstandard.ZstdCompressor(level=1)


def encode_frame(messages: Sequence[Any], zstd: Any) -> bytes:
    """``messages`` as one frame of viser's wire format (the page guard's frames sent ahead)."""
    return _frame(messages, zstd)


def _frame(window: Sequence[Any], zstd: Any) -> bytes:
    """A window of messages as viser's wire frame (``viser.infra._infra._message_producer``):
    zstd-compressed msgpack of the messages' wire forms, then their arrays, 8-byte aligned."""
    arrays: list[memoryview] = []
    forms = tuple(_wire_form(m, arrays) for m in window)
    inner = msgspec.msgpack.encode({
        "messages": forms,
        "timestampSec": time.perf_counter(),
        "binaryBufferLengths": tuple(b.nbytes for b in arrays),
    })
    compressed = zstd.compress(inner)
    parts: list[bytes | memoryview] = [len(inner).to_bytes(8, "little"), len(compressed).to_bytes(8, "little"),
                                       compressed]
    vinfra._append_aligned_buffers(parts, arrays, 16 + len(compressed))
    return b"".join(parts)


def _wire_form(message: Any, arrays: list[memoryview]) -> dict[str, Any]:
    """``message.as_serializable_dict(arrays)``: the same dict and the same arrays in the same
    order, by a converter made once per message class (:func:`_wire_converter`)."""
    convert = _CONVERTERS.get(type(message))
    if convert is None:
        convert = _CONVERTERS[type(message)] = _wire_converter(type(message))
    return convert(message, arrays)


_CONVERTERS: dict[type, Any] = {}


def _wire_converter(cls: type) -> Any:
    """A message class's wire form without viser's per-value type dispatch.

    viser's ``as_serializable_dict`` runs ``_prepare_for_serialization`` on every field and,
    recursively, on every value in it: a cascade of type checks per value, for the 40 poses
    and 60 plot updates a second the largest part of the frames' encoding. Here each field's
    conversion is chosen once from its type hint, and values of plain types (str, float,
    int, bool, None, tuple, list, dict, numpy array) are converted as viser converts them;
    any other value, or a value that does not fit its hint, goes to viser's own function."""
    hints = vmessages.get_type_hints_cached(cls)
    fields = tuple((name, _field_converter(hints[name])) for name in vmessages.wire_field_names(cls))
    type_name = cls.__name__

    def convert(message: Any, arrays: list[memoryview]) -> dict[str, Any]:
        out = {name: conv(getattr(message, name), arrays) for name, conv in fields}
        out["type"] = type_name
        return out

    return convert


def _field_converter(hint: Any) -> Any:
    prepare = vmessages._prepare_for_serialization
    args = typing.get_args(hint)
    if hint is str:
        def convert_str(v: Any, arrays: list[memoryview]) -> Any:
            return v if type(v) is str else prepare(v, hint, arrays)
        return convert_str
    if typing.get_origin(hint) is tuple and args and Ellipsis not in args and all(a is float for a in args):
        n = len(args)

        def convert_floats(v: Any, arrays: list[memoryview]) -> Any:
            if type(v) is tuple and len(v) == n:
                return tuple([float(x) for x in v])  # viser: float(x) for a float hint
            return prepare(v, hint, arrays)
        return convert_floats
    if typing.get_origin(hint) is dict:
        def convert_dict(v: Any, arrays: list[memoryview]) -> Any:
            if type(v) is dict:  # viser: each value as for an Any hint, whatever the dict's hint
                return {k: _any(x, arrays) for k, x in v.items()}
            return prepare(v, hint, arrays)
        return convert_dict
    if hint is Any:
        return _any
    return lambda v, arrays: prepare(v, hint, arrays)


_PLAIN = (str, float, int, bool, type(None))


def _any(v: Any, arrays: list[memoryview]) -> Any:
    """viser's ``_prepare_for_serialization(v, Any, arrays)`` for values of plain types."""
    t = type(v)
    if t in _PLAIN:
        return v
    if t is tuple:
        return tuple([_any(x, arrays) for x in v])
    if t is np.ndarray:
        arrays.append(v.data if v.flags.c_contiguous else v.copy().data)
        return {"__binary_index": len(arrays) - 1, "dtype": v.dtype.str}
    if t is list:
        return [_any(x, arrays) for x in v]
    if t is dict:
        return {k: _any(x, arrays) for k, x in v.items()}
    return vmessages._prepare_for_serialization(v, Any, arrays)


async def _sharing_producer(websocket: Any, buffer: Any, client_id: int, backlog_done_message: Any = None) -> None:
    """viser's per-page sender (``viser.infra._infra._message_producer``, 1.1.1), sending a
    window of the broadcast buffer that another page's sender has just sent as the same
    frame bytes (module docstring)."""
    window_generator = buffer.window_generator(client_id, backlog_done_message=backlog_done_message)
    zstd = zstandard.ZstdCompressor(level=1)
    # only the broadcast buffer (the persistent one) has more than one sender; its senders
    # all run in the server's one event-loop thread
    kept: dict[tuple[int, ...], tuple[Sequence[Any], bytes]] | None = None
    if buffer.persistent_messages:
        kept = buffer.__dict__.setdefault("_ucat_frames", {})
    # a guarded server's page is sent telemetry only while its link has room (the page
    # guard's "slow links"): the window is taken from the buffer only then, so what waits
    # meanwhile is coalesced by viser's buffer to the newest value of each property
    guard = _GUARDS.get(getattr(websocket, "server", None))
    page = guard.flow(client_id) if guard is not None else None
    last_sent: dict[str, int] = {}  # a large update's key -> when it last went (_send_thinned)
    try:
        while not buffer.done:
            if page is not None:
                await guard.wait_room(page)
            try:
                window = await window_generator.__anext__()
            except StopAsyncIteration:
                break
            if page is not None and page.link.split and len(window) > 1:
                await _send_thinned(websocket, buffer, guard, page, window, zstd, last_sent)
                continue
            if kept is None:
                data = _frame(window, zstd)
            else:
                # the key holds while the entry keeps the window's messages alive
                key = tuple(map(id, window))
                entry = kept.get(key)
                if entry is None:
                    data = _frame(window, zstd)
                    kept[key] = (window, data)
                    if len(kept) > _KEPT_FRAMES:
                        del kept[next(iter(kept))]
                else:
                    data = entry[1]
            if page is not None:
                guard.sent(page, len(data))
            await websocket.send(data)
    finally:
        # closed at once, as viser's own sender does: its finally releases the GC cursor
        await window_generator.aclose()


#: an update whose frame is over this many bytes goes after the small ones in a thinned batch
_SMALL_FRAME = 2048


async def _send_thinned(websocket: Any, buffer: Any, guard: Any, page: Any, window: Sequence[Any], zstd: Any,
                        last_sent: dict[str, int]) -> None:
    """A window for a page on a slow link, sent in parts, each only when the link has room,
    so that a heartbeat waits behind one part at most: the small messages (the robot's pose and fins) together, in
    their order, then the large updates (a plot's arrays) one by one, the one sent longest
    ago first, so that every plot gets its turn. An update a newer one has replaced in
    viser's buffer meanwhile is not sent (the newer one comes with the next window: the
    page gets the newest value, not every one). An update followed in the window by another
    message of its element keeps its place among the small ones."""
    frames = [(m, _frame((m,), zstd)) for m in window]
    keys = [m.entity_state_key() for m in window]
    parts: list[list[tuple[Any, bytes]]] = [[]]  # runs of small messages, and what must keep its place
    large: list[tuple[Any, bytes]] = []
    for k, (m, data) in enumerate(frames):
        if len(data) <= _SMALL_FRAME:
            parts[-1].append((m, data))
        elif _is_update(m) and (keys[k] is None or keys[k] not in keys[k + 1:]):
            large.append((m, data))
        else:
            parts += [[(m, data)], []]
    large.sort(key=lambda md: last_sent.get(md[0].redundancy_key(), -1))
    parts += [[md] for md in large]
    for part in parts:
        await guard.wait_room(page)
        live = [(m, d) for m, d in part if not _superseded(buffer, m)]
        if not live:
            continue
        data = live[0][1] if len(live) == 1 else _frame(tuple(m for m, _ in live), zstd)
        guard.sent(page, len(data))
        await websocket.send(data)
        if len(live) == 1 and len(data) > _SMALL_FRAME:
            last_sent[live[0][0].redundancy_key()] = next(_SENT_ORDER)


_SENT_ORDER = itertools.count()  # (event-loop thread)


def _is_update(message: Any) -> bool:
    return str(message.lifecycle_phase or "").startswith("update")


def _superseded(buffer: Any, message: Any) -> bool:
    """Whether viser's buffer holds a newer message of the same redundancy key (an update
    that replaced this one: viser's own coalescing, for a message already taken from it)."""
    if not _is_update(message):
        return False
    newest = buffer.id_from_redundancy_key.get(message.redundancy_key())
    return newest is not None and buffer.message_from_id.get(newest) is not message


class _ModuleView:
    """A module with some attributes replaced (the rest read from the module itself)."""

    def __init__(self, module: Any, **replaced: Any) -> None:
        self._module = module
        self._replaced = replaced

    def __getattr__(self, name: str) -> Any:
        if name in self._replaced:
            return self._replaced[name]
        return getattr(self._module, name)
