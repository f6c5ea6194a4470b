"""Each private name of viser the console uses (docs/viser-compat.md, all in
:mod:`ucat_console.ui.viser_compat`) is still there, with the shape the console relies on.

One test per name, so that a new viser names what it changed. The functions the console
replaces are read from the installed viser's source (the running process has them
replaced), the rest from a live server and its handles."""

from __future__ import annotations

import ast
import dataclasses
from pathlib import Path
from typing import Iterator

import numpy as np
import pytest
import viser
import viser._messages as vm
import viser.infra._async_message_buffer as vbuffer
import viser.infra._infra as vinfra

from ucat_console.ui import viser_compat


def _source_of(module: object) -> ast.Module:
    return ast.parse(Path(module.__file__).read_text(encoding="utf-8"))  # type: ignore[attr-defined]


def _function(module: object, name: str, cls: str | None = None) -> ast.FunctionDef | ast.AsyncFunctionDef:
    """The definition of ``name`` (a method of ``cls`` if given) in the module's source."""
    tree = _source_of(module)
    scope: list[ast.stmt] = tree.body
    if cls is not None:
        found = [n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == cls]
        assert found, f"viser no longer defines class {cls} in {module.__name__}"  # type: ignore[attr-defined]
        scope = found[0].body
    defs = [n for n in scope if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) and n.name == name]
    where = f"{module.__name__}.{cls + '.' if cls else ''}{name}"  # type: ignore[attr-defined]
    assert defs, f"viser no longer defines {where}"
    return defs[0]


def _params(fn: ast.FunctionDef | ast.AsyncFunctionDef) -> list[str]:
    a = fn.args
    return [p.arg for p in (*a.posonlyargs, *a.args, *a.kwonlyargs)]


@pytest.fixture(scope="module")
def server() -> Iterator[viser.ViserServer]:
    s = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    yield s
    s.stop()


# ------------------------------------------------------------------ the safety path


def test_viser_serves_its_pages_through_websockets_serve_with_a_request_hook() -> None:
    """The guard's handshake check replaces the ``serve`` viser calls through its module's
    ``websockets`` name, and sets the ``process_request`` and ``max_size`` viser passes."""
    worker = ast.unparse(_function(vinfra, "_background_worker", "WebsockServer"))
    assert "websockets.asyncio.server.serve(" in worker, "viser no longer calls websockets.asyncio.server.serve"
    assert "process_request=" in worker and "max_size=" in worker
    assert "websockets" in vars(vinfra), "viser's infra no longer imports websockets as a module name"


def test_viser_reads_each_page_s_messages_in_one_consumer() -> None:
    """Per-input admission replaces ``_message_consumer(websocket, handle_message, message_class)``,
    called by that name from the server's worker."""
    fn = _function(vinfra, "_message_consumer")
    assert isinstance(fn, ast.AsyncFunctionDef)
    assert _params(fn) == ["websocket", "handle_message", "message_class"]
    assert "_message_consumer(" in ast.unparse(_function(vinfra, "_background_worker", "WebsockServer"))


def test_viser_sends_each_page_s_messages_from_one_producer() -> None:
    """Slow-link pacing replaces ``_message_producer(websocket, buffer, client_id, backlog_done_message)``,
    called by that name, and encodes with viser's ``_append_aligned_buffers(parts, buffers, offset)``."""
    fn = _function(vinfra, "_message_producer")
    assert _params(fn) == ["websocket", "buffer", "client_id", "backlog_done_message"]
    assert "window_generator(" in ast.unparse(fn)
    assert "_message_producer(" in ast.unparse(_function(vinfra, "_background_worker", "WebsockServer"))
    assert len(_params(_function(vinfra, "_append_aligned_buffers"))) == 3


def test_viser_s_message_buffer_keeps_its_event_its_loop_and_its_coalescing_tables() -> None:
    """The console's loop event replaces the buffer's ``message_event`` after viser's
    ``__init__`` (the buffer is a dataclass), and its pacing reads the coalescing tables."""
    fields = {f.name for f in dataclasses.fields(vbuffer.AsyncMessageBuffer)}
    for name in ("message_event", "event_loop", "id_from_redundancy_key", "message_from_id", "done"):
        assert name in fields, f"AsyncMessageBuffer no longer has {name}"
    assert "message_event.set()" in ast.unparse(_function(vbuffer, "push", "AsyncMessageBuffer"))
    params = _params(_function(vbuffer, "window_generator", "AsyncMessageBuffer"))
    assert "client_id" in params and "backlog_done_message" in params


