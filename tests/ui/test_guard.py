"""The page guard against raw websocket clients on 127.0.0.1: what a hostile page, a frozen
page or a cut link does to a console running the simulated robot in real time.

The clients speak viser's protocol directly (:class:`ucat_console.bench.raw_page.RawPage`),
so they can send what no browser page would, stop answering, or stop reading.
"""

from __future__ import annotations

import logging
import threading
from pathlib import Path
from typing import Iterator

import pytest
import websockets.exceptions
from support import wait_for

from ucat_console.backend.access import LOCAL
from ucat_console.backend.supervisor import Supervisor
from ucat_console.bench.raw_page import RawPage
from ucat_console.config import AccessConfig, AppConfig, ConsoleConfig, FailsafeConfig, FailsafeRule
from ucat_console.telemetry import channels as ch
from ucat_console.ui.app import ConsoleApp
from ucat_console.ui.guard import MAX_FRAME, origin_allowed

TOKEN = "guard-test-token"
PILOT_GONE = 1.0


class Console:
    def __init__(self, tmp: Path, **console: object) -> None:
        cfg = AppConfig(
            access=AccessConfig(token=TOKEN),
            console=ConsoleConfig(port=0, record_on_arm=False, scene_rate=10.0, plot_rate=2.0,
                                  heartbeat_period=0.1, **console),
            failsafe=FailsafeConfig(pilot_gone=FailsafeRule("hold", PILOT_GONE)),
        )
        self.sup = Supervisor(cfg, sessions_dir=tmp)
        self.events: list = []
        self.sup.stream.subscribe(lambda c, m: self.events.append(m), [ch.EVENTS])
        self.app = ConsoleApp(self.sup)
        self.app.start()
        self.sup.start()
        self.url = self.app.url

    def page(self, **kw: object) -> RawPage:
        p = RawPage(self.url, **kw)
        p.wait_for("Take control")
        return p

    def cid_of(self, page: RawPage) -> int:
        """The client id the console gave ``page`` (its role line names it)."""
        def find() -> list[int]:  # a list: client 0 is a valid id
            for el in list(page.elements.values()):
                text = str(el.get("_markdown", ""))
                if "(client " in text and "Read-only" in text:
                    return [int(text.split("(client ", 1)[1].split(")", 1)[0])]
            return []
        return wait_for(find, what="the page's role line")[0]

    def event(self, source: str, code: str, after: int = 0):
        return next((e for e in self.events[after:] if e.source == source and e.code == code), None)

    def stop(self) -> None:
        self.sup.stop()
        self.app.stop()


@pytest.fixture
def console(tmp_path: Path) -> Iterator[Console]:
    c = Console(tmp_path)
    yield c
    c.stop()


def pilot_page(console: Console) -> tuple[RawPage, int]:
    page = console.page()
    cid = console.cid_of(page)
    page.take_control(TOKEN)
    wait_for(lambda: console.sup.access.pilot == cid, what="the page taking control")
    return page, cid


def arm_and_move(console: Console, velocity: float = 0.2) -> None:
    sup = console.sup
    sup.arm(LOCAL)
    sup.set_setpoints(LOCAL, velocity=velocity)
    assert sup.armed


# ------------------------------------------------------------------ handshake
def test_origin_rules() -> None:
    assert origin_allowed(None, "127.0.0.1:8080")  # not a browser
    assert origin_allowed("http://127.0.0.1:8080", "127.0.0.1:8080")
    assert origin_allowed("http://localhost:8080", "localhost:8080")
    assert origin_allowed("http://[::1]:8080", "[::1]:8080")
    assert not origin_allowed("http://evil.example", "127.0.0.1:8080")
    assert not origin_allowed("http://127.0.0.1:9999", "127.0.0.1:8080")  # another local server
    assert not origin_allowed("http://rebound.example:8080", "rebound.example:8080")  # DNS rebinding
    assert origin_allowed("https://console.example.org", "127.0.0.1:8080", ["https://console.example.org"])
    assert not origin_allowed("null", "127.0.0.1:8080")


