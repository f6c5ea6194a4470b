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
* the page itself: ``/`` is served from :mod:`ucat_console.ui.page_client` (viser's client
  with its reconnection patched: back-off retries that never close a handshake in
  progress), not viser's file;
* the per-page sender (:func:`_pacing_producer`): for such a server, a page is sent
  telemetry only while its link has room (``PageGuard.wait_room``,
  :mod:`ucat_console.ui.link`), and a page on a slow link gets its batches in parts,
  thinned (:func:`_send_thinned`). :func:`encode_frame` makes the frames the guard sends
  ahead of the telemetry (heartbeat requests for liveness, the status bar), in viser's
  wire format, on the guard's own path.

Correctness: every message buffer's event is a :class:`_LoopEvent`, set only in the event
loop's thread: viser sets it from whichever thread queued a message, which races the loop
("deque mutated during iteration").

No patch for speed: each one the console had (uvloop's event loop, no window wait after a
batch, one encoding of a broadcast batch for all pages, a per-class wire-form converter,
setting the live view's properties without viser's casts) was measured against viser's
public path with ``ucat-console bench ui`` and bought no figure an operator sees by 25 %
(docs/viser-compat.md); the live view flushes viser's buffer after each pass instead
(public ``ViserServer.flush``).

And the handles' and messages' private names the console needs (:func:`handle_uuid`,
:func:`show_value`, :func:`set_slider_marks`, :func:`set_plot_data`, :func:`run_javascript`, the guard's
accessors, :data:`PAGE_CLIENT` for the page script), each with its reason below.
"""

from __future__ import annotations

import asyncio
import itertools
import threading
import time
import types
from typing import Any, Sequence

import msgspec
import zstandard

import viser
import viser.infra._async_message_buffer as vbuffer
import viser.infra._infra as vinfra
import viser._messages as vm
from websockets.datastructures import Headers
from websockets.exceptions import ConnectionClosed
from websockets.http11 import Response
from websockets.frames import CloseCode

from ucat_console.backend.dependencies import require
from ucat_console.ui import page_client

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
    page_client.index_bytes()  # made before the first page asks for it (and checked: PageClientChanged)
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
        # the same guard for each of viser's tries (the next port when one is taken); a plain
        # ViserServer another thread starts meanwhile would be guarded too (the safe side)
        guard = _PENDING[-1] if _PENDING else None
        if guard is None:
            return real_serve(handler, host, port, **kwargs)
        http = kwargs.get("process_request")

        def process_request(connection: Any, request: Any) -> Any:
            if request.headers.get("Upgrade", "").lower() == "websocket":
                refusal = guard.handshake_refusal(connection, request)
                if refusal is not None:
                    return refusal
            elif request.path.partition("?")[0] in ("/", "/index.html"):
                return _page_response()
            return http(connection, request) if http is not None else None

        async def guarded_handler(connection: Any) -> None:
            refusal = guard.connection_refusal(connection)
            if refusal is not None:  # before viser makes anything of the connection
                await connection.close(CloseCode.TRY_AGAIN_LATER, refusal)
                return
            try:
                await handler(connection)
            finally:
                guard.connection_closed(connection)

        kwargs["process_request"] = process_request
        kwargs["max_size"] = guard.max_frame
        serving = real_serve(guarded_handler, host, port, **kwargs)
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
            message = guard.decode(client, raw, message_class.deserialize)
            if message is not None and guard.admit(client, message) and not guard.take_urgent(client, message):
                handle_message(message)

    server_ns = types.SimpleNamespace(**{k: getattr(real_ws.asyncio.server, k)
                                         for k in dir(real_ws.asyncio.server) if not k.startswith("__")})
    server_ns.serve = guarded_serve
    asyncio_ns = types.SimpleNamespace(server=server_ns)
    vinfra.websockets = _ModuleView(real_ws, asyncio=asyncio_ns)
    vinfra._message_consumer = guarded_consumer
    vbuffer.AsyncMessageBuffer.__init__ = _with_loop_event(vbuffer.AsyncMessageBuffer.__init__)
    vinfra._message_producer = _pacing_producer
    _INSTALLED = True


def _with_loop_event(real_init: Any) -> Any:
    """``AsyncMessageBuffer.__init__`` with a :class:`_LoopEvent` for its message event."""

    def __init__(self: Any, *args: Any, **kwargs: Any) -> None:
        real_init(self, *args, **kwargs)
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


def compressor() -> Any:
    """A compressor for :func:`encode_frame` (one per thread that encodes)."""
    return zstandard.ZstdCompressor(level=1)


def encode_frame(messages: Sequence[Any], zstd: Any) -> bytes:
    """``messages`` as one frame of viser's wire format (the page guard's frames sent ahead)."""
    return _frame(messages, zstd)


def _frame(window: Sequence[Any], zstd: Any) -> bytes:
    """A window of messages as viser's wire frame (``viser.infra._infra._message_producer``):
    zstd-compressed msgpack of the messages' wire forms (viser's ``as_serializable_dict``),
    then their arrays, 8-byte aligned. viser has no public call that encodes a frame: the
    guard sends its frames (heartbeat requests, the status bar) ahead of the page's queue,
    and the sender below paces the page's windows, so both encode them here."""
    arrays: list[Any] = []
    forms = tuple(m.as_serializable_dict(arrays) for m in window)
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