def test_viser_s_websocket_server_keeps_its_loop_sockets_thread_and_connect_callbacks(
        server: viser.ViserServer) -> None:
    ws = server._websock_server
    assert ws._background_event_loop.is_running()
    assert isinstance(ws._live_connections, dict)
    assert callable(ws.on_client_connect) and callable(ws.on_client_disconnect)
    assert ws._server_thread.is_alive()
    assert viser_compat.event_loop(server) is ws._background_event_loop


def test_viser_s_message_classes_the_guard_sends_and_checks_are_there() -> None:
    for name in ("GuiUpdateMessage", "CommandTriggerMessage", "ViewerCameraMessage",
                 "LocalStorageGetItemRequestMessage", "LocalStorageGetItemResponseMessage",
                 "RunJavascriptMessage", "GuiSliderMark"):
        assert hasattr(vm, name), f"viser._messages no longer has {name}"
    message = viser_compat.run_javascript("1")
    assert message.source == "1"
    forms: list[object] = []
    wire = message.as_serializable_dict(forms)
    assert wire["type"] == "RunJavascriptMessage"
    assert isinstance(message.redundancy_key(), str)
    assert hasattr(message, "lifecycle_phase") and callable(message.entity_state_key)


def test_a_frame_encoded_by_the_console_is_one_viser_s_wire_format_reads() -> None:
    """``encode_frame`` (viser's wire format, for frames sent ahead): 16 bytes of lengths,
    zstd msgpack of ``messages``; a change of the format shows here."""
    import msgspec.msgpack
    import zstandard

    frame = viser_compat.encode_frame([viser_compat.run_javascript("x")], viser_compat.compressor())
    inner_len = int.from_bytes(frame[:8], "little")
    comp_len = int.from_bytes(frame[8:16], "little")
    inner = zstandard.ZstdDecompressor().decompress(frame[16:16 + comp_len], max_output_size=inner_len)
    decoded = msgspec.msgpack.decode(inner)
    assert decoded["messages"][0]["type"] == "RunJavascriptMessage"
    assert "timestampSec" in decoded and "binaryBufferLengths" in decoded


# ------------------------------------------------------------------ handles


def test_a_gui_handle_keeps_its_id_its_props_and_its_update(server: viser.ViserServer) -> None:
    number = server.gui.add_number("n", 1.0)
    assert isinstance(viser_compat.handle_uuid(number), str)
    assert number._impl.props is not None and number._impl.gui_api is server.gui
    viser_compat.show_value(number)  # _queue_update("value", ...)
    line = np.array([0.0, 1.0])
    chart = server.gui.add_uplot(data=(line, line), series=({"label": "t"}, {"label": "y"}))
    longer = np.array([0.0, 1.0, 2.0], dtype=np.float32)
    viser_compat.set_plot_data(chart, (longer.astype(np.float64), longer))
    assert chart._impl.props.data[1].dtype == np.float32
    assert len(chart._impl.props.data[0]) == 3
    number.remove()
    chart.remove()


def test_a_slider_takes_new_marks(server: viser.ViserServer) -> None:
    slider = server.gui.add_slider("s", min=0.0, max=10.0, step=1.0, initial_value=0.0)
    viser_compat.set_slider_marks(slider, (2.0, 5.0))
    assert [m.value for m in slider._marks] == [2.0, 5.0]
    slider.remove()


def test_a_page_s_elements_in_shared_containers_can_be_let_go_of(server: viser.ViserServer) -> None:
    """``release_page_elements`` uses the gui's ``_release_cross_scope_nesting`` and
    ``_tombstone_subtree`` and a container's ``_children``."""
    for name in ("_release_cross_scope_nesting", "_tombstone_subtree"):
        assert callable(getattr(server.gui, name, None)), f"viser's GuiApi no longer has {name}"
    folder = server.gui.add_folder("f")
    assert isinstance(folder._children, dict)
    folder.remove()
