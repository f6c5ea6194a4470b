"""A stream view's passes on the pages' server's event loop (the live view's way of running)."""

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
from ucat_console.ui import viser_hooks
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


def _after_loop(loop: Any) -> None:
    """Return once everything the loop had queued before now has run."""
    done = threading.Event()
    loop.call_soon_threadsafe(done.set)
    assert done.wait(10.0), "the server's event loop did not run a callback"


def test_on_the_servers_loop_the_passes_run_in_its_thread_and_no_thread_of_their_own(server: Any) -> None:
    threads: set[str] = set()
    view = _view(server, on_tick=lambda: threads.add(threading.current_thread().name))
    view.show()
    before = {t.name for t in threading.enumerate()}
    view.start(viser_hooks.event_loop(server))
    try:
        assert view.running
        view.on_message(ch.BODY_STATE, _body(1))
        wait_for(lambda: view.scene is not None and view.scene.updates >= 1 and view.scene.position is not None,
                 what="the first pose")
        loop_thread: list[str] = []
        viser_hooks.event_loop(server).call_soon_threadsafe(lambda: loop_thread.append(threading.current_thread().name))
        wait_for(lambda: loop_thread, what="a callback on the server's loop")
        assert threads == set(loop_thread)  # every pass ran in the server's event-loop thread
        assert "ui-view" not in {t.name for t in threading.enumerate()} - before
        assert view.tick_errors == 0
    finally:
        view.stop()
    assert not view.running


def test_a_body_state_wakes_a_view_that_waits_for_one(server: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    # nothing else is due for 100 s: only a body state's arrival can bring the next pose
    monkeypatch.setattr(view_module, "_TICK", 100.0)
    monkeypatch.setattr(view_module, "SLOW_PERIOD", 100.0)
    view = _view(server, plot_rate=0.01)
    view.show()
    view.start(viser_hooks.event_loop(server))
    try:
        wait_for(lambda: view.scene.updates >= 1, what="the first pass")  # type: ignore[union-attr]
        for k in range(1, 6):
            wait_for(lambda: view._waiting, what="the view waiting for a body state")
            shown = view.scene.updates  # type: ignore[union-attr]
            # published from a thread of the stream's, as the loop publishes
            t = threading.Thread(target=view.on_message, args=(ch.BODY_STATE, _body(k)))
            t.start()
            t.join()
            wait_for(lambda: view.scene.updates == shown + 1, what=f"the pose of body state {k}")  # type: ignore[union-attr]
            assert view.scene.position == _body(k).position  # type: ignore[union-attr]
    finally:
        view.stop()


def test_a_stopped_view_makes_no_more_passes(server: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(view_module, "_TICK", 100.0)
    monkeypatch.setattr(view_module, "SLOW_PERIOD", 100.0)
    loop = viser_hooks.event_loop(server)
    view = _view(server, plot_rate=0.01)
    view.show()
    view.start(loop)
    wait_for(lambda: view.scene.updates >= 1, what="the first pass")  # type: ignore[union-attr]
    view.stop()
    _after_loop(loop)  # the timer's cancellation has run
    shown = view.scene.updates  # type: ignore[union-attr]
    view.on_message(ch.BODY_STATE, _body(7))
    _after_loop(loop)
    _after_loop(loop)
    assert view.scene.updates == shown  # type: ignore[union-attr]
    assert view._timer is None
    # and it starts again, on the loop or in a thread of its own
    view.start()
    try:
        view.on_message(ch.BODY_STATE, _body(8))
        wait_for(lambda: view.scene.position == _body(8).position, what="the pose after a restart")  # type: ignore[union-attr]
    finally:
        view.stop()


def test_a_failing_pass_is_counted_and_the_passes_go_on(server: Any) -> None:
    fails = {"n": 0}

    def on_tick() -> None:
        fails["n"] += 1
        if fails["n"] <= 3:
            raise RuntimeError("a broken status line")

    view = _view(server, on_tick=on_tick)
    view.show()
    view.start(viser_hooks.event_loop(server))
    try:
        wait_for(lambda: fails["n"] > 5, what="passes after the failing ones")
        assert view.tick_errors == 3
    finally:
        view.stop()
