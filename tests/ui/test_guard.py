"""The page guard against raw websocket clients on 127.0.0.1: what a hostile page, a frozen
page or a cut link does to a console running the simulated robot in real time.

The clients speak viser's protocol directly (:class:`ucat_console.bench.raw_page.RawPage`),
so they can send what no browser page would, stop answering, or stop reading.
"""

from __future__ import annotations

import logging
from pathlib import Path
import socket
import threading
import time
from typing import Callable

import pytest
import websockets.exceptions
from support import TOKEN, Console, console_config, wait_for

from ucat_console.backend.access import LOCAL
from ucat_console.bench.raw_page import RawPage
from ucat_console.ui import viser_compat
from ucat_console.ui.guard import MAX_FRAME, PageGuard, PortTaken, origin_allowed

PILOT_GONE = 1.0  # the liveness tests' pilot timeout
PATIENT = 30.0  # everyone else's: a pilot page slowed by a busy machine is not what they test
GUARD_SETTINGS = {"scene_rate": 10.0, "plot_rate": 2.0, "heartbeat_period": 0.1}


@pytest.fixture
def guarded(make_console: Callable[..., Console]) -> Callable[..., Console]:
    """``guarded(pilot_gone=PATIENT, **console)``: a served console on the simulated robot
    in real time, the pilot's token TOKEN, the guard's test settings unless changed."""
    def make(pilot_gone: float = PATIENT, **console: object) -> Console:
        return make_console(console_config(TOKEN, pilot_gone, **{**GUARD_SETTINGS, **console}), serve=True)
    return make


@pytest.fixture
def console(guarded: Callable[..., Console]) -> Console:
    return guarded()


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


def test_a_reverse_proxys_origin_can_be_allowed(guarded: Callable[..., Console]) -> None:
    c = guarded(allowed_origins=("https://console.example.org",))
    try:
        c.page(origin="https://console.example.org").close()
        with pytest.raises(websockets.exceptions.InvalidStatus):
            RawPage(c.url, origin="https://other.example.org")
    finally:
        c.stop()