def test_a_cross_origin_handshake_is_refused_and_a_same_origin_one_accepted(console: Console) -> None:
    with pytest.raises(websockets.exceptions.InvalidStatus) as e:
        RawPage(console.url, origin="http://evil.example")
    assert e.value.response.status_code == 403
    with pytest.raises(websockets.exceptions.InvalidStatus):
        RawPage(console.url, origin="http://127.0.0.1:1")
    assert any(why.startswith("origin http://evil.example") for _, why in console.app.guard.refusals)
    page = console.page(origin=console.url)  # the console's own page
    page.close()


def test_a_reverse_proxys_origin_can_be_allowed(tmp_path: Path) -> None:
    c = Console(tmp_path, allowed_origins=("https://console.example.org",))
    try:
        c.page(origin="https://console.example.org").close()
        with pytest.raises(websockets.exceptions.InvalidStatus):
            RawPage(c.url, origin="https://other.example.org")
    finally:
        c.stop()


# ------------------------------------------------------------------ liveness
def test_a_pilot_that_stops_answering_trips_the_failsafe_and_is_closed(console: Console) -> None:
    page, cid = pilot_page(console)
    arm_and_move(console)
    n = len(console.events)
    page.answer_heartbeats = False  # a frozen page: the socket stays open
    fired = wait_for(lambda: console.event("failsafe", "pilot_gone", n), timeout=PILOT_GONE + 20.0,
                     what="the pilot_gone failsafe")
    assert fired.data["action"] == "hold"
    left = console.event("access", "pilot_left", n)
    assert left is not None and left.data["silent_for"] >= PILOT_GONE
    sup = console.sup
    assert sup.access.pilot is None and cid not in sup.access.clients
    assert sup.setpoints.velocity == 0.0 and sup.setpoints.yaw_rate == 0.0
    wait_for(lambda: page.closed, what="the server closing the silent page's socket")


def test_a_pilot_that_stops_reading_trips_the_failsafe(console: Console) -> None:
    page, cid = pilot_page(console)
    arm_and_move(console)
    n = len(console.events)
    page.stop_reading()  # TCP stays open; the server's sends back up
    wait_for(lambda: console.event("failsafe", "pilot_gone", n), timeout=PILOT_GONE + 20.0,
             what="the pilot_gone failsafe")
    assert console.sup.access.pilot is None and console.sup.setpoints.velocity == 0.0
    page.close()


def test_after_a_silent_pilot_the_token_gives_control_at_once_and_the_waiting_page_takes_over(
        console: Console) -> None:
    a, a_id = pilot_page(console)
    b = console.page()
    b_id = console.cid_of(b)
    b.take_control(TOKEN)
    wait_for(lambda: console.sup.access.pending == b_id, what="b asking a for control")
    a.answer_heartbeats = False
    wait_for(lambda: console.sup.access.pilot == b_id, timeout=PILOT_GONE + 20.0,
             what="b taking control from the silent pilot")
    assert console.event("access", "pilot") is not None
    c = console.page()
    b.answer_heartbeats = False
    wait_for(lambda: console.sup.access.pilot is None, timeout=PILOT_GONE + 20.0, what="b gone")
    c_id = console.cid_of(c)
    c.take_control(TOKEN)  # nobody to ask: at once
    wait_for(lambda: console.sup.access.pilot == c_id, what="c taking control")
    c.close()


def test_a_viewer_that_stops_answering_is_closed_too(tmp_path: Path) -> None:
    c = Console(tmp_path, page_timeout=1.0)
    try:
        viewer = c.page()
        cid = c.cid_of(viewer)
        viewer.answer_heartbeats = False
        wait_for(lambda: viewer.closed, timeout=20.0, what="the silent viewer's socket closed")
        wait_for(lambda: cid not in c.sup.access.clients, what="the viewer forgotten")
    finally:
        c.stop()


def test_a_socket_that_never_shows_is_counted_among_the_clients(console: Console) -> None:
    import websockets.sync.client
    import viser

    ws = websockets.sync.client.connect(console.url.replace("http", "ws"),
                                        subprotocols=[f"viser-v{viser.__version__}"])
    try:  # no camera message: viser never calls the page connected
        wait_for(lambda: len(console.sup.access.clients) == 1, what="the socket counted")
        assert console.sup.health().clients == 1
    finally:
        ws.close()


