"""Real camera sources through PyAV (FFmpeg): a V4L2 device, an RTSP stream, an HTTP MJPEG
stream, or a video file. PyAV is the optional extra ``camera``
(``pip install 'ucat-console[camera]'``), imported only when such a source is opened.

A live source (a device or a stream) is read as fast as it sends, in a reader thread of its
own, and only its newest frame is kept: the camera thread takes frames at ``camera.fps``,
and a source that sends faster (a 30 fps stream taken at 10 fps) would otherwise queue its
frames in FFmpeg's and the socket's buffers, each frame taken older than the one before and
stamped with a time it was not seen at. A video file (tests, a recorded clip) is read in
order, one frame per call."""

from __future__ import annotations

import logging
import threading
from typing import Any

from ucat_console.backend.camera.config import DEVICE_PREFIX, STREAM_SCHEMES, CameraConfig
from ucat_console.backend.camera.emulated import encode_jpeg

log = logging.getLogger(__name__)

MISSING = ("camera source {source!r} needs PyAV, the optional extra 'camera': "
           "pip install 'ucat-console[camera]' (or pip install av)")


def import_av() -> Any:
    """The ``av`` module; ImportError naming the extra when it is not installed."""
    try:
        import av
    except ImportError as e:
        raise ImportError(MISSING.format(source="(PyAV)")) from e
    return av


def is_live(source: str) -> bool:
    """A device or a stream (read for its newest frame), not a file (read in order)."""
    return source.startswith((DEVICE_PREFIX, *STREAM_SCHEMES))


class PyAVCamera:
    """Decoded frames of one source, scaled to the configured size and JPEG-encoded.

    ``frame(t)`` gives the source's newest frame not given before, waiting up to one period
    (``1 / camera.fps``) for it, None when none came (a live source); the next frame, blocking
    until it is read (a file). It raises when the source failed or ended (the camera thread
    closes it and opens it again). ``skipped`` counts the frames a live source sent that were
    never taken (newer ones came first)."""

    def __init__(self, cfg: CameraConfig, source: str | None = None) -> None:
        self.cfg = cfg
        self.source = source or cfg.source
        try:
            av = import_av()
        except ImportError:
            raise ImportError(MISSING.format(source=self.source)) from None
        url, fmt, options = self.source, None, {}
        if url.startswith(DEVICE_PREFIX):
            url, fmt = url[len(DEVICE_PREFIX):], "v4l2"
            options = {"framerate": f"{cfg.fps:g}", "video_size": f"{cfg.width}x{cfg.height}"}
        elif url.startswith(("rtsp://", "rtsps://")):
            options = {"rtsp_transport": "tcp"}
        self._container = av.open(url, format=fmt, options=options, timeout=5.0)
        self._frames = self._container.decode(video=0)
        self.live = is_live(self.source)
        self.skipped = 0
        self._newest: Any = None
        self._error: BaseException | None = None
        self._stop = False
        self._ready = threading.Condition()
        self._reader: threading.Thread | None = None
        if self.live:
            self._reader = threading.Thread(target=self._read, name="camera-reader", daemon=True)
            self._reader.start()

    @property
    def where(self) -> str:
        return self.source

    def _read(self) -> None:
        """The reader thread of a live source: keeps the newest decoded frame; it closes the
        container itself (never closed under a read in progress)."""
        try:
            for frame in self._frames:
                with self._ready:
                    if self._stop:
                        break
                    if self._newest is not None:
                        self.skipped += 1
                    self._newest = frame
                    self._ready.notify_all()
            else:
                raise EOFError(f"the stream {self.source!r} ended")
        except BaseException as e:  # noqa: BLE001: handed to the camera thread, which reopens
            with self._ready:
                self._error = e
                self._ready.notify_all()
        finally:
            try:
                self._container.close()
            except Exception:  # noqa: BLE001: closing a failed source
                log.debug("camera %s: closing failed", self.source, exc_info=True)

    def frame(self, t: float) -> bytes | None:
        """The newest frame as JPEG bytes (class docstring); StopIteration: a file ended."""
        if not self.live:
            return self._encode(next(self._frames))
        with self._ready:
            self._ready.wait_for(lambda: self._newest is not None or self._error is not None,
                                 timeout=1.0 / self.cfg.fps)
            frame, self._newest = self._newest, None
            error = self._error
        if frame is None and error is not None:
            raise error
        return None if frame is None else self._encode(frame)

    def _encode(self, frame: Any) -> bytes:
        img = frame.to_image()
        if img.size != (self.cfg.width, self.cfg.height):
            img = img.resize((self.cfg.width, self.cfg.height))
        return encode_jpeg(img, self.cfg.jpeg_quality)

    def close(self) -> None:
        if self._reader is None:
            self._container.close()
            return
        with self._ready:
            self._stop = True  # the reader closes the container after the read in progress


def open_camera(cfg: CameraConfig) -> Any:
    """The camera of ``cfg.source`` (None for ``none``)."""
    if cfg.source == "none":
        return None
    if cfg.source == "emulated":
        from ucat_console.backend.camera.emulated import EmulatedCamera
        return EmulatedCamera(cfg)
    return PyAVCamera(cfg)
