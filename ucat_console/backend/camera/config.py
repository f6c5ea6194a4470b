"""The ``[camera]`` configuration: where the frames come from, how often and how large."""

from __future__ import annotations

from dataclasses import dataclass

from ucat_console.typedconf import Config, param

#: the prefixes a source may start with besides ``none`` and ``emulated``
DEVICE_PREFIX = "v4l2:"
STREAM_SCHEMES = ("rtsp://", "rtsps://", "http://", "https://")


@dataclass(frozen=True)
class CameraConfig(Config):
    """The vehicle's camera (docs/camera.md)."""

    source: str = param(
        "none",
        doc="where frames come from: 'none'; 'emulated' (a test picture with the stream time); "
        "'v4l2:/dev/video0' (a local device); 'rtsp://...' or 'http://...' (an RTSP or MJPEG stream; "
        "the last three need the 'camera' extra, PyAV)",
    )
    fps: float = param(10.0, lo=0.1, hi=30.0, unit="Hz", doc="frames per second taken and recorded")
    width: int = param(640, lo=16, hi=4096, unit="px", doc="frame width (frames are scaled to it)")
    height: int = param(360, lo=16, hi=4096, unit="px", doc="frame height (frames are scaled to it)")
    jpeg_quality: int = param(75, lo=1, hi=95, doc="JPEG quality of the frames sent and recorded (Pillow's scale)")
    lost_after: float = param(
        2.0, lo=0.1, hi=60.0, unit="s",
        doc="no frame for this long: the camera is lost (an event and a red light; never a failsafe)",
    )

    def _check(self) -> None:
        s = self.source
        if s in ("none", "emulated"):
            return
        if s.startswith(DEVICE_PREFIX) and len(s) > len(DEVICE_PREFIX):
            return
        if s.startswith(STREAM_SCHEMES) and "://" in s and len(s.split("://", 1)[1]) > 0:
            return
        raise ValueError(
            f"camera.source: {s!r} is not a camera source; allowed: 'none', 'emulated', "
            "'v4l2:/dev/videoN', 'rtsp://host/path', 'http://host/stream.mjpeg'")

    @property
    def enabled(self) -> bool:
        return self.source != "none"