# ------------------------------------------------------------------ ports
def _taken_port() -> socket.socket:
    """A socket bound and listening on a free port of 127.0.0.1 (another program's)."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.bind(("127.0.0.1", 0))
    sock.listen(1)
    return sock


def _bare_guard() -> PageGuard:
    return PageGuard(is_pilot=lambda cid: False, pilot_timeout=lambda: 1.0, page_timeout=5.0, heartbeat_period=1.0)


def test_the_server_viser_starts_on_the_next_port_is_guarded_too() -> None:
    """When the port asked for is taken, viser serves on the next free one: that server's
    handshakes and messages go through the guard all the same."""
    sock = _taken_port()
    taken = sock.getsockname()[1]
    guard = _bare_guard()
    server = viser_compat.guarded_server(guard, host="127.0.0.1", port=taken, verbose=False)
    try:
        got = server.get_port()
        assert got != taken  # viser's retry
        url = f"http://127.0.0.1:{got}"
        with pytest.raises(websockets.exceptions.InvalidStatus) as e:
            RawPage(url, origin="http://evil.example")
        assert e.value.response.status_code == 403
        assert any(why == "origin http://evil.example" for _, why in guard.refusals)
        page = RawPage(url)  # no Origin: let through, and its messages decoded by the guard
        try:
            page.send_raw("a text frame")
            wait_for(lambda: any("a text frame" in why for _, why in guard.refusals), what="the guard's refusal")
        finally:
            page.close()
    finally:
        server.stop()
        sock.close()


def test_the_console_refuses_a_port_other_than_the_one_it_was_given(tmp_path: Path) -> None:
    sock = _taken_port()
    taken = sock.getsockname()[1]
    try:
        with pytest.raises(PortTaken, match=f"port {taken} is in use"):
            _bare_guard().serve(host="127.0.0.1", port=taken, verbose=False)
        with pytest.raises(PortTaken, match=f"port {taken} is in use"):
            Console(console_config(TOKEN, port=taken), tmp_path, serve=True)
        # and the server viser had started on another port is gone
        guard = _bare_guard()
        with pytest.raises(PortTaken) as e:
            guard.serve(host="127.0.0.1", port=taken, verbose=False)
        assert guard.server is None and e.value.got != taken

        def refused() -> bool:
            try:
                socket.create_connection(("127.0.0.1", e.value.got), timeout=1.0).close()
            except ConnectionRefusedError:
                return True
            return False
        wait_for(refused, what=f"port {e.value.got} closed")
    finally:
        sock.close()


def test_an_automatic_port_is_reported(tmp_path: Path, caplog) -> None:
    caplog.set_level(logging.INFO, logger="ucat_console.ui.guard")
    guard = _bare_guard()
    server = guard.serve(host="127.0.0.1", port=0, verbose=False)
    try:
        assert server.get_port() != 0
        assert f"on port {server.get_port()} (chosen by the system)" in caplog.text
    finally:
        guard.stop()
        server.stop()


# ------------------------------------------------------------------ liveness
def test_a_pilot_that_stops_answering_trips_the_failsafe_and_is_closed(guarded: Callable[..., Console]) -> None:
    console = guarded(pilot_gone=PILOT_GONE)
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


def test_a_pilot_that_stops_reading_trips_the_failsafe(guarded: Callable[..., Console]) -> None:
    console = guarded(pilot_gone=PILOT_GONE)
    page, cid = pilot_page(console)
    arm_and_move(console)
    n = len(console.events)
    page.stop_reading()  # TCP stays open; the server's sends back up
    wait_for(lambda: console.event("failsafe", "pilot_gone", n), timeout=PILOT_GONE + 20.0,
             what="the pilot_gone failsafe")
    assert console.sup.access.pilot is None and console.sup.setpoints.velocity == 0.0
    page.close()


def test_a_viewer_that_stops_answering_is_closed_too(guarded: Callable[..., Console]) -> None:
    c = guarded(page_timeout=1.0)
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

    from ucat_console.bench.raw_page import SUBPROTOCOL

    ws = websockets.sync.client.connect(console.url.replace("http", "ws"), subprotocols=[SUBPROTOCOL])
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

    def connect(k: int) -> None:
        try:  # each from an address of its own: one address may have console.max_pages_per_address
            p = RawPage(console.url, local_host=f"127.0.0.{2 + k}")
            p.wait_for("Take control")
            pages.append(p)
        except BaseException as e:
            errors.append(e)

    threads = [threading.Thread(target=connect, args=(k,)) for k in range(20)]
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


# ------------------------------------------------------------------ the pilot's safety commands first
def _burn(seconds: float) -> None:
    """Hold the interpreter for ``seconds`` (as listing a folder of big sessions does)."""
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        pass


def test_a_viewer_spamming_the_review_does_not_hold_up_the_pilots_disarm(
        guarded: Callable[..., Console], monkeypatch) -> None:
    """A viewer clicks Refresh list 20 times a second (within the guard's rate) where a
    listing holds the interpreter 0.3 s, and presses the pilot's controls of its own page;
    the pilot's DISARM is applied while the spam goes on, and nothing of the spam reaches
    the loop. (The pages run in the console's own process here, so they share its
    interpreter with the burning listings: the pilot may be silent longer than a browser in
    its own process would be, and its liveness is not what this test is about.)"""
    console = guarded()
    app, sup = console.app, console.sup
    real = app.session_list.sessions
    listings = [0]

    def slow_listing() -> list:
        listings[0] += 1
        _burn(0.3)
        return real()

    monkeypatch.setattr(app.session_list, "sessions", slow_listing)
    pilot, pilot_id = pilot_page(console)
    spammer = console.page()
    s_id = console.cid_of(spammer)
    refresh = spammer.wait_for("Refresh list", "GuiButtonMessage")
    own = [spammer.wait_for("Arm motors", "GuiButtonMessage"), spammer.wait_for("DISARM", "GuiButtonMessage"),
           spammer.wait_for("Apply setpoints", "GuiButtonMessage")]
    velocity = spammer.wait_for("Velocity m/s")
    arm_and_move(console)
    journal = len(sup.journal())
    n_events = len(console.events)
    stop, done = threading.Event(), threading.Event()

    def spam() -> None:
        try:
            for k in range(160):  # 8 s at 20 a second
                if stop.is_set():
                    return
                spammer.update(refresh, value=True)
                if k % 4 == 0:  # the pilot's controls, on the viewer's own page
                    spammer.update(velocity, value=0.9)
                    for uuid in own:
                        spammer.update(uuid, value=True)
                time.sleep(0.05)
        finally:
            done.set()

    t = threading.Thread(target=spam, daemon=True)
    t.start()
    try:
        wait_for(lambda: listings[0] >= 2 and app.jobs.refused >= 3, what="the spam rationed")
        pilot.update(pilot.wait_for("DISARM", "GuiButtonMessage"), value=True)
        wait_for(lambda: not sup.armed, timeout=60.0, what="the pilot's disarm")
        assert not done.is_set(), "the disarm waited for the spam to end"
    finally:
        stop.set()
        t.join(timeout=30.0)
    assert app.guard.urgent_runs >= 1  # by the guard's safety thread, not viser's pool
    disarmed = console.event("supervisor", "disarmed", n_events)
    assert disarmed is not None and disarmed.data["who"] == str(pilot_id)
    # the spam: rationed, each refusal shown on the spammer's page with its reason
    review = app.reviews[s_id]
    assert any(m.startswith("Refresh list: the last one is still") for m in review.messages)
    assert listings[0] < 40  # not 20 a second
    # and nothing of it reached the loop: the guard refused the pilot's controls of its page
    assert sup.setpoints.velocity == pytest.approx(0.2)
    assert all(e.who != f"client {s_id}" for e in sup.journal()[journal:])
    assert any(c == s_id and "only the pilot's page may use it" in why for c, why in app.guard.refusals)


def test_the_pilots_safety_commands_go_through_the_guard_and_only_the_pilots(console: Console) -> None:
    pilot, pilot_id = pilot_page(console)
    viewer = console.page()
    sup, guard = console.sup, console.app.guard
    arm_and_move(console)
    runs = guard.urgent_runs
    viewer.update(viewer.wait_for("DISARM", "GuiButtonMessage"), value=True)  # its own page's: pilot-only
    viewer.update(pilot.wait_for("DISARM", "GuiButtonMessage"), value=True)  # the pilot's page's
    wait_for(lambda: sum(1 for c, _ in guard.refusals if c == console.cid_of(viewer)) >= 2,
             what="the viewer's presses refused")
    assert sup.armed and guard.urgent_runs == runs
    pilot.update(pilot.wait_for("DISARM", "GuiButtonMessage"), value=True)
    wait_for(lambda: not sup.armed, what="the pilot's disarm")
    wait_for(lambda: guard.urgent_runs == runs + 1, what="the disarm run by the guard")


# ------------------------------------------------------------------ slow links
@pytest.mark.slow
def test_a_pilot_whose_link_slows_to_50_kb_s_stays_the_pilot_until_it_stops_answering(
        guarded: Callable[..., Console]) -> None:
    """The live view at its full rates (40 poses and 12 plot refreshes a second); the pilot's
    page then reads 50 kB/s: it stays the pilot for 300 kB of traffic, its bar says the link
    is slow, its DISARM goes through; when it stops answering, the failsafe fires."""
    c = guarded(pilot_gone=2.0, scene_rate=40.0, plot_rate=12.0)
    try:
        pilot, cid = pilot_page(c)
        arm_and_move(c)
        n = len(c.events)
        pilot.read_rate = 50_000.0
        start = pilot.bytes_read
        wait_for(lambda: pilot.bar.get("link_slow"), timeout=60.0, what="the page told its link is slow")
        wait_for(lambda: pilot.bytes_read - start >= 300_000 or c.sup.access.pilot != cid, timeout=120.0,
                 what="300 kB of armed traffic at 50 kB/s")
        assert c.sup.access.pilot == cid
        assert c.event("failsafe", "pilot_gone", n) is None and c.event("access", "pilot_left", n) is None
        pilot.update(pilot.wait_for("DISARM", "GuiButtonMessage"), value=True)
        wait_for(lambda: not c.sup.armed, what="the slow pilot's disarm")
        c.sup.arm(LOCAL)
        pilot.answer_heartbeats = False
        fired = wait_for(lambda: c.event("failsafe", "pilot_gone", n), timeout=30.0, what="the pilot_gone failsafe")
        assert fired.data["action"] == "hold"
        pilot.close()
    finally:
        c.stop()


# ------------------------------------------------------------------ pages that close under a callback
def _gone(console: Console, page: RawPage, cid: int) -> None:
    """Close ``page`` and wait until the console has let go of it (its elements removed)."""
    page.close()
    wait_for(lambda: cid not in console.app.server.get_clients() and cid not in console.app.guard.clients,
             timeout=30.0, what="the page gone")


def _no_tracebacks(caplog, capfd) -> None:
    err = capfd.readouterr().err
    assert "Traceback" not in err and "Task failed" not in err, err
    bad = [r for r in caplog.records if r.name.startswith("ucat_console") and r.levelno >= logging.ERROR]
    assert not bad, [r.getMessage() for r in bad]


def test_a_page_closing_while_its_review_lists_the_sessions_leaves_no_error(console: Console, monkeypatch,
                                                                              caplog, capfd) -> None:
    caplog.set_level(logging.DEBUG, logger="ucat_console")
    app = console.app
    viewer = console.page()
    cid = console.cid_of(viewer)
    real = app.session_list.listing
    closed = threading.Event()

    def listing_while_the_page_closes() -> object:
        if threading.current_thread().name == "page-jobs" and not closed.is_set():
            _gone(console, viewer, cid)
            closed.set()
        return real()

    wait_for(lambda: not app.jobs.busy(cid), what="the page's first listing done")
    monkeypatch.setattr(app.session_list, "listing", listing_while_the_page_closes)
    done = app.jobs.done
    viewer.click("Refresh list")
    wait_for(lambda: closed.is_set() and app.jobs.done > done, what="the listing done after the page went")
    _no_tracebacks(caplog, capfd)


def test_a_page_closing_during_its_command_leaves_no_error(console: Console, monkeypatch, caplog, capfd) -> None:
    caplog.set_level(logging.DEBUG, logger="ucat_console")
    viewer = console.page()
    cid = console.cid_of(viewer)
    ran = threading.Event()

    def set_name(who: object, name: object) -> None:
        _gone(console, viewer, cid)
        ran.set()
        raise ValueError("name: refused after the page went")  # shown on a page that has gone

    monkeypatch.setattr(console.sup.access, "set_name", set_name)
    viewer.set_value("Your name", "late")
    wait_for(ran.is_set, what="the command run")
    wait_for(lambda: cid not in console.app.panels, what="the page's panel dropped")
    _no_tracebacks(caplog, capfd)


def test_a_page_closing_while_its_review_plays_leaves_no_error(console: Console, monkeypatch, caplog, capfd) -> None:
    caplog.set_level(logging.DEBUG, logger="ucat_console")
    app, sup = console.app, console.sup
    sup.start_recording(LOCAL)
    t0 = sup.loop.time
    wait_for(lambda: sup.loop.time > t0 + 0.5, what="half a second recorded")
    [path] = sup.stop_recording(LOCAL)
    viewer = console.page()
    cid = console.cid_of(viewer)
    wait_for(lambda: cid in app.reviews, what="the page's review")
    review = app.reviews[cid]
    assert review.act(lambda: review.open(path.name))
    real = review._sync_inputs
    closed = threading.Event()

    def sync_while_the_page_closes() -> None:
        if threading.current_thread().name == "ui-review" and not closed.is_set():
            _gone(console, viewer, cid)
            closed.set()
        real()

    monkeypatch.setattr(review, "_sync_inputs", sync_while_the_page_closes)
    wait_for(closed.is_set, what="the page closed under the review's update")
    wait_for(lambda: not review.view.running, what="the review stopped")
    assert review.view.tick_errors == 0
    _no_tracebacks(caplog, capfd)
