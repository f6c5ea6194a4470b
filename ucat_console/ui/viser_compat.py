"""Every use of viser's private names in the console, each with the reason viser's public API
cannot do it (docs/viser-compat.md lists them with their figures and the upstream change
that would remove each).

Checked against the viser versions in :data:`ucat_console.backend.dependencies.SUPPORTED`
(:func:`install` checks the installed one first and refuses any other with a clear error).

Safety (the page guard, :mod:`ucat_console.ui.guard`; docs/pages.md, docs/safety.md):
viser has no hook for a websocket handshake, for its incoming messages or for pacing
what a page is sent, so :func:`install` replaces names in viser's websocket module
(``viser.infra._infra``), once for the process:

* the ``websockets`` serve call: for a server made by :func:`guarded_server`, every
  websocket upgrade goes through the guard's handshake check first (the Origin check),
  and frames are limited to :data:`ucat_console.ui.guard.MAX_FRAME` bytes. Every serve
  call viser makes while such a server starts gets the guard, including viser's retries
  on the next ports when the one asked for is taken (which ``PageGuard.serve`` then
  refuses);
* the per-connection message consumer: for such a server, every message is decoded here
  and handed to viser only when the guard admits it (per-input admission; an undecodable
  one is refused, not a traceback that closes the connection), and not at all when it is
  one of the pilot's safety commands, which the guard runs on its own thread
  (``PageGuard.take_urgent``);
* the per-page sender (:func:`_sending_producer`): for such a server, a page is sent
  telemetry only while its link has room (``PageGuard.wait_room``,
  :mod:`ucat_console.ui.link`), and a page on a slow link gets its batches in parts,
  thinned (:func:`_send_thinned`). :func:`encode_frame` makes the frames the guard sends
  ahead of the telemetry (heartbeat requests for liveness, the status bar), in viser's
  wire format, on the guard's own path.

Correctness: every message buffer's event is a :class:`_LoopEvent`, set only in the event
loop's thread: viser sets it from whichever thread queued a message, which races the loop
("deque mutated during iteration").

Performance (:data:`PATCHES`, each measured against viser's public path with ``ucat-console
bench ui --public-path NAME``; kept only where it buys >= 25 % of a figure an operator
sees, docs/viser-compat.md): see :data:`PATCHES`.

And the handles' and messages' private names the console needs (:func:`handle_uuid`,
:func:`show_value`, :func:`set_slider_marks`, :func:`run_javascript`, the guard's
accessors, :data:`PAGE_CLIENT` for the page script), each with its reason below.
"""

from __future__ import annotations

import asyncio
import itertools
import logging
import threading
import time
import types
import typing
from typing import Any, Iterable, Sequence

import msgspec
import numpy as np
import zstandard

import viser
import viser.infra._async_message_buffer as vbuffer
import viser.infra._infra as vinfra
import viser._messages as vm
import viser.infra._messages as vmessages
from websockets.exceptions import ConnectionClosed
from websockets.frames import CloseCode

try:
    import uvloop
except ImportError:  # no build for this platform (Windows): viser keeps asyncio's loop
    uvloop = None

from ucat_console.backend.dependencies import require

log = logging.getLogger(__name__)

#: The performance patches, each on unless :func:`use_public_path` turned it off before
#: :func:`install` (``ucat-console bench ui --public-path NAME`` measures viser's own path):
#: name -> what it replaces (docs/viser-compat.md: its measured figure and why it is kept).
PATCHES: dict[str, str] = {
    "uvloop": "viser's websocket thread on uvloop's event loop (viser: asyncio.new_event_loop)",
    "no_window_wait": "no 1/60 s wait for more messages after each batch (AsyncMessageBuffer's window), "
                      "and that window's wait made one turn of the loop (_window_delay)",
    "shared_frames": "pages in step are sent the same encoded frame of a broadcast batch "
                     "(viser encodes it once per page)",
    "wire_converter": "a message's wire form by a converter made once per message class (_wire_form) "
                      "instead of viser's as_serializable_dict",
    "fast_props": "the live view's poses and plot data set without viser's casts and comparisons "
                  "(set_pose, set_prop)",
}
_PUBLIC: set[str] = set()  # the patches turned off

