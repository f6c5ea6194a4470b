"""viser's senders as :mod:`ucat_console.ui.viser_compat` makes them: every page still
receives exactly the messages and arrays the server sent (pages in step sharing frames, a
page joining late, a scene file written meanwhile), on uvloop, without a wait after a batch."""

from __future__ import annotations

from typing import Any, Iterator

import asyncio
import threading
import warnings

import msgspec.msgpack
import numpy as np
import pytest
import uvloop
import viser
import viser._messages as vm
import zstandard
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from support import wait_for

from ucat_console.bench.raw_page import RawPage, split_buffers, with_arrays
from ucat_console.ui import viser_compat


class _Recorder(RawPage):
    """A raw page that keeps every point cloud it receives (name -> points, colours)."""

    def __init__(self, url: str) -> None:
        self.clouds: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self.cloud_frame: dict[str, int] = {}  # the frame each cloud came in
        self.cloud_bytes: dict[str, bytes] = {}  # that frame as received
        super().__init__(url)

    def _apply(self, m: dict[str, Any]) -> None:
        if m.get("type") == "PointCloudMessage":
            self.clouds[m["name"]] = (m["props"]["points"], m["props"]["colors"])
            self.cloud_frame[m["name"]] = self.frames
            self.cloud_bytes[m["name"]] = self.last_frame
        super()._apply(m)


@pytest.fixture
def server() -> Iterator[viser.ViserServer]:
    viser_compat.install()
    s = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    yield s
    s.stop()


def test_two_pages_receive_every_array_the_server_sent(server: viser.ViserServer) -> None:
    url = f"http://127.0.0.1:{server.get_port()}"
    pages = [_Recorder(url), _Recorder(url)]
    try:
        wait_for(lambda: len(server.get_clients()) == 2, what="two pages connected")
        sent: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        for k in range(40):  # many per batch: later clouds' arrays fall after earlier ones'
            name = f"/cloud{k % 8}"
            points = np.random.default_rng(k).normal(size=(10 + k, 3)).astype(np.float32)
            colors = np.full((10 + k, 3), k, dtype=np.uint8)
            server.scene.add_point_cloud(name, points, colors, point_size=0.01, precision="float32")
            sent[name] = (points, colors)
        for page in pages:
            def arrived(page: _Recorder = page) -> bool:
                return all(name in page.clouds and len(page.clouds[name][0]) == 3 * len(p)
                           for name, (p, _) in sent.items())
            wait_for(arrived, what="the last point clouds on a page")
            for name, (points, colors) in sent.items():
                got_points, got_colors = page.clouds[name]
                np.testing.assert_array_equal(got_points.reshape(-1, 3), points)
                np.testing.assert_array_equal(got_colors.reshape(-1, 3), colors)
        # a page that connects later is sent the kept messages again, at other positions
        late = _Recorder(url)
        pages.append(late)
        wait_for(lambda: len(late.clouds) == len(sent), what="the scene on a late page")
        for name, (points, colors) in sent.items():
            np.testing.assert_array_equal(late.clouds[name][0].reshape(-1, 3), points)
            np.testing.assert_array_equal(late.clouds[name][1].reshape(-1, 3), colors)
    finally:
        for page in pages:
            page.close()


