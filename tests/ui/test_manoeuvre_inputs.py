"""The Drive tab's Manoeuvre folder without a browser: the pilot's only, a confirmation that
lists the plan, a shipped manoeuvre's name only, DISARM stops it."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import pytest
from support import Console

from ucat_console.backend.access import AccessConfig
from ucat_console.config import AppConfig
from ucat_console.ui.app import ConsoleApp
from ucat_console.ui.panels import ControlPanel

TOKEN = "pool-side-token"


def page(app: ConsoleApp, cid: int, pilot: bool) -> ControlPanel:
    stand_ins = app.__dict__.setdefault("_stand_ins", set())
    if not stand_ins:
        real = app.page_present
        app.page_present = lambda c: c in stand_ins or real(c)  # type: ignore[method-assign]
    stand_ins.add(cid)
    app.sup.client_connected(cid)
    if pilot:
        assert app.sup.take_control(cid, TOKEN)
    return ControlPanel(app, cid, app.server.gui)


def test_the_pilot_starts_a_listed_manoeuvre_and_disarm_stops_it(tmp_path: Path) -> None:
    sup = Console(AppConfig(access=AccessConfig(token=TOKEN)), tmp_path).sup
    app = ConsoleApp(sup, port=0)
    try:
        viewer = page(app, 2, pilot=False)
        pilot = page(app, 1, pilot=True)
        m = pilot.manoeuvres
        assert set(m.choice.options) == {"ab_modes", "depth_step", "e4_ladder", "fig8_circle"}
        m.choice.value = "e4_ladder"
        assert pilot.act(m.request_start) is False and "arm the motors first" in pilot.messages[-1]
        sup.arm(1)
        assert viewer.act(viewer.manoeuvres.request_start) is False and "read-only" in viewer.messages[-1]
        texts: list[str] = []
        real_md = pilot.gui.add_markdown
        pilot.gui.add_markdown = lambda text, **kw: texts.append(text) or real_md(text, **kw)
        assert pilot.act(m.request_start)
        assert sup.script_run is None  # only the confirmation starts it
        assert any("E4 rung 0.4 m/s: velocity 0.4 m/s, depth 1 m" in t for t in texts)
        viewer.manoeuvres.pending = m.pending  # a viewer's page cannot start it either
        assert viewer.act(viewer.manoeuvres.confirm_start) is False and "read-only" in viewer.messages[-1]
        assert pilot.act(m.confirm_start)
        run = sup.script_run
        assert run is not None and not run.finished and sup.setpoints.velocity == 0.1
        pilot.refresh()
        assert m.stop.visible and m.progress.visible and "segment 1 of 4" in m.status.content
        sup.step(1.0)
        sup.disarm(1)  # the status bar's DISARM and Esc disarm
        assert run.finished and run.reason == "the robot is disarmed"
        pilot.refresh()
        assert not m.stop.visible and "ended: the robot is disarmed" in m.status.content
        # a page names a shipped manoeuvre only, never a file
        m.choice = SimpleNamespace(value=str(tmp_path / "mine.toml"))
        with pytest.raises(ValueError, match="not a shipped manoeuvre"):
            m.script()
    finally:
        app.stop()
        sup.stop()
