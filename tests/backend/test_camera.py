"""The camera: the emulated picture, the PyAV path on a file PyAV writes, the camera thread's
frames, loss and recovery (an event and a light, never a failsafe), and camera/image recorded
as foxglove.CompressedImage and read back."""

from __future__ import annotations

import base64
import io
import json

import jsonschema
import pytest
from mcap.reader import make_reader
from PIL import Image, ImageChops
from support import Collector, Console, wait_for

from ucat_console.backend.camera.config import CameraConfig
from ucat_console.backend.camera.emulated import EmulatedCamera, bar_x
from ucat_console.backend.camera.source import CameraThread
from ucat_console.backend.sessions.reader import SessionReader
from ucat_console.backend.sessions.recorder import Recorder, RecorderConfig
from ucat_console.config import AppConfig, load_config
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.messages import CameraImage
from ucat_console.telemetry.stream import TelemetryStream
from ucat_console.ui.status_bar import vehicle_parts

SMALL = CameraConfig(source="emulated", fps=20.0, width=160, height=90, jpeg_quality=80, lost_after=0.3)


def _decode(data: bytes) -> Image.Image:
    img = Image.open(io.BytesIO(data))
    assert img.format == "JPEG"
    img.load()
    return img.convert("RGB")


def test_config_refuses_a_source_it_cannot_open() -> None:
    with pytest.raises(ValueError, match="camera.source: 'ftp://x' is not a camera source"):
        AppConfig.from_dict({"camera": {"source": "ftp://x"}})
    with pytest.raises(ValueError, match="camera.fps"):
        AppConfig.from_dict({"camera": {"fps": 60}})
    assert AppConfig.from_dict({"camera": {"source": "v4l2:/dev/video0"}}).camera.enabled
    assert not load_config("robot").camera.enabled
    assert load_config("sim-tuned").camera.source == "emulated"


def test_emulated_frames_are_jpeg_of_the_size_asked_with_the_time_burned_in() -> None:
    cam = EmulatedCamera(SMALL)
    a, b, a2 = _decode(cam.frame(1.0)), _decode(cam.frame(2.0)), _decode(cam.frame(1.0))
    assert a.size == (160, 90)
    # the same time draws the same picture; another time changes the time text and the bar
    assert ImageChops.difference(a, a2).getbbox() is None or \
        max(ImageChops.difference(a, a2).getextrema()[0]) < 8
    diff = ImageChops.difference(a, b).convert("L").point(lambda v: 255 if v > 60 else 0)
    box = diff.getbbox()
    assert box is not None
    text_changed = diff.crop((0, 0, 160, 30)).getbbox() is not None  # the corner with t = ...
    assert text_changed
    # the white bar sits where bar_x puts it at each time
    for t, img in ((1.0, a), (2.0, b)):
        x = bar_x(t, 160) + 1
        assert min(img.getpixel((x, 80))) > 200, (t, img.getpixel((x, 80)))
    cam.fail = True
    assert cam.frame(3.0) is None


def test_pyav_reads_a_video_file_pyav_wrote() -> None:
    av = pytest.importorskip("av")
    from ucat_console.backend.camera.pyav import PyAVCamera
    import tempfile, os
    cam = EmulatedCamera(SMALL)
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "clip.mkv")
        out = av.open(path, "w")
        s = out.add_stream("mjpeg", rate=10)
        s.width, s.height, s.pix_fmt = 160, 90, "yuvj420p"
        for i in range(4):
            for p in s.encode(av.VideoFrame.from_image(cam.picture(0.5 * i))):
                out.mux(p)
        for p in s.encode():
            out.mux(p)
        out.close()
        src = PyAVCamera(CameraConfig(source="http://unused", width=80, height=45), source=path)
        frames = []
        with pytest.raises(StopIteration):
            while True:
                frames.append(_decode(src.frame(0.0)))
        src.close()
    assert len(frames) == 4 and all(f.size == (80, 45) for f in frames)


