"""The first start: the page is served at once while the compiled code is prepared (a slow
compile stood in by a preparation that waits for the test), nothing can be armed then, and
the console takes over the same port when it is ready."""

from __future__ import annotations

import threading

import pytest
from support import wait_for

from ucat_console import compiled
from ucat_console.backend import prepare
from ucat_console.backend.prepare import Preparation, Progress, Step
from ucat_console.backend.supervisor import CommandRefused
from ucat_console.bench.raw_page import RawPage
from ucat_console.cli import run as run_cli
from ucat_console.config import AppConfig, ConsoleConfig


class SlowPreparation:
    """Compiling until the test says it is done."""

    def __init__(self, steps, on_progress) -> None:
        self.error = ""
        self.go = threading.Event()
        self.on_progress = on_progress
        self.steps = steps
        self.complete = False
        on_progress(Progress(0, 2, "the planners"))

    def done(self, key) -> bool:
        return self.complete

    def wait(self, timeout=None) -> bool:
        self.go.wait()
        self.on_progress(Progress(2, 2, ""))
        return True

    def cancel(self) -> None:
        self.go.set()


def test_the_page_is_served_while_compiling_and_the_console_takes_over(make_console, monkeypatch, capsys) -> None:
    slow: list[SlowPreparation] = []
    monkeypatch.setattr(prepare, "start",
                        lambda cfg, steps, cb, workers=None: slow.append(SlowPreparation(steps, cb)) or slow[-1])
    cfg = AppConfig(console=ConsoleConfig(port=0, record_on_arm=False, heartbeat_period=0.1))
    out: dict = {}
    t = threading.Thread(target=lambda: out.setdefault("cfg", run_cli._prepare_with_page(cfg)[0]), daemon=True)
    t.start()
    url = wait_for(lambda: next((w for w in capsys.readouterr().out.split() if w.startswith("http://")), None),
                   what="the loading page's address")
    page = RawPage(url)
    # the page first shows the start, then the preparation's progress
    text = wait_for(lambda: next((str(e.get("_markdown")) for e in page.elements.values()
                                  if "step 1 of 2" in str(e.get("_markdown", ""))), None),
                    what="the progress shown")
    assert "Starting the console" in text
    assert page.find("Arm motors") is None and page.find("Take control") is None  # nothing to arm yet
    page.update("any", value=True)  # whatever a page sends, there is no input to take it
    slow[0].go.set()
    t.join(timeout=30.0)
    wait_for(lambda: page.closed, what="the loading page closing")
    port = out["cfg"].console.port
    assert f":{port}" in url
    console = make_console(out["cfg"], serve=True)
    assert console.url == url  # the same address: open pages reconnect to the console
    console_page = RawPage(url)
    console_page.wait_for("Arm motors")
    console_page.close()


def test_a_real_preparation_reports_its_steps_and_finishes() -> None:
    """The needed steps first (ready), the other formulation's planner in the background
    (complete); each step's time is reported."""
    seen: list[Progress] = []
    cfg = AppConfig()
    prep = prepare.start(cfg, compiled.console_steps(cfg), seen.append)
    assert prep.wait(900.0) and not prep.error
    needed = [s.key for s in compiled.console_steps(cfg) if s.needed]
    assert needed == ["planner:paper", "loop", "plant", "page"]
    assert all(prep.done(k) for k in needed)
    assert seen[-1].done == seen[-1].total == 4 and seen[-1].text() == "ready"
    assert prep.wait_all(900.0) and not prep.error and prep.done("planner:closed_stroke")
    assert set(prep.seconds) == {"planner:paper", "loop", "plant", "page", "planner:closed_stroke"}
    assert prep.ready_after is not None and prep.complete_after >= prep.ready_after


def test_a_formulation_still_compiling_cannot_be_switched_to(make_console) -> None:
    ready = {"paper"}
    sup = make_console(AppConfig(), planner_ready=lambda f: f in ready).sup
    try:
        sup.set_params("local", {"mpc.formulation": "closed_stroke"})
        raise AssertionError("the switch was taken")
    except CommandRefused as e:
        assert "still being compiled" in str(e)
    assert sup.loop.mpc_config.formulation == "paper"
    ready.add("closed_stroke")  # the background compile is done
    sup.set_params("local", {"mpc.formulation": "closed_stroke"})
    assert sup.loop.mpc_config.formulation == "closed_stroke"


def test_the_caller_says_what_each_step_runs() -> None:
    """The preparation runs the steps it is given, each through the function it names (in
    a child process), and refuses steps it cannot run, naming them."""

    cfg = AppConfig()
    assert {s.key for s in compiled.needed_steps(cfg)} == {"planner:paper", "loop", "plant", "page"}
    assert "plant" not in {s.key for s in compiled.console_steps(cfg.replace(robot="hardware"))}
    prep = prepare.start(cfg, [Step("nothing", "a step with nothing to compile", True, "builtins:id")],
                         workers=1)
    assert prep.wait_all(120.0) and not prep.error and prep.done("nothing")
    with pytest.raises(ValueError, match="step x: target 'nowhere' is not"):
        prepare.run_step(Step("x", "x", True, "nowhere"), cfg)
    with pytest.raises(ValueError, match="^step y: target 'no_such_module_here:f'"):
        prepare.run_step(Step("y", "y", True, "no_such_module_here:f"), cfg)
    with pytest.raises(ValueError, match="key given twice"):
        Preparation(cfg, [Step("a", "a", True, "builtins:id")] * 2)