def test_a_scene_file_holds_every_array_and_a_later_page_still_gets_each_cloud_s_own(server: viser.ViserServer) -> None:
    url = f"http://127.0.0.1:{server.get_port()}"
    same = np.ones((5, 3), dtype=np.float32)  # equal arrays: the file merges them
    other = np.arange(12, dtype=np.float32).reshape(4, 3)
    page = _Recorder(url)
    try:
        server.scene.add_point_cloud("/a", other, np.full((4, 3), 9, np.uint8), point_size=0.01, precision="float32")
        server.scene.add_point_cloud("/b", same, np.zeros((5, 3), np.uint8), point_size=0.01, precision="float32")
        server.scene.add_point_cloud("/c", same, np.zeros((5, 3), np.uint8), point_size=0.01, precision="float32")
        wait_for(lambda: len(page.clouds) == 3, what="the clouds on the page")
        data = server.get_scene_serializer().serialize()
    finally:
        page.close()
    clouds = {m["name"]: m["props"] for _, m in _scene_file_messages(data)
              if m.get("type") == "PointCloudMessage"}
    np.testing.assert_array_equal(clouds["/a"]["points"].reshape(-1, 3), other)
    np.testing.assert_array_equal(clouds["/a"]["colors"].reshape(-1, 3), np.full((4, 3), 9))
    np.testing.assert_array_equal(clouds["/b"]["points"].reshape(-1, 3), same)
    np.testing.assert_array_equal(clouds["/c"]["points"].reshape(-1, 3), same)
    # a page that connects after the file was written still gets each cloud's own arrays
    late = _Recorder(url)
    try:
        wait_for(lambda: len(late.clouds) == 3, what="the scene on a late page")
        np.testing.assert_array_equal(late.clouds["/a"][0].reshape(-1, 3), other)
        np.testing.assert_array_equal(late.clouds["/a"][1].reshape(-1, 3), np.full((4, 3), 9))
        np.testing.assert_array_equal(late.clouds["/c"][0].reshape(-1, 3), same)
        np.testing.assert_array_equal(late.clouds["/c"][1].reshape(-1, 3), np.zeros((5, 3)))
    finally:
        late.close()


def _scene_file_messages(data: bytes) -> list[tuple[float, dict[str, Any]]]:
    """The (time, message) pairs of a viser scene file, with their arrays: the file is
    [8-byte size][zstd of: 8-byte msgpack length, msgpack, 8-byte aligned buffers]."""
    size = int.from_bytes(data[0:8], "little")
    raw = zstandard.ZstdDecompressor().decompress(data[8:], max_output_size=size)
    n = int.from_bytes(raw[0:8], "little")
    inner = msgspec.msgpack.decode(raw[8:8 + n])
    buffers = split_buffers(raw, 8 + n, inner["binaryBufferLengths"])
    return [(t, with_arrays(m, buffers)) for t, m in inner["messages"]]


def test_viser_s_websocket_thread_runs_on_uvloop_and_the_rest_of_the_process_does_not(
        server: viser.ViserServer) -> None:
    assert isinstance(server.get_event_loop(), uvloop.Loop)
    other = asyncio.new_event_loop()  # asyncio's own, as before
    try:
        assert not isinstance(other, uvloop.Loop)
    finally:
        other.close()
    # and pages are served on it
    page = _Recorder(f"http://127.0.0.1:{server.get_port()}")
    try:
        server.scene.add_point_cloud("/p", np.zeros((3, 3), np.float32), np.zeros((3, 3), np.uint8),
                                     point_size=0.01, precision="float32")
        wait_for(lambda: "/p" in page.clouds, what="a cloud on the page")
    finally:
        page.close()


def test_viser_s_senders_do_not_wait_after_a_batch(server: viser.ViserServer) -> None:
    """Every message buffer (the broadcast one and each page's) sends what is queued as soon
    as it is queued: the console batches a pass's messages itself (``server.atomic()``)."""
    page = _Recorder(f"http://127.0.0.1:{server.get_port()}")
    try:
        wait_for(lambda: len(server.get_clients()) == 1, what="the page connected")
        buffers = [server._websock_server._broadcast_buffer]
        buffers += [c._websock_connection.get_message_buffer() for c in server.get_clients().values()]
        assert [b.window_duration_sec for b in buffers] == [0.0, 0.0]
        # and a batch still arrives whole, in one frame: many messages queued in one atomic block
        with server.atomic():
            for k in range(50):
                server.scene.add_point_cloud(f"/batch/{k}", np.full((2, 3), k, np.float32),
                                             np.zeros((2, 3), np.uint8), point_size=0.01,
                                             precision="float32")
        wait_for(lambda: len(page.clouds) == 50, what="the batch on the page")
        assert all(page.clouds[f"/batch/{k}"][0][0] == k for k in range(50))
        assert len({page.cloud_frame[f"/batch/{k}"] for k in range(50)}) == 1
    finally:
        page.close()