async def _pacing_producer(websocket: Any, buffer: Any, client_id: int, backlog_done_message: Any = None) -> None:
    """viser's per-page sender (``viser.infra._infra._message_producer``, 1.1.1) for a
    guarded server's page: a window is taken from viser's buffer only while the page's link
    has room (the page guard's "slow links"), so what waits meanwhile is coalesced by
    viser's buffer to the newest value of each property; a page on a slow link gets its
    windows in parts (:func:`_send_thinned`). A page of any other server gets viser's own."""
    guard = _GUARDS.get(getattr(websocket, "server", None))
    page = guard.flow(client_id) if guard is not None else None
    if page is None:  # not a guarded server's, or a page its guard does not follow
        return await _VISER_PRODUCER(websocket, buffer, client_id, backlog_done_message)
    window_generator = buffer.window_generator(client_id, backlog_done_message=backlog_done_message)
    zstd = zstandard.ZstdCompressor(level=1)
    last_sent: dict[str, int] = {}  # a large update's key -> when it last went (_send_thinned)
    try:
        while not buffer.done:
            await guard.wait_room(page)
            try:
                window = await window_generator.__anext__()
            except StopAsyncIteration:
                break
            if page.link.split and len(window) > 1:
                await _send_thinned(websocket, buffer, guard, page, window, zstd, last_sent)
                continue
            data = _frame(window, zstd)
            guard.sent(page, len(data))
            await websocket.send(data)
    finally:
        # closed at once, as viser's own sender does: its finally releases the GC cursor
        await window_generator.aclose()


_VISER_PRODUCER = vinfra._message_producer


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


def _page_response() -> Response:
    """The page (viser's client with the console's patch of its reconnection,
    :mod:`ucat_console.ui.page_client`), in place of the file viser would serve for ``/``."""
    body = page_client.index_bytes()
    headers = Headers({"Content-Type": "text/html; charset=utf-8", "Content-Length": str(len(body)),
                       "Cache-Control": "no-store"})
    return Response(200, "OK", headers, body)


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


def release_page_elements(client: Any, containers: Sequence[Any]) -> None:
    """Unhook a gone page's elements from the shared ``containers`` they were added to (its
    controls in the shared tabs), so that nothing of the page stays: viser does it when the
    page disconnects (``_release_cross_scope_nesting``, from its record of such elements),
    but not for the elements of a page built while it went, and it misses an element it
    unhooks while the element is being made (a folder adds itself to its container a second
    time at the end of its constructor): such an element, and the page's handle with it,
    would stay in the shared tab for as long as the console runs. viser has no public call
    for it (``gui.reset()`` removes only what sits in the page's own root), hence its
    record and the containers' ``_children``. Nothing is sent."""
    gui = client.gui
    gui._release_cross_scope_nesting()
    for container in containers:
        for uuid, handle in list(container._children.items()):
            if getattr(getattr(handle, "_impl", None), "gui_api", None) is gui:
                gui._tombstone_subtree(handle)
                container._children.pop(uuid, None)


def page_socket(server: viser.ViserServer, client_id: int) -> Any:
    """The websockets connection of a page (its frames ahead of the telemetry, its address,
    closing a page that has gone silent): viser keeps it private."""
    return server._websock_server._live_connections.get(client_id)


def set_plot_data(chart: Any, data: tuple[Any, ...]) -> None:
    """``chart.data = data`` for a uPlot chart, with the arrays sent as they are: viser's
    assignment casts every array to float64 (its props' type hint), which doubles the bytes
    of the plots' values the console keeps in float32 (the time axis is float64), and the
    plots are most of what a page on a slow link is sent (docs/pages.md). viser has no public
    way to set a property without its cast. The caller must not change the arrays afterwards
    (viser serialises them later, in its own thread)."""
    chart._impl.props.data = data
    chart._queue_update("data", data)
