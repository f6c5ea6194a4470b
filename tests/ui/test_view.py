"""A stream view's UI thread: woken by a body state when it waits for one, stopped for good."""

from __future__ import annotations

import threading
from typing import Any

import pytest
import viser
from support import wait_for

from ucat_console.robot.geometry import Geometry
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.messages import BodyState
from ucat_console.ui import view as view_module
from ucat_console.ui.view import StreamView


def _body(k: int) -> BodyState:
    return BodyState(0.02 * k, (0.01 * k, 0.0, 1.0), (1.0, 0.0, 0.0, 0.0), (0.2, 0.0, 0.0), (0.0, 0.0, 0.0), 1.0)


@pytest.fixture
def server() -> Any:
    s = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    yield s
    s.stop()


def _view(server: Any, **kw: Any) -> StreamView:
    args: dict[str, Any] = dict(plot_rate=12.0, scene_rate=40.0, max_plot_points=100, history=lambda: 10.0,
                                max_history=30.0, corridor=lambda: (0.25, 0.35), trail_points=20, trail_spacing=0.05)
    args.update(kw)
    return StreamView(server.scene, server.gui, Geometry(), **args)


def test_a_body_state_wakes_a_view_that_waits_for_one(server: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    # nothing else is due for 100 s: only a body state's arrival can bring the next pose
    monkeypatch.setattr(view_module, "_TICK", 100.0)
    monkeypatch.setattr(view_module, "SLOW_PERIOD", 100.0)
    passes = {"n": 0}
    view = _view(server, plot_rate=0.01, on_tick=lambda: passes.__setitem__("n", passes["n"] + 1))
    view.show()
    view.start()
    try:
        # a pose pass at once, then one at the time the next pose may go: from then on it waits
        wait_for(lambda: passes["n"] >= 2, what="the first two passes")
        for k in range(1, 6):
            shown, n = view.scene.updates, passes["n"]  # type: ignore[union-attr]
            t = threading.Thread(target=view.on_message, args=(ch.BODY_STATE, _body(k)))  # the stream's thread
            t.start()
            t.join()
            wait_for(lambda: view.scene.updates == shown + 1, what=f"the pose of body state {k}")  # type: ignore[union-attr]
            assert view.scene.position == _body(k).position  # type: ignore[union-attr]
            wait_for(lambda: passes["n"] >= n + 2, what="the pass after the pose")  # waiting again
        assert view.tick_errors == 0
    finally:
        view.stop()
    assert not view.running


def test_a_stopped_view_makes_no_more_passes_and_starts_again(server: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(view_module, "_TICK", 100.0)
    monkeypatch.setattr(view_module, "SLOW_PERIOD", 100.0)
    view = _view(server, plot_rate=0.01)
    view.show()
    view.start()
    wait_for(lambda: view.scene.updates >= 1, what="the first pass")  # type: ignore[union-attr]
    view.stop()  # joins the thread
    assert not view.running
    shown = view.scene.updates  # type: ignore[union-attr]
    view.on_message(ch.BODY_STATE, _body(7))
    assert not any(t.name == "ui-view" for t in threading.enumerate())
    assert view.scene.updates == shown  # type: ignore[union-attr]
    view.start()
    try:
        view.on_message(ch.BODY_STATE, _body(8))
        wait_for(lambda: view.scene.position == _body(8).position, what="the pose after a restart")  # type: ignore[union-attr]
    finally:
        view.stop()


def test_a_failing_pass_is_counted_and_the_passes_go_on(server: Any) -> None:
    calls = {"n": 0}

    def on_tick() -> None:
        calls["n"] += 1
        if calls["n"] <= 3:
            raise RuntimeError("a broken status line")

    view = _view(server, on_tick=on_tick)
    view.show()
    view.start()
    try:
        wait_for(lambda: calls["n"] > 5, what="passes after the failing ones")
        assert view.tick_errors == 3
    finally:
        view.stop()