def test_the_window_delay_is_one_turn_of_the_loop_and_reports_what_is_done() -> None:
    """With a window of 0 viser's window loop waits for 0 s (or a flush): one turn of the
    event loop, in which every other ready task runs; a flush already done is reported done."""

    async def scenario() -> None:
        loop = asyncio.get_running_loop()
        ran: list[str] = []
        flushed = loop.create_future()
        flushed.set_result(True)
        waiting = loop.create_future()
        loop.call_soon(ran.append, "other task")
        before = len(loop._scheduled) if hasattr(loop, "_scheduled") else None
        done, pending = await viser_compat._window_delay([flushed, waiting], timeout=0.0)
        assert ran == ["other task"]  # the other ready work had its turn
        assert done == {flushed} and pending == {waiting}
        if before is not None:
            assert len(loop._scheduled) == before  # no timer was made for it
        # a window other than 0 is asyncio's own wait: it times out, or ends with the flush
        done, pending = await viser_compat._window_delay([waiting], timeout=0.05)
        assert not done and pending == {waiting}
        loop.call_later(0.01, waiting.set_result, True)
        done, pending = await viser_compat._window_delay([waiting], timeout=30.0)
        assert done == {waiting} and not pending

    asyncio.run(scenario())


def test_a_buffer_s_message_event_is_set_only_in_its_loop_s_thread() -> None:
    """viser sets a message buffer's event directly from the thread that queues a message;
    asyncio's Event walks its waiters there, racing the loop's thread ("deque mutated during
    iteration" in the live view). With the console's event a set() from another thread
    changes nothing, and the set() viser schedules in the loop's thread wakes the waiter: a
    message queued from another thread is still sent at once."""
    from viser.infra._async_message_buffer import AsyncMessageBuffer

    viser_compat.install()
    loop = asyncio.new_event_loop()
    thread = threading.Thread(target=loop.run_forever, name="loop", daemon=True)
    thread.start()
    try:
        async def make() -> AsyncMessageBuffer:
            return AsyncMessageBuffer(loop, persistent_messages=False)

        buffer = asyncio.run_coroutine_threadsafe(make(), loop).result(10.0)
        event = buffer.message_event
        assert isinstance(event, viser_compat._LoopEvent)
        woke = threading.Event()

        async def waiter() -> None:
            await event.wait()
            woke.set()

        asyncio.run_coroutine_threadsafe(waiter(), loop)
        event.set()  # from this thread: nothing happens here
        assert not event.is_set()
        loop.call_soon_threadsafe(event.set)  # in the loop's thread: asyncio's own
        wait_for(woke.is_set, what="the waiter woken from the loop's thread")
        # and end to end: a window generator waiting for messages gets one queued from here
        got: list[Any] = []

        async def consume() -> None:
            gen = buffer.window_generator(0)
            got.extend(await gen.__anext__())
            await gen.aclose()

        event.clear()
        future = asyncio.run_coroutine_threadsafe(consume(), loop)
        buffer.push(vm.RunJavascriptMessage(source="1"))
        future.result(10.0)
        assert [m.source for m in got] == ["1"]
    finally:
        loop.call_soon_threadsafe(loop.stop)
        thread.join(timeout=5.0)
        loop.close()