#: the guard of the server being constructed (:func:`guarded_server`; under _PENDING_LOCK)
_PENDING: list[Any] = []
_PENDING_LOCK = threading.Lock()
_GUARDS: dict[Any, Any] = {}  # websockets Server -> its guard
_INSTALLED = False


def guarded_server(guard: Any, **kwargs: Any) -> viser.ViserServer:
    """A ViserServer (``kwargs`` as for viser) whose handshakes and messages ``guard`` checks.
    When the port asked for is taken, viser serves on the next free one: that server is
    guarded too (the caller checks the port it got: ``PageGuard.serve``)."""
    install()
    with _PENDING_LOCK:  # viser's serve calls happen inside the constructor, in viser's thread
        _PENDING.append(guard)
        try:
            server = viser.ViserServer(**kwargs)
        finally:
            _PENDING.remove(guard)
    # named for thread listings (``bench ui``): the thread of the pages' sockets
    thread = getattr(server._websock_server, "_server_thread", None)
    if thread is not None:
        thread.name = "viser-websocket"
    return server


def use_public_path(names: Iterable[str]) -> None:
    """Turn the performance patches ``names`` off (viser's own code runs instead), before
    :func:`install` (``bench ui --public-path``)."""
    names = set(names)
    unknown = names - set(PATCHES)
    if unknown:
        raise ValueError(f"no performance patch named {', '.join(sorted(unknown))}: "
                         f"they are {', '.join(PATCHES)}")
    if _INSTALLED and names != _PUBLIC:
        raise RuntimeError("viser's patches are installed already: choose the public path before")
    _PUBLIC.clear()
    _PUBLIC.update(names)


def patched(name: str) -> bool:
    """Whether the performance patch ``name`` is on."""
    return name not in _PUBLIC


def install() -> None:
    """Wrap viser's serve call, message consumer and sender once (idempotent), after
    checking the installed viser's version."""
    global _INSTALLED
    if _INSTALLED:
        return
    require("viser")
    real_ws = vinfra.websockets
    real_serve = real_ws.asyncio.server.serve
    real_consumer = vinfra._message_consumer

    def guarded_serve(handler: Any, host: Any, port: Any, **kwargs: Any) -> Any:
        # the same guard for each of viser's tries (the next port when one is taken)
        guard = _PENDING[-1] if _PENDING else None
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
    if uvloop is not None and patched("uvloop"):
        vinfra.asyncio = _ModuleView(asyncio, new_event_loop=uvloop.new_event_loop)
    vbuffer.AsyncMessageBuffer.__init__ = _with_loop_event(vbuffer.AsyncMessageBuffer.__init__)
    vinfra._message_producer = _sharing_producer
    if patched("no_window_wait"):
        vbuffer.asyncio = _ModuleView(asyncio, wait=_window_delay)
    _INSTALLED = True


def _with_loop_event(real_init: Any) -> Any:
    """``AsyncMessageBuffer.__init__`` with a :class:`_LoopEvent` for its message event, and
    a window duration of 0 (:data:`PATCHES` ``no_window_wait``)."""
    no_wait = patched("no_window_wait")

    def __init__(self: Any, *args: Any, **kwargs: Any) -> None:
        real_init(self, *args, **kwargs)
        if no_wait:
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
    forms = tuple(_form(m, arrays) for m in window)
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


def _form(message: Any, arrays: list[memoryview]) -> dict[str, Any]:
    """A message's wire form: :func:`_wire_form`, or viser's own with ``wire_converter`` off."""
    if patched("wire_converter"):
        return _wire_form(message, arrays)
    return message.as_serializable_dict(arrays)


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
    if buffer.persistent_messages and patched("shared_frames"):
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


