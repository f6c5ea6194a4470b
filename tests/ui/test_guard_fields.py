"""Every field of every message a page may send, checked before viser reads it; and one page's
camera, whatever it holds, never stops the other pages' cameras following the robot.

The pages are raw websocket clients (:class:`ucat_console.bench.raw_page.RawPage`) on a
console running the simulated robot in real time.
"""

from __future__ import annotations

import logging
import math
from typing import Any, Callable

import msgspec
import pytest
import websockets.sync.client
from support import TOKEN, Console, console_config, wait_for

from ucat_console.backend.access import LOCAL
from ucat_console.bench.raw_page import CAMERA, SUBPROTOCOL
from ucat_console.ui.guard import FIELDS, Burst, MAX_DISTANCE, MAX_ID, MAX_TEXT, field_problem


def camera(**fields: Any) -> dict[str, Any]:
    """A camera message as a browser sends it, with ``fields`` changed."""
    return {**CAMERA, **fields}


def _missing_and_unknown() -> dict[str, Any]:
    message = camera(extra=1)
    del message["position"]
    return message


#: camera messages a browser never sends, each with what is wrong in it
BAD_CAMERAS: list[tuple[dict[str, Any], str]] = [
    (camera(position=[math.nan, 0.0, 0.0]), "position: not finite"),
    (camera(position=[math.inf, 0.0, 0.0]), "position: not finite"),
    (camera(look_at=[0.0, -math.inf, 0.0]), "look_at: not finite"),
    (camera(position=[1e300, 0.0, 0.0]), "position: 1e+300 beyond"),
    (camera(look_at=[0.0, 0.0, 2 * MAX_DISTANCE]), "look_at: 2e+06 beyond"),
    (camera(position={"a": 1}), "position: expected 3 numbers"),
    (camera(position="abc"), "position: expected 3 numbers"),
    (camera(position=None), "position: expected 3 numbers"),
    (camera(position=[1.0, 2.0]), "position: expected 3 numbers"),
    (camera(position=[1.0, 2.0, 3.0, 4.0]), "position: expected 3 numbers"),
    (camera(position=["1", "2", "3"]), "position: expected 3 numbers, got a str"),
    (camera(look_at=[True, 0.0, 0.0]), "look_at: expected 3 numbers, got a bool"),
    (camera(wxyz=[0.0, 0.0, 0.0, 0.0]), "wxyz: not of length 1"),
    (camera(wxyz=[1.0, 0.0, 0.0]), "wxyz: expected 4 numbers"),
    (camera(up_direction=[0.0, 0.0, 0.0]), "up_direction: not of length 1"),
    (camera(up_direction=[0.0, 0.0, math.nan]), "up_direction: not finite"),
    (camera(fov=math.nan), "fov: not a finite number"),
    (camera(fov=-1.0), "fov: -1.0 rad outside"),
    (camera(fov=4.0), "fov: 4.0 rad outside"),
    (camera(fov="1.0"), "fov: expected a number, got str"),
    (camera(near=0.0), "near: 0.0 m outside"),
    (camera(far=math.inf), "far: not a finite number"),
    (camera(near=10.0, far=1.0), "far plane is not beyond its near plane"),
    (camera(image_height=-1), "image_height: -1 outside"),
    (camera(image_height=1 << 40), "image_height: 1099511627776 outside"),
    (camera(image_width=800.5), "image_width: expected a whole number, got float"),
    (camera(image_width=True), "image_width: expected a whole number, got bool"),
    (_missing_and_unknown(), "position, extra missing or unknown"),
]


# ------------------------------------------------------------------ the checks
def test_a_burst_of_refusals_is_one_log_line_and_then_one_every_period_with_the_count() -> None:
    burst = Burst(every=10.0)
    assert burst.note(0.0) == 0  # the first: logged at once
    assert [burst.note(t) for t in (1.0, 2.0, 9.9)] == [None, None, None]
    assert burst.note(10.0) == 3  # the next line says how many were not logged
    assert burst.note(10.5) is None
    assert burst.note(100.0) == 1
    assert burst.count == 7


def test_a_browsers_camera_message_passes_as_msgpack_has_it() -> None:
    assert field_problem(camera()) is None
    # a browser's whole numbers come as integers (msgpack): the far plane, a position at 0
    assert field_problem(camera(far=1000, position=[0, 0, 3], look_at=(0, 0, 0))) is None


