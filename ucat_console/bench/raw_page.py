"""A console page without a browser: viser's websocket protocol spoken directly.

:class:`RawPage` connects to the console's websocket as the page's script does (the
``viser-v<version>`` subprotocol, msgpack messages out, zstd-compressed msgpack batches
in), keeps the GUI elements the server creates for it (uuid -> type and properties), and
can click buttons, set values, and send anything at all: what a hostile page or a broken
network would do. By default it answers the console's heartbeats as the real page does;
``answer_heartbeats=False`` makes it a frozen page, :meth:`RawPage.stop_reading` one that
stops reading its socket without closing it, ``read_rate`` (bytes a second, settable at
any time) one on a slow link. It keeps the status bar's last state (:attr:`RawPage.bar`).

The safety benchmark and the tests use it; it is not part of the console. It uses no
private name of viser: it speaks viser's wire protocol (its message names and fields, as
viser's client sends them), which is what a hostile page would do, and checks the installed
viser against the supported range as the console does (``backend.dependencies.require``).
"""

from __future__ import annotations

import json
import socket
import threading
import time
from typing import Any

import msgspec.msgpack
import numpy as np
import viser
import websockets.sync.client
import zstandard

from ucat_console.backend.dependencies import require

#: the websocket subprotocol viser's page asks for (its wire protocol's version)
SUBPROTOCOL = f"viser-v{viser.__version__}"

CAMERA = {
    "type": "ViewerCameraMessage", "wxyz": (1.0, 0.0, 0.0, 0.0), "position": (0.0, 0.0, 3.0),
    "fov": 1.0, "near": 0.01, "far": 1000.0, "image_height": 600, "image_width": 800,
    "look_at": (0.0, 0.0, 0.0), "up_direction": (0.0, 0.0, 1.0),
}


def decode_batch(frame: bytes) -> list[dict[str, Any]]:
    """The messages of one server frame, with their arrays (the binary buffers that follow
    the compressed messages, each 8-byte aligned) as numpy arrays."""
    n = int.from_bytes(frame[0:8], "little")
    c = int.from_bytes(frame[8:16], "little")
    inner = msgspec.msgpack.decode(
        zstandard.ZstdDecompressor().decompress(frame[16:16 + c], max_output_size=n))
    buffers = split_buffers(frame, 16 + c, inner.get("binaryBufferLengths", ()))
    return [with_arrays(m, buffers) for m in inner["messages"]]


def split_buffers(data: bytes, offset: int, lengths: Any) -> list[bytes]:
    """The binary buffers of ``lengths`` bytes each that follow ``offset`` in ``data``, each
    starting at a multiple of 8 (viser's layout, in a frame and in a scene file alike)."""
    buffers = []
    for length in lengths:
        offset += (8 - offset % 8) % 8
        buffers.append(data[offset:offset + length])
        offset += length
    return buffers


def with_arrays(v: Any, buffers: list[bytes]) -> Any:
    if isinstance(v, dict):
        if "__binary_index" in v and "dtype" in v:
            return np.frombuffer(buffers[v["__binary_index"]], dtype=np.dtype(v["dtype"]))
        return {k: with_arrays(x, buffers) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [with_arrays(x, buffers) for x in v]
    return v


class ThrottledSocket(socket.socket):
    """A TCP socket whose ``recv`` hands over at most ``rate`` bytes a second (None: no
    limit), with a small receive buffer: the page's end of a slow link."""

    def __init__(self, family: int, rate: float | None) -> None:
        super().__init__(family, socket.SOCK_STREAM)
        self.rate = rate
        self.received = 0
        self.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 16 * 1024)

    def recv(self, n: int, flags: int = 0) -> bytes:
        rate = self.rate
        if rate is None:
            data = super().recv(n, flags)
        else:  # 20 ms of the link's bytes at a time, then the time they take
            data = super().recv(max(1, min(n, int(rate * 0.02))), flags)
            time.sleep(len(data) / rate)
        self.received += len(data)
        return data


_BAR = "window.__ucat && window.__ucat.render("  # the status bar's update (ui.page_script)


