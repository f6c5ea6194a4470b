"""The first start: the page is served at once while the compiled code is prepared (a slow
compile stood in by a preparation that waits for the test), nothing can be armed then, and
the console takes over the same port when it is ready."""

from __future__ import annotations

import threading
from pathlib import Path

from support import wait_for

from ucat_console.backend import prepare
from ucat_console.backend.prepare import Progress
from ucat_console.backend.supervisor import Supervisor
from ucat_console.bench.raw_page import RawPage
from ucat_console.cli import run as run_cli
from ucat_console.config import AppConfig, ConsoleConfig
from ucat_console.ui.app import ConsoleApp


class SlowPreparation:
    """Compiling until the test says it is done."""

    def __init__(self, cfg, on_progress) -> None:
        self.error = ""
        self.go = threading.Event()
        self.on_progress = on_progress
        on_progress(Progress(0, 2, "the planners"))

    def wait(self, timeout=None) -> bool:
        self.go.wait()
        self.on_progress(Progress(2, 2, ""))
        return True

    def cancel(self) -> None:
        self.go.set()


def test_the_page_is_served_while_compiling_and_the_console_takes_over(tmp_path: Path, monkeypatch, capsys) -> None:
    slow: list[SlowPreparation] = []
    monkeypatch.setattr(prepare, "start", lambda cfg, cb: slow.append(SlowPreparation(cfg, cb)) or slow[-1])
    cfg = AppConfig(console=ConsoleConfig(port=0, record_on_arm=False, heartbeat_period=0.1))
    out: dict = {}
    t = threading.Thread(target=lambda: out.setdefault("cfg", run_cli._prepare_with_page(cfg)), daemon=True)
    t.start()
    url = wait_for(lambda: next((w for w in capsys.readouterr().out.split() if w.startswith("http://")), None),
                   what="the loading page's address")
    page = RawPage(url)
    text = wait_for(lambda: next((str(e.get("_markdown")) for e in page.elements.values()
                                  if "Starting the console" in str(e.get("_markdown", ""))), None),
                    what="the progress shown")
    assert "step 1 of 2" in text
    assert page.find("Arm motors") is None and page.find("Take control") is None  # nothing to arm yet
    page.update("any", value=True)  # whatever a page sends, there is no input to take it
    slow[0].go.set()
    t.join(timeout=30.0)
    wait_for(lambda: page.closed, what="the loading page closing")
    port = out["cfg"].console.port
    assert f":{port}" in url
    sup = Supervisor(out["cfg"], sessions_dir=tmp_path)
    app = ConsoleApp(sup)
    try:
        app.start()
        sup.start()
        assert app.url == url  # the same address: open pages reconnect to the console
        console_page = RawPage(url)
        console_page.wait_for("Arm motors")
        console_page.close()
    finally:
        sup.stop()
        app.stop()


def test_a_real_preparation_reports_its_steps_and_finishes() -> None:
    seen: list[Progress] = []
    prep = prepare.start(AppConfig(), seen.append)
    assert prep.wait(600.0) and not prep.error
    assert seen[-1].done == seen[-1].total == 2 and seen[-1].text() == "ready"
    assert [p.step for p in seen[:-1]] == ["the planners", "the simulated robot and the closed loop"]