# ---------------------------------------------------------------------- handles and messages
#
# viser's message classes live in its private ``viser._messages``; the console sends or
# checks these few, which viser's public API does not name:
#: a page's update of a GUI input (the guard admits it or not)
GuiUpdateMessage = vm.GuiUpdateMessage
#: a page's trigger of a registered command (the Esc key's DISARM)
CommandTriggerMessage = vm.CommandTriggerMessage
#: a page's camera (allowed through the guard)
ViewerCameraMessage = vm.ViewerCameraMessage
#: the heartbeat: a request only the page's running script answers, and its answer
LocalStorageGetItemRequestMessage = vm.LocalStorageGetItemRequestMessage
LocalStorageGetItemResponseMessage = vm.LocalStorageGetItemResponseMessage


def run_javascript(source: str) -> Any:
    """The message that runs ``source`` in a page (the status bar's script). viser sends it
    for its own plotly support but offers no public call to run a script in one page."""
    return vm.RunJavascriptMessage(source=source)


#: The page's own viser client, whose ``sendMessage`` the status bar's DISARM, theme and
#: gamepad use (:mod:`ucat_console.ui.page_script`): viser's page offers no public way for a
#: script to send a message. Checked by the browser tests (``tests/ui/test_browser*.py``).
PAGE_CLIENT = "window.__viserMutable"


def handle_uuid(handle: Any) -> str:
    """The id viser's messages name a GUI handle by (``_impl.uuid``): the guard's table of
    inputs a page may change, and the status bar's DISARM, are keyed by it; viser has no
    public name for it."""
    return handle._impl.uuid


def show_value(handle: Any) -> None:
    """Send an input's value in force to the pages again (``_queue_update``): a page whose
    update was refused shows what it typed until then, and viser's public ``handle.value =``
    sends nothing when the value is unchanged."""
    handle._queue_update("value", handle.value)


def set_slider_marks(slider: Any, times: Sequence[float]) -> None:
    """A slider's marks at ``times`` (unlabelled). viser takes marks only when the slider is
    made (``add_slider(marks=)``); its props field ``_marks`` takes new ones."""
    slider._marks = tuple(vm.GuiSliderMark(value=float(t), label=None) for t in times) or None


def event_loop(server: viser.ViserServer) -> asyncio.AbstractEventLoop:
    """The pages' event loop (viser's websocket thread's): the guard sends its frames ahead
    of the telemetry and paces it there. viser does not expose it."""
    return server._websock_server._background_event_loop


def on_socket_open(server: viser.ViserServer, callback: Any) -> None:
    """``callback(connection)`` when a page's websocket opens, before viser makes its client
    handle (so the guard knows every page, including one that never shows: liveness)."""
    server._websock_server.on_client_connect(callback)


def on_socket_close(server: viser.ViserServer, callback: Any) -> None:
    server._websock_server.on_client_disconnect(callback)


def page_socket(server: viser.ViserServer, client_id: int) -> Any:
    """The websockets connection of a page (its frames ahead of the telemetry, its address,
    closing a page that has gone silent): viser keeps it private."""
    return server._websock_server._live_connections.get(client_id)


def set_prop(handle: Any, name: str, value: Any) -> None:
    """``handle.<name> = value`` for a value the page takes as it is (arrays of float64
    or float32 for a plot's data, float32 for batched orientations), without viser's cast
    against the property's type hint and comparison with the last value (``fast_props``).
    The caller must not change ``value`` afterwards (viser serialises it later, in its own
    thread)."""
    if patched("fast_props"):
        setattr(handle._impl.props, name, value)
        handle._queue_update(name, value)
    else:
        setattr(handle, name, value)


def set_pose(node: Any, position: tuple[float, float, float], wxyz: tuple[float, float, float, float]) -> None:
    """``node.position = position; node.wxyz = wxyz`` (tuples of floats), without the
    casts and the comparisons with the last pose (``fast_props``)."""
    if not patched("fast_props"):
        node.position = position
        node.wxyz = wxyz
        return
    impl = node._impl
    impl.position[:] = position
    impl.wxyz[:] = wxyz
    queue = impl.api._queue_scene_message
    queue(vm.SetPositionMessage(impl.name, position))
    queue(vm.SetOrientationMessage(impl.name, wxyz))