def test_pages_in_step_are_sent_one_encoding_of_a_broadcast_batch(server: viser.ViserServer, monkeypatch) -> None:
    encoded: list[tuple[str, ...]] = []
    real = viser_compat._frame

    def counted(window: Any, zstd: Any) -> bytes:
        encoded.append(tuple(getattr(m, "name", "") for m in window))
        return real(window, zstd)

    monkeypatch.setattr(viser_compat, "_frame", counted)
    url = f"http://127.0.0.1:{server.get_port()}"
    pages = [_Recorder(url), _Recorder(url)]
    try:
        wait_for(lambda: len(server.get_clients()) == 2, what="two pages connected")
        server.scene.add_point_cloud("/first", np.zeros((1, 3), np.float32), np.zeros((1, 3), np.uint8),
                                     point_size=0.01, precision="float32")
        wait_for(lambda: all("/first" in p.clouds for p in pages), what="the first cloud on both pages")
        for k in range(5):  # each batch sent once both pages have the one before: in step
            names = [f"/step{k}/{j}" for j in range(3)]
            with server.atomic():
                for j, name in enumerate(names):
                    server.scene.add_point_cloud(name, np.full((4, 3), k + j, np.float32),
                                                 np.zeros((4, 3), np.uint8), point_size=0.01,
                                                 precision="float32")
            wait_for(lambda: all(n in p.clouds for p in pages for n in names), what=f"batch {k} on both pages")
            a, b = (p.cloud_bytes[names[0]] for p in pages)
            assert a == b  # the same frame bytes
            assert all(p.cloud_bytes[n] is p.cloud_bytes[names[0]] for p in pages for n in names)
            assert len([w for w in encoded if names[0] in w]) == 1  # encoded once
        # a page's own messages (its buffer, not the broadcast one) go to that page only
        own = list(server.get_clients().values())[0]
        own.scene.add_point_cloud("/own", np.ones((2, 3), np.float32), np.zeros((2, 3), np.uint8),
                                  point_size=0.01, precision="float32")
        server.scene.add_point_cloud("/after", np.ones((2, 3), np.float32), np.zeros((2, 3), np.uint8),
                                     point_size=0.01, precision="float32")
        wait_for(lambda: all("/after" in p.clouds for p in pages), what="the last cloud on both pages")
        assert ["/own" in p.clouds for p in pages].count(True) == 1
    finally:
        for page in pages:
            page.close()


def test_a_page_that_stops_reading_holds_up_no_other_and_later_gets_everything(server: viser.ViserServer) -> None:
    url = f"http://127.0.0.1:{server.get_port()}"
    pages = [_Recorder(url), _Recorder(url)]
    reader, frozen = pages
    try:
        wait_for(lambda: len(server.get_clients()) == 2, what="two pages connected")
        frozen.stop_reading()
        # 40 batches of 1.2 MB, each sent once the reading page has the one before: far more
        # than the socket buffers and the frozen page's client queue take
        names = [f"/big/{k}" for k in range(40)]
        for k, name in enumerate(names):
            with server.atomic():
                server.scene.add_point_cloud(name, np.full((100_000, 3), k, np.float32),
                                             np.zeros((100_000, 3), np.uint8), point_size=0.01,
                                             precision="float32")
            wait_for(lambda: name in reader.clouds, what=f"batch {k} on the page still reading")
        assert not all(n in frozen.clouds for n in names)
        frozen._reading.set()  # reads again: what piled up for it comes in windows of its own
        wait_for(lambda: all(n in frozen.clouds for n in names), what="every batch on the page read again",
                 timeout=60.0)
        for k, name in enumerate(names):
            assert frozen.clouds[name][0][0] == k and len(frozen.clouds[name][0]) == 300_000
        assert len({frozen.cloud_frame[n] for n in names}) < len(names)  # batches merged while it lagged
    finally:
        for page in pages:
            page.close()


# ---------------------------------------------------------------------- wire forms
def _encoded(form: dict[str, Any], arrays: list[Any]) -> tuple[bytes, list[bytes]]:
    """A wire form as the frame holds it (msgpack bytes) and its arrays' bytes."""
    return msgspec.msgpack.encode(form), [bytes(a) for a in arrays]


def _both_forms(message: Any, wire_form: Any = viser_compat._wire_form) -> tuple[Any, Any]:
    """(viser's own wire form, the console's), each as :func:`_encoded`, or the exception
    type each raised."""
    out = []
    for make in (lambda a: message.as_serializable_dict(a), lambda a: wire_form(message, a)):
        arrays: list[Any] = []
        try:
            out.append(_encoded(make(arrays), arrays))
        except Exception as e:  # both must refuse the same way
            out.append(type(e))
    return out[0], out[1]