@pytest.mark.parametrize("message, why", BAD_CAMERAS, ids=[w for _, w in BAD_CAMERAS])
def test_each_bad_camera_field_is_refused_with_its_reason(message: dict[str, Any], why: str) -> None:
    problem = field_problem(message)
    assert problem is not None and problem.startswith("a ViewerCameraMessage")
    assert why in problem, problem


def test_every_message_type_the_console_takes_is_checked_field_by_field() -> None:
    assert set(FIELDS) == {"ViewerCameraMessage", "GuiUpdateMessage", "CommandTriggerMessage",
                           "LocalStorageGetItemResponseMessage"}
    good = {
        "GuiUpdateMessage": {"uuid": "u", "updates": {"value": 1}},
        "CommandTriggerMessage": {"uuid": "u"},
        "LocalStorageGetItemResponseMessage": {"value": None, "error": None, "request_uuid": "r"},
    }
    for name, fields in good.items():
        assert field_problem({"type": name, **fields}) is None
    bad = [
        ({"type": "GuiUpdateMessage", "uuid": "u" * (MAX_ID + 1), "updates": {"value": 1}}, "uuid: text of"),
        ({"type": "GuiUpdateMessage", "uuid": 7, "updates": {"value": 1}}, "uuid: expected text, got int"),
        ({"type": "GuiUpdateMessage", "uuid": "u", "updates": [1]}, "updates: expected a map"),
        ({"type": "GuiUpdateMessage", "uuid": "u", "updates": {1: 2}}, "updates: expected a map"),
        ({"type": "GuiUpdateMessage", "uuid": "u"}, "updates missing"),
        ({"type": "CommandTriggerMessage", "uuid": None}, "uuid: expected text, got NoneType"),
        ({"type": "CommandTriggerMessage", "uuid": "u", "x": 1}, "x unknown"),
        ({"type": "LocalStorageGetItemResponseMessage", "value": "v" * (MAX_TEXT + 1), "error": None,
          "request_uuid": "r"}, "value: text of"),
        ({"type": "LocalStorageGetItemResponseMessage", "value": None, "error": 3, "request_uuid": "r"},
         "error: expected text"),
        ({"type": "ShareUrlRequest"}, "a ShareUrlRequest, which the console does not take"),
        ({"uuid": "u"}, "a None, which the console does not take"),
        ([1, 2], "not a message"),
    ]
    for fields, why in bad:
        problem = field_problem(fields)
        assert problem is not None and why in problem, (fields, problem)


# ------------------------------------------------------------------ against a console
@pytest.fixture
def console(make_console: Callable[..., Console]) -> Console:
    return make_console(console_config(TOKEN, 5.0, scene_rate=10.0, plot_rate=2.0, heartbeat_period=0.1),
                        serve=True)


def _camera_of(console: Console, cid: int) -> tuple[float, ...]:
    return tuple(float(v) for v in console.app.pages[cid].client.camera.position)


def _follows(console: Console, cid: int) -> None:
    """Wait until page ``cid``'s camera has moved 5 cm with the swimming robot."""
    start = _camera_of(console, cid)
    wait_for(lambda: math.dist(_camera_of(console, cid), start) > 0.05, timeout=30.0,
             what=f"page {cid}'s camera following the robot")


def _swim(console: Console) -> None:
    console.sup.arm(LOCAL)
    console.sup.set_setpoints(LOCAL, velocity=0.2)


def _tracebacks(caplog: pytest.LogCaptureFixture, capfd: pytest.CaptureFixture[str]) -> list[str]:
    err = capfd.readouterr().err
    found = [r.getMessage() for r in caplog.records if r.name.startswith("ucat_console") and
             (r.exc_info is not None or (r.name.startswith("ucat_console.ui") and r.levelno >= logging.ERROR))]
    return found + (["stderr: " + err] if "Traceback" in err else [])