# ------------------------------------------------------------------ lock-out
def test_a_viewer_spamming_wrong_tokens_does_not_keep_the_pilot_out(console: Console) -> None:
    spammer = console.page()
    stop = threading.Event()

    def spam() -> None:
        while not stop.is_set():
            try:
                spammer.take_control("wrong-token")
            except Exception:
                return
            stop.wait(0.02)

    t = threading.Thread(target=spam, daemon=True)
    t.start()
    try:
        wait_for(lambda: console.event("access", "refused") is not None, what="the spam being refused")
        pilot, cid = pilot_page(console)  # the right token, from the same address
        assert console.sup.access.pilot == cid
    finally:
        stop.set()
        t.join(timeout=5.0)


# ------------------------------------------------------------------ page construction
def test_twenty_pages_connecting_at_once_all_get_working_controls(console: Console) -> None:
    pages: list[RawPage] = []
    errors: list[BaseException] = []

    def connect() -> None:
        try:
            p = RawPage(console.url)
            p.wait_for("Take control")
            pages.append(p)
        except BaseException as e:
            errors.append(e)

    threads = [threading.Thread(target=connect) for _ in range(20)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120.0)
    assert not errors and len(pages) == 20
    assert console.app.tick_errors == 0
    for p in pages:  # each page's own Take control works
        cid = console.cid_of(p)
        p.take_control(TOKEN)
        wait_for(lambda: console.sup.access.pilot == cid, what=f"page {cid} taking control")
        p.click("Release control")
        wait_for(lambda: console.sup.access.pilot is None, what=f"page {cid} releasing control")
    for p in pages:
        p.close()


# ------------------------------------------------------------------ incoming updates
def test_crafted_updates_from_a_viewer_change_nothing(console: Console, caplog) -> None:
    caplog.set_level(logging.WARNING, logger="ucat_console.ui.guard")
    pilot, pilot_id = pilot_page(console)
    viewer = console.page()
    v_id = console.cid_of(viewer)
    app, sup = console.app, console.sup
    v_open = viewer.wait_for("Open", "GuiButtonMessage")
    v_note = viewer.wait_for("Review note")
    p_velocity = pilot.wait_for("Velocity m/s")
    v_arm = viewer.wait_for("Arm motors", "GuiButtonMessage")
    v_velocity = viewer.wait_for("Velocity m/s")
    review = app.reviews[v_id]
    callbacks_before = len(review.open_button._impl.update_cb)
    n = len(app.guard.refusals)

    viewer.update(v_open, update_cb=[])  # viser would have killed the button's callbacks
    viewer.update(v_open, label="pwned")
    viewer.update(v_open, disabled=True)
    viewer.update(v_note, value="x" * 100_000)  # over the input's limit (one frame)
    viewer.update(viewer.wait_for("Marker note"), value="live")  # pilot-only (the live marker's note)
    viewer.update(v_arm, value=True)  # pilot-only
    viewer.update(v_velocity, value=0.5)  # pilot-only
    viewer.update(p_velocity, value=0.5)  # another page's input
    p_speed = pilot.wait_for("Speed [")
    viewer.update(p_speed, value=4.0)  # another page's review: its playback speed
    viewer.update(pilot.wait_for("Play", "GuiButtonMessage"), value=True)  # and its Play
    # the identification folder is the pilot's: its own page's buttons, pressed by a viewer
    viewer.update(viewer.wait_for("Run the identification manoeuvre", "GuiButtonMessage"), value=True)
    viewer.update(viewer.wait_for("Fit the fin model", "GuiButtonMessage"), value=True)
    viewer.update("no-such-uuid", value=1)
    viewer.send({"type": "ShareUrlRequest"})
    viewer.send({"type": "FileTransferStartUpload", "source_component_uuid": v_open, "transfer_uuid": "t",
                 "filename": "x", "mime_type": "text/plain", "part_count": 1, "size_bytes": 10})
    viewer.send_raw(b"\x00not msgpack")
    viewer.send_raw("a text frame")
    wait_for(lambda: len(app.guard.refusals) >= n + 17, what="every crafted message refused")

    assert len(review.open_button._impl.update_cb) == callbacks_before
    assert review.open_button.label == "Open" and not review.open_button.disabled
    assert review.note.value == ""
    assert not sup.armed and sup.setpoints.velocity == 0.0
    assert app.panels[pilot_id].sp_inputs["velocity"].value == 0.0
    assert app.panels[v_id].note.value == ""
    assert app.reviews[pilot_id].speed.value == 1.0  # the pilot's review is the pilot's own
    assert sup.manoeuvre is None and app.panels[v_id].identify._fitting is None  # nothing started
    assert app.reviews[pilot_id].player is None or not app.reviews[pilot_id].player.playing
    # the page still works: its own allowed controls still answer
    viewer.click("Refresh list")
    viewer.set_value("Review note", "fine")
    wait_for(lambda: review.note.value == "fine", what="an allowed value applied")
    # a frame over the limit closes the socket; nothing is applied
    big = RawPage(console.url)
    big.wait_for("Take control")
    big.update(big.wait_for("Review note"), value="y" * (MAX_FRAME + 1))
    wait_for(lambda: big.closed, what="the oversized frame closing the socket")
    wait_for(lambda: any("over the limit" in why for _, why in app.guard.refusals),
             what="the oversized frame refused with a reason")
    assert all(r.note.value != "y" * (MAX_FRAME + 1) for r in app.reviews.values())
    # refusals are log lines with their reason, never tracebacks
    lines = [r for r in caplog.records if r.name == "ucat_console.ui.guard"]
    assert any(r.getMessage().startswith(f"refused from page {v_id}:") for r in lines)
    assert all(r.exc_info is None for r in lines)