_scalars = st.one_of(
    st.none(), st.booleans(), st.integers(-2**63, 2**63 - 1), st.floats(allow_nan=True), st.text(max_size=8),
    st.floats(width=32).map(np.float32), st.floats().map(np.float64), st.integers(-2**31, 2**31).map(np.int64),
    st.booleans().map(np.bool_), st.text(max_size=4).map(np.str_),
)
_arrays = st.one_of(
    st.lists(st.floats(width=32), max_size=12).map(lambda v: np.array(v, dtype=np.float32)),
    st.lists(st.floats(), max_size=12).map(lambda v: np.array(v, dtype=np.float64)),
    st.lists(st.integers(0, 255), min_size=2, max_size=12).map(lambda v: np.array(v, dtype=np.uint8)[::2]),  # strided
    st.integers(1, 5).map(lambda n: np.arange(2 * n, dtype=np.float64).reshape(2, n).T),  # not C-contiguous
)
_values = st.recursive(
    st.one_of(_scalars, _arrays),
    lambda inner: st.one_of(st.lists(inner, max_size=4), st.lists(inner, max_size=4).map(tuple),
                            st.dictionaries(st.text(max_size=6), inner, max_size=4)),
    max_leaves=12,
)
_coords = st.one_of(st.floats(), st.floats().map(np.float64), st.integers(-5, 5), st.floats(width=32).map(np.float32))


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_a_message_s_wire_form_is_viser_s_own(data: Any) -> None:
    """The poses, the plots' and blades' updates and the status bar's script with any values
    (numpy scalars, strided and non-contiguous arrays, nested lists, tuples and dicts, a
    tuple of the wrong length, NaN): the same wire form and arrays as viser makes, in the
    same order, or the same refusal."""
    kind = data.draw(st.sampled_from(["position", "orientation", "gui", "node", "script"]))
    if kind == "position":
        n = data.draw(st.sampled_from([3, 3, 3, 2]))
        pos = data.draw(st.one_of(st.tuples(*[_coords] * n), st.lists(_coords, min_size=3, max_size=3)))
        message = vm.SetPositionMessage(data.draw(st.one_of(st.text(max_size=8), st.text(max_size=3).map(np.str_))), pos)
    elif kind == "orientation":
        n = data.draw(st.sampled_from([4, 4, 4, 5]))
        message = vm.SetOrientationMessage("/robot", data.draw(st.tuples(*[_coords] * n)))
    elif kind == "gui":
        message = vm.GuiUpdateMessage("uuid-1", data.draw(st.dictionaries(st.text(max_size=6), _values, max_size=5)))
    elif kind == "node":
        message = vm.SceneNodeUpdateMessage("/robot/blades", data.draw(st.dictionaries(st.text(max_size=6), _values, max_size=5)))
    else:
        message = vm.RunJavascriptMessage(source=data.draw(st.text(max_size=40)))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # viser warns of a tuple that does not fit its hint
        theirs, ours = _both_forms(message)
    assert ours == theirs


def test_every_message_of_a_console_session_has_viser_s_wire_form(tmp_path, monkeypatch) -> None:
    """Every message the console sends a page while it builds the page, arms, swims with
    the plots and the robot moving, and records: the same wire form as viser's own."""
    from ucat_console.backend.access import LOCAL
    from ucat_console.backend.supervisor import Supervisor
    from ucat_console.config import AppConfig, ConsoleConfig
    from ucat_console.ui.app import ConsoleApp

    seen: dict[str, int] = {}
    different: list[str] = []
    real = viser_compat._wire_form

    def checked(message: Any, arrays: list[Any]) -> dict[str, Any]:
        name = type(message).__name__
        seen[name] = seen.get(name, 0) + 1
        theirs, ours = _both_forms(message, real)
        if ours != theirs:
            different.append(name)
        return real(message, arrays)

    monkeypatch.setattr(viser_compat, "_wire_form", checked)
    sup = Supervisor(AppConfig(console=ConsoleConfig(port=0)), sessions_dir=tmp_path)
    app = ConsoleApp(sup)
    app.start()
    sup.start()
    page = None
    try:
        page = RawPage(app.url)
        sup.set_setpoints(LOCAL, velocity=0.2)
        sup.arm(LOCAL)
        wait_for(lambda: app.plots.updates >= 12 and seen.get("SetPositionMessage", 0) >= 20, timeout=60,
                 what="the robot swimming on the page, with its plots")
    finally:
        if page is not None:
            page.close()
        sup.stop()
        app.stop()
    assert not different, different
    for name in ("SetPositionMessage", "SetOrientationMessage", "GuiUpdateMessage", "SceneNodeUpdateMessage",
                 "RunJavascriptMessage", "GuiUplotMessage"):
        assert seen.get(name, 0) > 0, (name, seen)
