"""The first start: the page is served at once while the compiled code is prepared (a slow
compile stood in by a preparation that waits for the test), nothing can be armed then, and
the console takes the page's server over when it is ready."""

from __future__ import annotations

import logging
import os
import re
import signal
import socket
import threading

import pytest
from support import TOKEN, wait_for

from ucat_console import compiled
from ucat_console.backend import prepare
from ucat_console.backend.prepare import Preparation, Progress, Step
from ucat_console.backend.supervisor import CommandRefused
from ucat_console.bench.raw_page import RawPage
from ucat_console.cli import main
from ucat_console.config import AppConfig


class SlowPreparation:
    """Compiling until the test says it is done (``go``); then everything is ready."""

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
        self.complete = True
        return True

    def cancel(self) -> None:
        self.go.set()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_the_console_takes_the_loading_page_over_one_server_one_address(monkeypatch, capsys, tmp_path) -> None:
    """``ucat-console run``: the page served at once while compiling (nothing to arm, nothing a
    page sends taken), then the console on the same server: a page open during the loading
    gets the console on its socket, and the terminal shows one address box, one address,
    and viser's "Server stopped" only once the console stops."""
    slow: list[SlowPreparation] = []
    monkeypatch.setattr(prepare, "start",
                        lambda cfg, steps, cb, workers=None: slow.append(SlowPreparation(steps, cb)) or slow[-1])
    config = tmp_path / "console.toml"
    config.write_text(f'[console]\nrecord_on_arm = false\nheartbeat_period = 0.1\n[access]\ntoken = "{TOKEN}"\n')
    url = f"http://127.0.0.1:{_free_port()}"
    seen: dict = {}

    def operator() -> None:
        try:
            wait_for(lambda: slow, timeout=60.0, what="the preparation started")
            page = RawPage(url)
            # the page first shows the start, then the preparation's progress
            text = wait_for(lambda: next((str(e.get("_markdown")) for e in page.elements.values()
                                          if "step 1 of 2" in str(e.get("_markdown", ""))), None),
                            what="the progress shown")
            assert "Starting the console" in text
            assert page.find("Arm motors") is None and page.find("Take control") is None  # nothing to arm yet
            page.update("any", value=True)  # whatever a page sends, there is no input to take it
            slow[0].go.set()
            seen["arm"] = page.wait_for("Arm motors", timeout=120.0)  # the console, on the same socket
            seen["closed"] = page.closed
            seen["loading_left"] = [e for e in page.elements.values() if "Starting the console" in
                                    str(e.get("_markdown", ""))]
            page.take_control(TOKEN)
            seen["pilot"] = wait_for(lambda: page.bar.get("you_pilot"), timeout=30.0, what="the page the pilot")
            page.close()
        except BaseException as e:  # noqa: BLE001 (the test's thread says what failed)
            seen["error"] = e
        finally:
            if slow:
                slow[0].go.set()
            wait_for(lambda: signal.getsignal(signal.SIGTERM) not in (signal.SIG_DFL, None), timeout=60.0,
                     what="the console's handler of SIGTERM")
            os.kill(os.getpid(), signal.SIGTERM)  # as the operator's Ctrl-C

    monkeypatch.setenv("UCAT_CONSOLE_SESSIONS", str(tmp_path))
    thread = threading.Thread(target=operator, daemon=True)
    thread.start()
    code = main(["run", "--config", str(config), "--port", url.rsplit(":", 1)[1]])
    thread.join(timeout=30.0)
    out = capsys.readouterr().out
    assert "error" not in seen, (seen.get("error"), out)
    assert code == 0, out
    assert seen["arm"] and not seen["closed"] and not seen["loading_left"] and seen["pilot"]
    # viser's "Server stopped" once, when the console stops (after it was ready)
    assert out.count("Server stopped") == 1 and out.rfind("pilot token") < out.find("Server stopped"), out
    assert out.count("HTTP") == 1, out  # viser's address box, once
    # websockets' INFO lines ("connection rejected (200 OK)" for each page load) kept off the terminal
    assert logging.getLogger("websockets.server").getEffectiveLevel() >= logging.WARNING
    assert set(re.findall(r"(?:http|ws)://[^\s)│]+", out)) == {url, url.replace("http", "ws", 1)}, out


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
