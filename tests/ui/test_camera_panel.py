"""The camera's picture in the page: a raw page gets the image element and its updates and
hides it with its checkbox; Review shows the recorded frame at the playhead."""

from __future__ import annotations

import viser
from support import Console, wait_for

from ucat_console.backend.camera.config import CameraConfig
from ucat_console.backend.camera.emulated import EmulatedCamera
from ucat_console.backend.sessions.recorder import Recorder, RecorderConfig
from ucat_console.bench.raw_page import RawPage
from ucat_console.config import AppConfig, load_config
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.messages import BodyState, CameraImage
from ucat_console.telemetry.stream import TelemetryStream
from ucat_console.ui.app import ConsoleApp
from ucat_console.ui.camera_panel import CameraPanel
from ucat_console.ui.playback import PlaybackPanel

SMALL = CameraConfig(source="emulated", fps=10.0, width=96, height=54, jpeg_quality=70)


def _image(page: RawPage) -> str | None:
    with page._lock:
        return next((u for u, el in page.elements.items() if el["type"] == "GuiImageMessage"), None)


def test_a_page_gets_the_picture_and_its_updates_and_may_hide_it(tmp_path) -> None:
    cfg = load_config("sim-tuned")
    cfg = cfg.replace(camera=SMALL, console=cfg.console.replace(record_on_arm=False))
    c = Console(cfg, tmp_path)
    app = ConsoleApp(c.sup, port=0)
    app.start()
    page = None
    try:
        page = RawPage(app.url)
        page.wait_for("Show camera", "GuiCheckboxMessage")
        uuid = wait_for(lambda: _image(page), what="the image element")
        first = wait_for(lambda: page.element(uuid).get("_data"), what="a picture")
        c.sup.step(0.5)  # later frames carry another time: another picture
        wait_for(lambda: page.element(uuid).get("_data") not in (None, first), what="the picture updated")
        assert page.element(uuid).get("visible", True)
        page.set_value("Show camera", False)
        wait_for(lambda: page.element(uuid).get("visible") is False, what="the picture hidden")
    finally:
        if page is not None:
            page.close()
        app.stop()
        c.stop()


def test_no_camera_no_panel(tmp_path) -> None:
    c = Console(AppConfig(), tmp_path)
    app = ConsoleApp(c.sup, port=0)
    app.start()
    page = None
    try:
        page = RawPage(app.url)
        page.wait_for("Arm motors")
        assert page.find("Show camera") is None
    finally:
        if page is not None:
            page.close()
        app.stop()
        c.stop()


def test_review_shows_the_frame_at_or_before_the_playhead(tmp_path) -> None:
    stream = TelemetryStream()
    rec = Recorder(stream, RecorderConfig(), directory=tmp_path, epoch_offset=1_700_000_000.0)
    rec.start()
    cam = EmulatedCamera(SMALL)
    frame_times = [0.0, 0.5, 1.0, 1.5, 2.0]
    for i in range(41):  # body states every 0.05 s, frames every 0.5 s
        t = round(0.05 * i, 3)
        stream.publish(ch.BODY_STATE, BodyState(t, (0.0, 0.0, 1.0), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                                                (0.0, 0.0, 0.0), 1.0))
        if t in frame_times:
            stream.publish(ch.CAMERA_IMAGE, CameraImage(t=t, frame_id="camera", format="jpeg", data=cam.frame(t)))
    [path] = rec.stop()
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    panel = PlaybackPanel(server.gui, server.scene, AppConfig().plant.geometry, directory=tmp_path)
    try:
        panel.open(path.name)
        start = panel.player.reader.start if hasattr(panel.player, "reader") else 0.0
        for i, (pos, want) in enumerate(((1.2, 1.0), (0.3, 0.0), (1.5, 1.5), (1.99, 1.5))):
            panel.seek(pos)

            def shown(now: float = 1e9 + 10.0 * i) -> float | None:
                panel.camera.tick(now=now)  # (the review's own thread may have sent it first)
                s = panel.camera.shown
                return (s is not None and abs(s.t - (start + want)) < 1e-9
                        and panel.camera.caption.content.startswith(f"frame at {want:.3f} s of the session"))
            wait_for(shown, what=f"the frame of {want} s at the playhead {pos} s, its caption saying so")
    finally:
        panel.stop()
        server.stop()


def test_the_panel_sends_at_most_its_rate_and_skips_a_slow_page() -> None:
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        panel = CameraPanel(server.gui, width=96, height=54, rate=5.0)
        cam = EmulatedCamera(SMALL)
        panel.on_message(ch.CAMERA_IMAGE, CameraImage(0.0, "camera", "jpeg", cam.frame(0.0)))
        assert panel.tick(now=10.0)
        panel.on_message(ch.CAMERA_IMAGE, CameraImage(0.1, "camera", "jpeg", cam.frame(0.1)))
        assert not panel.tick(now=10.1)  # within 1 / rate of the last
        assert not panel.tick(slow=True, now=10.3) and panel.skipped == 1
        assert panel.tick(now=10.3) and panel.sent == 2
        assert panel.image.image.shape == (54, 96, 3)
    finally:
        server.stop()