class RawPage:
    """One page on ``url`` (``http://host:port``); ``origin``: the Origin header to send
    (None: none); ``local_host``: the loopback address to connect from; ``read_rate``: the
    bytes a second it reads (None: as fast as it can)."""

    def __init__(self, url: str, *, origin: str | None = None, local_host: str | None = None,
                 answer_heartbeats: bool = True, open_timeout: float = 20.0,
                 read_rate: float | None = None) -> None:
        require("viser")  # the wire protocol spoken here is that of the supported versions
        ws_url = url.replace("http://", "ws://", 1)
        host, port = ws_url.split("//", 1)[1].split("/", 1)[0].rsplit(":", 1)
        addr = socket.getaddrinfo(host, int(port), type=socket.SOCK_STREAM)[0]
        sock = ThrottledSocket(addr[0], read_rate)
        sock.settimeout(open_timeout)
        if local_host:
            sock.bind((local_host, 0))
        sock.connect(addr[4])
        self.socket = sock
        headers = {"Origin": origin} if origin is not None else None
        self.ws = websockets.sync.client.connect(
            ws_url, sock=sock, subprotocols=[SUBPROTOCOL], additional_headers=headers,
            max_size=None, open_timeout=open_timeout, compression=None,
        )
        self.answer_heartbeats = answer_heartbeats
        self._lock = threading.Lock()
        self.elements: dict[str, dict[str, Any]] = {}  # uuid -> {"type", **props}
        self.notifications: list[str] = []
        self.nodes: dict[str, dict[str, Any]] = {}  # scene node name -> its last pose and properties
        self.heartbeats = 0
        self.bar: dict[str, Any] = {}  # the status bar's last state
        self.frames = 0  # server frames (batches) received
        self.last_frame = b""  # the frame being applied, as received
        self.closed = False
        self._reading = threading.Event()
        self._reading.set()
        self._thread = threading.Thread(target=self._read, name="raw-page", daemon=True)
        self._thread.start()
        self.send(CAMERA)  # the page shows: the console builds its controls

    # ------------------------------------------------------------------ wire
    def send(self, message: dict[str, Any]) -> None:
        self.ws.send(msgspec.msgpack.encode(message))

    def send_raw(self, data: bytes | str) -> None:
        self.ws.send(data)

    def _read(self) -> None:
        try:
            while True:
                self._reading.wait()
                frame = self.ws.recv()
                if isinstance(frame, bytes):
                    self.frames += 1
                    self.last_frame = frame
                    for m in decode_batch(frame):
                        self._apply(m)
        except Exception:
            self.closed = True

    def _apply(self, m: dict[str, Any]) -> None:
        tp = m.get("type", "")
        if tp == "LocalStorageGetItemRequestMessage":
            self.heartbeats += 1
            if self.answer_heartbeats:
                try:
                    self.send({"type": "LocalStorageGetItemResponseMessage", "value": None, "error": None,
                               "request_uuid": m["request_uuid"]})
                except Exception:
                    pass
            return
        with self._lock:
            if tp == "GuiUpdateMessage":
                el = self.elements.get(m["uuid"])
                if el is not None:
                    el.update(m["updates"])
            elif tp == "GuiRemoveMessage":
                self.elements.pop(m["uuid"], None)
            elif tp == "SetPositionMessage":
                self.nodes.setdefault(m["name"], {})["position"] = tuple(m["position"])
            elif tp == "SetOrientationMessage":
                self.nodes.setdefault(m["name"], {})["wxyz"] = tuple(m["wxyz"])
            elif tp == "SceneNodeUpdateMessage":
                self.nodes.setdefault(m["name"], {}).update(m["updates"])
            elif tp == "NotificationShowMessage":
                self.notifications.append(str(m.get("props", {}).get("body", "")))
            elif tp == "RunJavascriptMessage" and str(m.get("source", "")).startswith(_BAR):
                self.bar = json.loads(m["source"][len(_BAR):].rsplit(");", 1)[0])
            elif tp.startswith("Gui") and "uuid" in m and isinstance(m.get("props"), dict):
                self.elements[m["uuid"]] = {"type": tp, **m["props"],
                                            **({"value": m["value"]} if "value" in m else {})}

    @property
    def read_rate(self) -> float | None:
        return self.socket.rate

    @read_rate.setter
    def read_rate(self, rate: float | None) -> None:
        self.socket.rate = rate

    @property
    def bytes_read(self) -> int:
        """Bytes read from the socket so far."""
        return self.socket.received

    def stop_reading(self) -> None:
        """Stop reading the socket without closing it (the server's sends back up)."""
        self._reading.clear()

    def close(self) -> None:
        self._reading.set()
        try:
            self.ws.close()
        except Exception:
            pass

    # ------------------------------------------------------------------ the page's controls
    def find(self, label: str, type_: str | None = None) -> str | None:
        """The uuid of an element whose label starts with ``label`` (None when there is none)."""
        with self._lock:
            for uuid, el in self.elements.items():
                if str(el.get("label", "")).startswith(label) and (type_ is None or el["type"] == type_):
                    return uuid
        return None

    def wait_for(self, label: str, type_: str | None = None, timeout: float = 30.0) -> str:
        deadline = time.monotonic() + timeout
        while True:
            uuid = self.find(label, type_)
            if uuid is not None:
                return uuid
            if time.monotonic() > deadline or self.closed:
                raise TimeoutError(f"the page never got an element labelled {label!r}")
            time.sleep(0.02)

    def element(self, uuid: str) -> dict[str, Any]:
        with self._lock:
            return dict(self.elements.get(uuid, {}))

    def update(self, uuid: str, **updates: Any) -> None:
        self.send({"type": "GuiUpdateMessage", "uuid": uuid, "updates": updates})

    def click(self, label: str) -> None:
        self.update(self.wait_for(label, "GuiButtonMessage"), value=True)

    def set_value(self, label: str, value: Any) -> None:
        self.update(self.wait_for(label), value=value)

    def take_control(self, token: str) -> None:
        self.set_value("Pilot token", token)
        self.click("Take control")
