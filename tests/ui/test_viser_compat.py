"""viser with :mod:`ucat_console.ui.viser_compat` installed: every page still receives exactly
the messages and arrays the server sent (two pages, a page joining late, a scene file written
meanwhile, a page that stops reading), and the buffers' event is set in the loop's thread."""

from __future__ import annotations

from typing import Any, Iterator

import asyncio
import threading

import msgspec.msgpack
import numpy as np
import pytest
import viser
import viser._messages as vm
import zstandard
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


def test_a_batch_arrives_whole_in_one_frame(server: viser.ViserServer) -> None:
    """Many messages queued in one atomic block (the console's pass) reach a page in one frame."""
    page = _Recorder(f"http://127.0.0.1:{server.get_port()}")
    try:
        wait_for(lambda: len(server.get_clients()) == 1, what="the page connected")
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
