"""Real camera sources through PyAV (FFmpeg): a V4L2 device, an RTSP stream, an HTTP MJPEG
stream, or a video file. PyAV is the optional extra ``camera``
(``pip install 'ucat-console[camera]'``), imported only when such a source is opened."""

from __future__ import annotations

from typing import Any

from ucat_console.backend.camera.config import DEVICE_PREFIX, CameraConfig
from ucat_console.backend.camera.emulated import encode_jpeg

MISSING = ("camera source {source!r} needs PyAV, the optional extra 'camera': "
           "pip install 'ucat-console[camera]' (or pip install av)")


def import_av() -> Any:
    """The ``av`` module; ImportError naming the extra when it is not installed."""
    try:
        import av
    except ImportError as e:
        raise ImportError(MISSING.format(source="(PyAV)")) from e
    return av


class PyAVCamera:
    """Decoded frames of one source, scaled to the configured size and JPEG-encoded.

    ``frame(t)`` reads the next frame from the source (it blocks until one arrives; the
    camera thread calls it, never the loop); it raises when the source fails (the thread
    closes it and opens it again)."""

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

    @property
    def where(self) -> str:
        return self.source

    def frame(self, t: float) -> bytes | None:
        """The next frame as JPEG bytes (StopIteration: the source ended)."""
        frame = next(self._frames)
        img = frame.to_image()
        if img.size != (self.cfg.width, self.cfg.height):
            img = img.resize((self.cfg.width, self.cfg.height))
        return encode_jpeg(img, self.cfg.jpeg_quality)

    def close(self) -> None:
        self._container.close()


def open_camera(cfg: CameraConfig) -> Any:
    """The camera of ``cfg.source`` (None for ``none``)."""
    if cfg.source == "none":
        return None
    if cfg.source == "emulated":
        from ucat_console.backend.camera.emulated import EmulatedCamera
        return EmulatedCamera(cfg)
    return PyAVCamera(cfg)
