"""The Drive tab's Seek efficiency folder without a browser: the pilot's only (the server
checks again), the configuration's parameters only, progress from the snapshot, Stop & keep
best / Stop & revert, DISARM stops it."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import pytest
from support import Console

from ucat_console.backend.access import AccessConfig
from ucat_console.backend.seek.config import SeekConfig, SeekParam
from ucat_console.config import AppConfig
from ucat_console.ui.app import ConsoleApp
from ucat_console.ui.panels import ControlPanel

pytest.importorskip("optuna")

TOKEN = "pool-side-token"
SEEK = SeekConfig(params=(SeekParam("mpc.st_opt", 0.2, 0.45), SeekParam("mpc.lam_st", 0.5, 20.0)),
                  settle_s=0.5, window_s=1.0, max_candidates=5, drift_check=False)


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


def test_the_pilot_seeks_over_the_ticked_parameters_and_stops_keeping_or_reverting(tmp_path: Path) -> None:
    sup = Console(AppConfig(access=AccessConfig(token=TOKEN), seek=SEEK), tmp_path).sup
    app = ConsoleApp(sup, port=0)
    try:
        viewer = page(app, 2, pilot=False)
        pilot = page(app, 1, pilot=True)
        s = pilot.seek
        assert set(s.params) == {"mpc.st_opt", "mpc.lam_st"}
        s.params["mpc.lam_st"].value = False
        assert pilot.act(s.start_seek) is False and "arm the motors first" in pilot.messages[-1]
        sup.arm(1)
        assert viewer.act(viewer.seek.start_seek) is False and "read-only" in viewer.messages[-1]
        assert sup.seek_run is None
        assert pilot.act(s.start_seek)
        run = sup.seek_run
        assert run is not None and not run.finished and [p.name for p in run.params] == ["mpc.st_opt"]
        pilot.refresh()
        assert s.keep.visible and s.revert.visible and "0 measured" in s.status.content
        viewer.refresh()
        assert not viewer.seek.keep.visible  # the viewer sees the progress, not the buttons
        assert viewer.act(lambda: viewer.seek.stop(True)) is False and "read-only" in viewer.messages[-1]
        while len(run.candidates) < 3:
            sup.step(0.5)
        pilot.refresh()
        assert "3 measured" in s.status.content or "4 measured" in s.status.content
        start = run.start_values["mpc.st_opt"]
        assert pilot.act(lambda: s.stop(False))
        assert run.finished and sup.param_value("mpc.st_opt") == start
        pilot.refresh()
        assert not s.keep.visible and "ended: stopped by" in s.status.content
        # a second seek, stopped by DISARM
        assert pilot.act(s.start_seek)
        run = sup.seek_run
        sup.step(1.0)
        sup.disarm(1)
        assert run.finished and run.reason == "the robot is disarmed"
        # a page names the configuration's parameters only
        s.params["mpc.lam_f"] = SimpleNamespace(value=True, disabled=False)
        sup.arm(1)
        assert pilot.act(s.start_seek) is False and "mpc.lam_f: not one of the seeker's parameters" in pilot.messages[-1]
    finally:
        app.stop()
        sup.stop()