def test_raw_gamepad_messages_drive_only_the_pilot_and_only_within_the_envelope(console: Console) -> None:
    """The page's hidden gamepad input, written by a raw client: a viewer's stick is refused,
    the pilot's malformed or out-of-range sticks are refused with a reason and change nothing."""
    pilot, pilot_id = pilot_page(console)
    viewer = console.page()
    app, sup = console.app, console.sup
    envelope = sup.cfg.loop.max_velocity
    n = len(app.guard.refusals)
    viewer.update(viewer.wait_for("gamepad"), value='{"v": 1, "r": 0, "dz": 0}')  # pilot-only
    viewer.update(pilot.wait_for("gamepad"), value='{"v": 1, "r": 0, "dz": 0}')  # another page's
    wait_for(lambda: len(app.guard.refusals) >= n + 2, what="the viewer's sticks refused")
    assert sup.setpoints.velocity == 0.0

    pad = pilot.wait_for("gamepad")
    pilot.update(pad, value='{"v": 0.5, "r": 0, "dz": 0}')
    wait_for(lambda: sup.setpoints.velocity == pytest.approx(0.5 * envelope), what="the pilot's stick")
    panel = app.panels[pilot_id]
    m, n = len(panel.messages), len(app.guard.refusals)
    bad = ["not json", '{"v": 5, "r": 0, "dz": 0}', '{"v": 1}', '{"v": true, "r": 0, "dz": 0}',
           '{"v": NaN, "r": 0, "dz": 0}', '{"v": 0, "r": 0, "dz": 0, "x": 1}', "[1, 2, 3]", 7, "x" * 201]
    for value in bad:
        pilot.update(pad, value=value)
    # each refused once: by the guard (not text, over the input's limit) or, with its reason
    # shown on the page, by the stick's parser
    wait_for(lambda: len(panel.messages) - m + len(app.guard.refusals) - n >= len(bad),
             what="every bad stick message refused")
    assert all(text.startswith("gamepad:") for text in panel.messages[m:])
    assert sup.setpoints.velocity == pytest.approx(0.5 * envelope)  # nothing applied
    assert not pilot.closed  # a bad value is refused, not a reason to drop the page