class _MjpegStream:
    """An HTTP MJPEG camera (multipart/x-mixed-replace, as IP cameras and mjpg-streamer
    serve it) on this machine: ``count`` flat grey frames (frame i is grey 4 i), then the
    connection held open until ``end`` is set."""

    def __init__(self, count: int) -> None:
        import threading
        from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
        self.count, self.sent, self.end = count, threading.Event(), threading.Event()
        stream = self

        class Handler(BaseHTTPRequestHandler):
            def do_GET(self) -> None:
                self.send_response(200)
                self.send_header("Content-Type", "multipart/x-mixed-replace; boundary=frame")
                self.end_headers()
                for i in range(stream.count):
                    buf = io.BytesIO()
                    Image.new("RGB", (64, 48), (4 * i,) * 3).save(buf, "JPEG")
                    d = buf.getvalue()
                    self.wfile.write(b"--frame\r\nContent-Type: image/jpeg\r\nContent-Length: %d\r\n\r\n"
                                     % len(d) + d + b"\r\n")
                self.wfile.flush()
                stream.sent.set()
                stream.end.wait(30.0)

            def log_message(self, *args) -> None:
                pass

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}/stream"
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    def close(self) -> None:
        self.end.set()
        self.server.shutdown()
        self.server.server_close()


def _fails(cam) -> bool:
    """The camera's next take raises (its source failed or ended)."""
    try:
        cam.frame(0.0)
    except Exception:
        return True
    return False


def test_a_live_stream_gives_its_newest_frame_not_a_queue() -> None:
    """A source sending faster than the camera takes frames: each take is the newest frame,
    the ones in between are skipped (counted), not queued behind it; the stream's end is a
    failure the camera thread reopens from."""
    pytest.importorskip("av")
    from ucat_console.backend.camera.pyav import PyAVCamera
    stream = _MjpegStream(60)
    try:
        cam = PyAVCamera(CameraConfig(source=stream.url, width=64, height=48, fps=5.0))
        assert cam.live
        wait_for(lambda: stream.sent.is_set() and cam.skipped == 59, 30.0, "the reader to read every frame")
        first = Image.open(io.BytesIO(cam.frame(0.0)))
        assert round(first.getpixel((32, 24))[0] / 4) == 59  # the newest, not the first sent
        assert cam.frame(0.0) is None  # nothing newer has come
        stream.end.set()  # the camera hangs up

        wait_for(lambda: _fails(cam), 30.0, "the ended stream to fail")
        cam.close()
    finally:
        stream.close()


class _RtspRelay:
    """An RTSP server on this machine that relays one stream, as a camera's or a media
    server's would serve it: a publisher pushes it (ANNOUNCE, SETUP, RECORD, then RTP
    interleaved on the TCP connection), readers play it (OPTIONS, DESCRIBE, SETUP, PLAY) and
    get the publisher's packets from then on; when the publisher hangs up, so do the readers."""

    def __init__(self) -> None:
        import socket
        import threading
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.url = f"rtsp://127.0.0.1:{self.sock.getsockname()[1]}/cam"
        self.sdp = b""
        self.recording = threading.Event()
        self.readers: list = []
        self.lock = threading.Lock()
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self) -> None:
        import threading
        while True:
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            threading.Thread(target=self._serve, args=(conn,), daemon=True).start()

    def _serve(self, conn) -> None:
        f = conn.makefile("rb")
        publisher = False
        try:
            while first := f.read(1):
                if first == b"$":  # an interleaved packet: channel, length, data
                    head = f.read(3)
                    packet = first + head + f.read(int.from_bytes(head[1:], "big"))
                    with self.lock:
                        for r in list(self.readers):
                            try:
                                r.sendall(packet)
                            except OSError:
                                self.readers.remove(r)
                    continue
                lines = [first + f.readline()]
                while lines[-1] not in (b"\r\n", b""):
                    lines.append(f.readline())
                method = lines[0].split()[0].decode()
                headers = {k.strip().lower(): v.strip() for k, _, v in
                           (ln.decode().partition(":") for ln in lines[1:-1])}
                body = f.read(int(headers.get("content-length", 0)))
                extra, content = "", b""
                if method == "OPTIONS":
                    extra = "Public: OPTIONS, DESCRIBE, SETUP, PLAY, ANNOUNCE, RECORD, TEARDOWN\r\n"
                elif method == "ANNOUNCE":
                    self.sdp, publisher = body, True
                elif method == "DESCRIBE":
                    content = self.sdp
                    extra = f"Content-Type: application/sdp\r\nContent-Base: {self.url}/\r\n"
                elif method == "SETUP":
                    extra = f"Transport: {headers['transport']}\r\nSession: 1\r\n"
                elif method in ("RECORD", "PLAY"):
                    extra = "Session: 1\r\n"
                with self.lock:
                    conn.sendall(f"RTSP/1.0 200 OK\r\nCSeq: {headers.get('cseq', '0')}\r\n{extra}"
                                 f"Content-Length: {len(content)}\r\n\r\n".encode() + content)
                    if method == "PLAY":
                        self.readers.append(conn)
                if method == "RECORD":
                    self.recording.set()
        except OSError:
            pass
        finally:
            if publisher:
                with self.lock:
                    for r in self.readers:
                        r.close()
                    self.readers.clear()
            f.close()
            conn.close()

    def close(self) -> None:
        self.sock.close()


