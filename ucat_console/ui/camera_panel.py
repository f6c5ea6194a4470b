"""The camera's picture in the page: an image panel above the controls, beside the 3-D view.

A :class:`CameraPanel` is one page's: a "Camera" folder with a "Show camera" checkbox (this
page's own input: hiding it hides it on this page only) and viser's image element. It keeps
the latest ``camera/image`` frame of a stream (O(1) per frame, in the publisher's thread)
and, when ticked, sends the page the newest frame at most ``rate`` times a second, skipping
while the page's link is slow or the picture is hidden (a frame is never queued for a page).
The live console ticks every page's panel from its UI thread (:class:`PageCameras`); a
review ticks its own from the review view's thread, so the frame shown is the one at the
playhead (the player publishes, on a seek, the latest frame at or before the position).

The caption under the picture gives the frame's time: ``t = 12.34 s`` (its stream time) live;
in a review also where it is in the session, ``frame at 3.217 s of the session (t = 15.3 s)``,
on the same clock as the playback's position (``origin()``: the session's start in stream
time), so an operator sees which moment the picture shows against the playhead.

The picture is decoded from its JPEG by Pillow and handed to viser's public
``gui.add_image`` element, which encodes it again for the page. Nothing here touches the
pilot's commands or DISARM's path."""

from __future__ import annotations

import io
import logging
import threading
import time
from typing import Any, Callable

import numpy as np
from PIL import Image

from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.messages import CameraImage
from ucat_console.telemetry.stream import TelemetryStream

log = logging.getLogger(__name__)

#: pictures a second a page gets at most
RATE = 5.0


def decode(frame: CameraImage) -> np.ndarray:
    """The frame's picture as an RGB array (ValueError when its data is not a picture)."""
    try:
        with Image.open(io.BytesIO(frame.data)) as img:
            return np.asarray(img.convert("RGB"))
    except Exception as e:  # noqa: BLE001: Pillow raises several kinds for bad data
        raise ValueError(f"camera frame at t={frame.t:.3f} s is not a {frame.format} picture: {e}") from None


class CameraPanel:
    """One page's camera picture (module docstring)."""

    def __init__(self, gui: Any, *, width: int, height: int, rate: float = RATE, order: float = 0.8,
                 allow: Callable[..., None] | None = None, label: str = "Camera",
                 show_label: str = "Show camera", origin: Callable[[], float | None] | None = None) -> None:
        """``origin()``: the session's start in stream time, for a review's caption (None: live)."""
        if not rate > 0.0:
            raise ValueError(f"camera panel: rate {rate!r} must be positive")
        self.period = 1.0 / rate
        self.origin = origin
        self._lock = threading.Lock()
        self._latest: CameraImage | None = None
        self._shown: CameraImage | None = None
        self._next = 0.0
        self.sent = 0  # pictures sent to the page
        self.skipped = 0  # ticks with a new frame not sent (link slow, hidden)
        self.folder = gui.add_folder(label, order=order)
        with self.folder:
            self.show = gui.add_checkbox(show_label, True, hint="hide or show the camera's picture on this page")
            self.caption = gui.add_markdown("No frame yet.")
            self.image = gui.add_image(np.zeros((height, width, 3), dtype=np.uint8), format="jpeg")
        if allow is not None:
            allow(self.show, False)

        @self.show.on_update
        def _(_: Any) -> None:
            self.image.visible = bool(self.show.value)

    def subscribe(self, stream: TelemetryStream) -> Callable[[], None]:
        return stream.subscribe(self.on_message, [ch.CAMERA_IMAGE])

    def on_message(self, channel: str, msg: Any) -> None:
        if type(msg) is CameraImage:
            with self._lock:
                self._latest = msg

    def reset(self) -> None:
        with self._lock:
            self._latest = None

    @property
    def shown(self) -> CameraImage | None:
        """The frame on the page."""
        return self._shown

    def tick(self, slow: bool = False, now: float | None = None) -> bool:
        """Send the newest frame if one is due (True when sent)."""
        now = time.monotonic() if now is None else now
        with self._lock:
            frame = self._latest
        if frame is None or frame is self._shown or now < self._next:
            return False
        if slow or not self.show.value:
            self.skipped += 1
            return False
        self._next = now + self.period
        try:
            picture = decode(frame)
        except ValueError as e:
            self.caption.content = str(e)
            self._shown = frame
            return False
        self.image.image = picture
        self.caption.content = self.describe(frame)
        self._shown = frame
        self.sent += 1
        return True


    def describe(self, frame: CameraImage) -> str:
        """The caption of ``frame`` (module docstring)."""
        start = self.origin() if self.origin is not None else None
        if start is None:
            return f"t = {frame.t:.2f} s"
        return f"frame at {frame.t - start:.3f} s of the session (t = {frame.t:.2f} s)"


class PageCameras:
    """Every live page's :class:`CameraPanel`, fed from the console's stream (no panel when
    the configuration ``cfg`` has no camera)."""

    def __init__(self, stream: TelemetryStream, cfg: Any, rate: float = RATE) -> None:
        self.enabled = bool(cfg.enabled)
        self._size = (cfg.width, cfg.height)
        self._rate = rate
        self._lock = threading.Lock()
        self.panels: dict[int, CameraPanel] = {}
        self._latest: CameraImage | None = None
        self._unsubscribe = stream.subscribe(self._on_message, [ch.CAMERA_IMAGE])

    def _on_message(self, channel: str, msg: Any) -> None:
        with self._lock:
            panels = tuple(self.panels.values())
        for p in panels:
            p.on_message(channel, msg)

    def add(self, cid: int, gui: Any, allow: Callable[..., None] | None = None) -> CameraPanel | None:
        if not self.enabled:
            return None
        panel = CameraPanel(gui, width=self._size[0], height=self._size[1], rate=self._rate, allow=allow)
        with self._lock:
            self.panels[cid] = panel
        return panel

    def remove(self, cid: int) -> None:
        with self._lock:
            self.panels.pop(cid, None)

    def tick(self, slow: Callable[[int], bool]) -> None:
        """Each page its newest frame when due (``slow(cid)``: its link is thinned)."""
        with self._lock:
            panels = tuple(self.panels.items())
        for cid, panel in panels:
            try:
                panel.tick(slow(cid))
            except Exception:  # a page that went meanwhile
                log.debug("the camera picture of client %s was not sent", cid, exc_info=True)

    def close(self) -> None:
        self._unsubscribe()
