"""viser's senders as :mod:`ucat_console.ui.viser_hooks` makes them: every page still
receives exactly the messages and arrays the server sent (pages in step sharing frames, a
page joining late, a scene file written meanwhile), on uvloop, without a wait after a batch."""

from __future__ import annotations

from typing import Any, Iterator

import asyncio

import msgspec.msgpack
import numpy as np
import pytest
import uvloop
import viser
import zstandard
from support import wait_for

from ucat_console.bench.raw_page import RawPage, split_buffers, with_arrays
from ucat_console.ui import viser_hooks


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
    viser_hooks.install()
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
        done, pending = await viser_hooks._window_delay([flushed, waiting], timeout=0.0)
        assert ran == ["other task"]  # the other ready work had its turn
        assert done == {flushed} and pending == {waiting}
        if before is not None:
            assert len(loop._scheduled) == before  # no timer was made for it
        # a window other than 0 is asyncio's own wait: it times out, or ends with the flush
        done, pending = await viser_hooks._window_delay([waiting], timeout=0.05)
        assert not done and pending == {waiting}
        loop.call_later(0.01, waiting.set_result, True)
        done, pending = await viser_hooks._window_delay([waiting], timeout=30.0)
        assert done == {waiting} and not pending

    asyncio.run(scenario())


def test_pages_in_step_are_sent_one_encoding_of_a_broadcast_batch(server: viser.ViserServer, monkeypatch) -> None:
    encoded: list[tuple[str, ...]] = []
    real = viser_hooks._frame

    def counted(window: Any, zstd: Any) -> bytes:
        encoded.append(tuple(getattr(m, "name", "") for m in window))
        return real(window, zstd)

    monkeypatch.setattr(viser_hooks, "_frame", counted)
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