#: an RTSP camera: H.264 (what IP cameras send) over TCP, frame i flat grey 4 (i mod 64),
#: 20 a second, a key frame every 10
_RTSP_PUBLISHER = """
import sys, time, av
from PIL import Image
out = av.open(sys.argv[1], "w", format="rtsp", options={"rtsp_transport": "tcp"})
s = out.add_stream("libx264", rate=20, options={"preset": "ultrafast", "tune": "zerolatency", "g": "10"})
s.width, s.height, s.pix_fmt = 64, 48, "yuv420p"
for i in range(100000):
    frame = av.VideoFrame.from_image(Image.new("RGB", (64, 48), (4 * (i % 64),) * 3))
    frame.pts = i
    for p in s.encode(frame):
        out.mux(p)
    time.sleep(0.05)
"""


def test_an_rtsp_camera_is_read_scaled_and_its_loss_seen() -> None:
    """An RTSP camera (H.264 over TCP through an RTSP server, a separate process pushing it):
    frames come, each the newest, scaled to the configured size over the whole picture (a
    picture decoded in part, its lower rows green, fails); the camera's hanging up is a
    failure the camera thread reopens from."""
    av = pytest.importorskip("av")
    import subprocess
    import sys
    from ucat_console.backend.camera.pyav import PyAVCamera
    if "libx264" not in av.codecs_available:
        pytest.skip("this PyAV has no H.264 encoder for the test's camera")
    relay = _RtspRelay()
    camera = subprocess.Popen([sys.executable, "-c", _RTSP_PUBLISHER, relay.url],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        wait_for(relay.recording.is_set, 30.0, "the camera to publish its stream")
        cam = PyAVCamera(CameraConfig(source=relay.url, width=32, height=24, fps=10.0))
        assert cam.live
        levels = []

        def taken() -> bool:
            data = cam.frame(0.0)
            if data is not None:
                img = _decode(data)
                assert img.size == (32, 24)
                px = [img.getpixel(xy) for xy in ((0, 0), (16, 12), (31, 23), (0, 23))]
                grey = px[1][0]
                for p in px:  # grey everywhere, the same grey in every corner
                    assert max(p) - min(p) <= 6 and abs(p[0] - grey) <= 6, px
                levels.append(grey)
            return len(levels) >= 5
        wait_for(taken, 30.0, "five frames from the RTSP camera")
        assert len(set(round(v / 4) for v in levels)) >= 3, levels  # newer frames, not one repeated
        camera.kill()

        wait_for(lambda: _fails(cam), 30.0, "the camera's hanging up to fail the source")
        cam.close()
    finally:
        camera.kill()
        camera.wait()
        relay.close()


def test_a_v4l2_device_is_opened_through_ffmpegs_v4l2_input() -> None:
    """A V4L2 source goes to FFmpeg's v4l2 input (present in PyAV's FFmpeg): it names a
    device that is not there, and asks a file that is no video device for its capabilities
    (the ioctl refused; read as a file it would be data FFmpeg cannot read). No device is at
    hand here to read frames from."""
    import errno
    pytest.importorskip("av")
    from ucat_console.backend.camera.pyav import PyAVCamera
    with pytest.raises(OSError, match="/dev/video-not-here"):
        PyAVCamera(CameraConfig(source="v4l2:/dev/video-not-here"))
    with pytest.raises(OSError) as e:
        PyAVCamera(CameraConfig(source="v4l2:/dev/null"))
    assert e.value.errno == errno.ENOTTY and "/dev/null" in str(e.value)


def test_a_missing_pyav_is_named(monkeypatch) -> None:
    import builtins
    from ucat_console.backend.camera import pyav
    real = builtins.__import__

    def no_av(name, *a, **k):
        if name == "av":
            raise ImportError("no av")
        return real(name, *a, **k)
    monkeypatch.setattr(builtins, "__import__", no_av)
    with pytest.raises(ImportError, match=r"'rtsp://cam/1' needs PyAV, the optional extra 'camera'"):
        pyav.PyAVCamera(CameraConfig(source="rtsp://cam/1"))


def test_loss_and_recovery_are_events_and_a_light() -> None:
    now = [0.0]
    frames, events = Collector(), Collector()
    cam = CameraThread(SMALL, lambda c, m: frames((c, m)), events, lambda: now[0])
    assert cam.light(0.0)[0] == "warn"
    assert cam.take()
    [(channel, msg)] = frames.items
    assert channel == ch.CAMERA_IMAGE and msg.t == 0.0 and msg.format == "jpeg"
    assert cam.light(0.0)[0] == "ok"
    cam.camera.fail = True
    now[0] = 0.2
    assert not cam.take() and not events.items  # not yet lost_after
    now[0] = 0.4
    cam.take()
    [lost] = events.items
    assert (lost.source, lost.code, lost.level) == ("camera", "lost", "warning")
    state, why = cam.light(0.4)
    assert state == "bad" and "camera lost" in why
    cam.camera.fail = False
    now[0] = 0.5
    assert cam.take()
    assert [e.code for e in events.items] == ["lost", "recovered"]
    assert cam.light(0.5)[0] == "ok"


def test_the_thread_publishes_frames_stamped_with_the_clock() -> None:
    stream = TelemetryStream()
    got = Collector()
    stream.subscribe(lambda c, m: got(m), [ch.CAMERA_IMAGE])
    cam = CameraThread(SMALL, stream.publish, Collector(), lambda: 42.0)
    cam.start()
    try:
        wait_for(lambda: len(got.items) >= 3, what="three frames")
    finally:
        cam.close()
    assert all(isinstance(m, CameraImage) and m.t == 42.0 for m in got.items)
    assert cam.frames >= 3 and cam.bytes > 0


def test_camera_loss_on_the_console_is_a_light_and_an_event_not_a_failsafe(tmp_path) -> None:
    cfg = load_config("sim-tuned")
    cfg = cfg.replace(camera=SMALL, console=cfg.console.replace(record_on_arm=False))
    c = Console(cfg, tmp_path)
    sup = c.sup
    try:
        wait_for(lambda: sup.camera.frames > 0, what="a frame")
        light = lambda: next(x for x in vehicle_parts(sup.state()) if x.name == "Camera")  # noqa: E731
        assert light().state == "ok"
        sup.camera.camera.fail = True
        sup.step(0.5)  # the loop's clock moves on past lost_after with no frame
        wait_for(lambda: sup.camera.lost, what="the camera judged lost")
        wait_for(lambda: c.event("camera", "lost"), what="the camera lost event")
        assert light().state == "bad"
        assert not sup.safety.active()
    finally:
        c.stop()


def test_recorded_as_compressed_image_and_read_back(tmp_path) -> None:
    stream = TelemetryStream()
    rec = Recorder(stream, RecorderConfig(), directory=tmp_path, epoch_offset=1_700_000_000.0)
    rec.start()
    cam = EmulatedCamera(SMALL)
    sent = [CameraImage(t=0.1 * i, frame_id="camera", format="jpeg", data=cam.frame(0.1 * i)) for i in range(5)]
    for m in sent:
        stream.publish(ch.CAMERA_IMAGE, m)
    [path] = rec.stop()
    assert rec.stats().image_bytes == sum(len(m.data) for m in sent)
    with SessionReader(path, tmp_path) as r:
        back = [rec_.message for rec_ in r.records([ch.CAMERA_IMAGE])]
    assert [m.t for m in back] == [m.t for m in sent]
    assert [m.data for m in back] == [m.data for m in sent]
    with open(path, "rb") as fh:  # as Foxglove reads it: its schema, base64 data, a timestamp
        reader = make_reader(fh)
        for schema, channel, message in reader.iter_messages(topics=[ch.CAMERA_IMAGE]):
            assert schema.name == "foxglove.CompressedImage"
            obj = json.loads(message.data)
            jsonschema.validate(obj, json.loads(schema.data))
            assert _decode(base64.b64decode(obj["data"])).size == (160, 90)
            assert obj["timestamp"]["sec"] * 10**9 + obj["timestamp"]["nsec"] == message.log_time
