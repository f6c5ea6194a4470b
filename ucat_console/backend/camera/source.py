"""The camera thread: takes frames at ``camera.fps`` in a thread of its own and publishes
them on the ``camera/image`` channel, stamped with the loop's time.

Never on the loop's thread. A frame that is due while the previous one is still being taken
or encoded is skipped, never queued (``dropped`` counts them). No frame for
``camera.lost_after`` seconds is camera loss: an Event (source ``camera``, code ``lost``,
level warning) and a red light in the status bar; the next frame is an Event ``recovered``
and a green light. A real source that fails is closed and opened again every
``lost_after`` seconds. Camera loss is never a failsafe."""

from __future__ import annotations

import logging
import threading
import time
from typing import Any, Callable

from ucat_console.backend.camera.config import CameraConfig
from ucat_console.backend.camera.pyav import open_camera
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.events import Event, EventSink
from ucat_console.telemetry.messages import CameraImage

log = logging.getLogger(__name__)

FRAME_ID = "camera"
SOURCE = "camera"
LABEL = "Camera"


class CameraThread:
    """One camera (``open_camera(cfg)``, or ``camera`` given) read in its own thread."""

    def __init__(self, cfg: CameraConfig, publish: Callable[[str, Any], None], on_event: EventSink,
                 clock: Callable[[], float], camera: Any = None,
                 opener: Callable[[CameraConfig], Any] = open_camera) -> None:
        self.cfg = cfg
        self._publish = publish
        self._on_event = on_event
        self._clock = clock
        self._opener = opener
        self._camera = camera
        self._open_error = ""
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.frames = 0
        self.dropped = 0
        self.bytes = 0
        self.lost = False
        self._last_t: float | None = None
        self._since = clock()
        if self._camera is None:
            self._reopen()

    @property
    def camera(self) -> Any:
        """The open camera (the emulated one's ``fail`` injects a loss); None while closed."""
        return self._camera

    def _reopen(self) -> None:
        try:
            self._camera = self._opener(self.cfg)
            self._open_error = ""
        except Exception as e:  # noqa: BLE001: a device or stream that will not open is camera loss
            self._camera = None
            if str(e) != self._open_error:
                log.warning("camera %s: %s", self.cfg.source, e)
            self._open_error = f"{type(e).__name__}: {e}"

    def light(self, now: float) -> tuple[str, str]:
        """The status bar's light: ``ok``, ``warn`` (no frame yet) or ``bad`` (lost), and why."""
        with self._lock:
            last, lost, err = self._last_t, self.lost, self._open_error
        where = self.cfg.source
        if lost:
            why = f"camera lost ({where}): no frame since t={last:.1f} s" if last is not None \
                else f"camera lost ({where}): no frame"
            return "bad", why + (f"; {err}" if err else "")
        if last is None:
            return "warn", f"camera {where}: no frame yet" + (f"; {err}" if err else "")
        return "ok", f"{self.frames} frames, {self.dropped} skipped ({where})"

    # ------------------------------------------------------------------ one step
    def take(self) -> bool:
        """Take one frame and publish it (True), or judge the camera lost or not (False)."""
        t = self._clock()
        data = None
        if self._camera is not None:
            try:
                data = self._camera.frame(t)
            except Exception as e:  # noqa: BLE001: the source failed: closed, opened again later
                self._open_error = f"{type(e).__name__}: {e}"
                self._close_camera()
        if data is not None:
            self._publish(ch.CAMERA_IMAGE, CameraImage(t=t, frame_id=FRAME_ID, format="jpeg", data=data))
            with self._lock:
                self._last_t = t
                self.frames += 1
                self.bytes += len(data)
                was_lost, self.lost = self.lost, False
            if was_lost:
                self._event(t, "recovered", "info", f"camera {self.cfg.source}: frames again")
            return True
        last = self._last_t if self._last_t is not None else self._since
        if not self.lost and t - last >= self.cfg.lost_after:
            with self._lock:
                self.lost = True
            self._event(t, "lost", "warning",
                        f"camera {self.cfg.source}: no frame for {t - last:.1f} s"
                        + (f" ({self._open_error})" if self._open_error else ""))
        return False

    def _event(self, t: float, code: str, level: str, message: str) -> None:
        try:
            self._on_event(Event(t=t, source=SOURCE, code=code, message=message, level=level,
                                 data={"source": self.cfg.source, "frames": self.frames}))
        except Exception:
            log.exception("camera: reporting %s failed", code)

    def _close_camera(self) -> None:
        cam, self._camera = self._camera, None
        if cam is not None:
            try:
                cam.close()
            except Exception:
                log.exception("camera: closing failed")

    # ------------------------------------------------------------------ the thread
    def start(self) -> None:
        if self._thread is not None:
            return
        self._thread = threading.Thread(target=self._run, name="camera", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        period = 1.0 / self.cfg.fps
        due = time.monotonic()
        next_open = due
        while not self._stop.is_set():
            now = time.monotonic()
            if self._camera is None and now >= next_open:
                self._reopen()
                next_open = now + self.cfg.lost_after
            self.take()
            due += period
            now = time.monotonic()
            if now > due:  # behind: skip the frames missed, never queue them
                missed = int((now - due) / period) + 1
                with self._lock:
                    self.dropped += missed
                due += missed * period
            self._stop.wait(max(0.0, due - time.monotonic()))

    def close(self) -> None:
        self._stop.set()
        t, self._thread = self._thread, None
        if t is not None:
            t.join(timeout=5.0)
        self._close_camera()