def test_crafted_camera_messages_are_refused_and_every_other_page_still_follows(
        console: Console, caplog: pytest.LogCaptureFixture, capfd: pytest.CaptureFixture[str]) -> None:
    caplog.set_level(logging.DEBUG, logger="ucat_console")
    app = console.app
    crafted = console.page()  # first: the follow loop comes to it before the other page
    c_id = console.cid_of(crafted)
    follower = console.page()
    f_id = console.cid_of(follower)
    _swim(console)
    _follows(console, f_id)
    app.guard.flow(c_id).refused.every = math.inf  # one burst, however long the machine takes
    guard_lines = len([r for r in caplog.records if r.name == "ucat_console.ui.guard"])
    for message, _ in BAD_CAMERAS:
        crafted.send(message)
    wait_for(lambda: sum(1 for c, _ in app.guard.refusals if c == c_id) >= len(BAD_CAMERAS),
             what="every crafted camera message refused")
    reasons = [why for c, why in app.guard.refusals if c == c_id]
    for (_, why), reason in zip(BAD_CAMERAS, reasons):
        assert why in reason, (why, reason)
    # nothing of it reached viser: the crafted page's camera is where the console put it
    assert all(math.isfinite(v) and abs(v) < 1e3 for v in _camera_of(console, c_id))
    _follows(console, f_id)  # the other page's camera still follows the robot
    _follows(console, c_id)  # and so does the crafted page's own
    assert app.tick_errors == 0
    # one log line for the burst, no traceback
    lines = [r for r in caplog.records[guard_lines:] if r.name == "ucat_console.ui.guard"]
    assert len(lines) == 1 and lines[0].getMessage().startswith(f"refused from page {c_id}: "), \
        [r.getMessage() for r in lines]
    assert not _tracebacks(caplog, capfd)
    assert not crafted.closed and not follower.closed


class _BrokenCamera:
    """A camera whose state cannot be read (whatever got into it)."""

    @property
    def position(self) -> Any:
        raise TypeError("iteration over a 0-d array")


class _PageWithBrokenCamera:
    def __init__(self, client: Any) -> None:
        self._client = client
        self.camera = _BrokenCamera()

    def __getattr__(self, name: str) -> Any:
        return getattr(self._client, name)


def test_a_page_whose_camera_fails_never_stops_the_other_pages_following(
        console: Console, caplog: pytest.LogCaptureFixture, capfd: pytest.CaptureFixture[str]) -> None:
    caplog.set_level(logging.DEBUG, logger="ucat_console")
    app = console.app
    broken = console.page()  # first: the follow loop comes to it before the other page
    b_id = console.cid_of(broken)
    follower = console.page()
    f_id = console.cid_of(follower)
    _swim(console)
    _follows(console, f_id)
    n = len(caplog.records)
    page = app.pages[b_id]
    page.follow_failed.every = math.inf  # one burst, however long the machine takes
    page.client = _PageWithBrokenCamera(page.client)
    wait_for(lambda: any("did not follow" in r.getMessage() for r in caplog.records[n:]),
             what="the broken camera noticed")
    _follows(console, f_id)
    wait_for(lambda: page.follow_failed.count >= 3, what="the broken camera tried again")
    _follows(console, f_id)
    assert app.tick_errors == 0
    # one line for the broken page's burst, without a traceback
    lines = [r for r in caplog.records[n:] if "did not follow" in r.getMessage()]
    assert len(lines) == 1 and lines[0].exc_info is None
    assert lines[0].getMessage().startswith(f"the camera of page {b_id} did not follow the robot: TypeError")
    assert not _tracebacks(caplog, capfd)
    broken.close()
    follower.close()


def test_a_page_that_sends_nothing_but_crafted_cameras_before_it_shows_is_never_built(
        console: Console) -> None:
    """viser builds a page at its first camera message: a crafted one is refused, so the page
    is not built until it sends one the console takes."""
    app = console.app
    ws = websockets.sync.client.connect(console.url.replace("http", "ws"), subprotocols=[SUBPROTOCOL])
    try:
        wait_for(lambda: len(app.guard.clients) == 1, what="the socket open")
        [cid] = app.guard.clients
        ws.send(msgspec.msgpack.encode(camera(position=[math.nan, 0.0, 0.0])))
        wait_for(lambda: any(c == cid for c, _ in app.guard.refusals), what="the crafted camera refused")
        assert cid not in app.server.get_clients() and cid not in app.pages
        ws.send(msgspec.msgpack.encode(camera()))
        wait_for(lambda: cid in app.pages, what="the page built at its first good camera message")
    finally:
        ws.close()
