"""What the safety benchmarks share (``ucat-console bench safety``, :mod:`.safety`): a console
on the simulated robot with a known pilot token, waiting for a condition, the pilot's raw page,
the time of an event."""

from __future__ import annotations

import time
from typing import Any

TOKEN = "safety-bench-token"


def start_console(tmp: str, pilot_gone: float, port: int = 0, pages: int = 0) -> tuple[Any, Any, list]:
    """A console on the simulated robot with :data:`TOKEN`; ``pages``: at least this many
    pages may come from one address (the bench's pages all come from 127.0.0.1)."""
    from ucat_console.backend.supervisor import Supervisor
    from ucat_console.backend.access import AccessConfig
    from ucat_console.backend.failsafe_config import FailsafeConfig, FailsafeRule
    from ucat_console.config import ConsoleConfig, load_config
    from ucat_console.telemetry import channels as ch
    from ucat_console.ui.app import ConsoleApp

    cfg = load_config("sim-tuned").replace(
        access=AccessConfig(token=TOKEN),
        console=ConsoleConfig(port=port, record_on_arm=False,
                              max_pages_per_address=max(pages, ConsoleConfig().max_pages_per_address)),
        failsafe=FailsafeConfig(pilot_gone=FailsafeRule("hold", pilot_gone)),
    )
    sup = Supervisor(cfg, sessions_dir=tmp)
    events: list = []
    sup.stream.subscribe(lambda c, m: events.append((time.monotonic(), m)), [ch.EVENTS])
    app = ConsoleApp(sup)
    app.start()
    sup.start()
    return sup, app, events


def wait_until(pred: Any, timeout: float, what: str) -> Any:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        v = pred()
        if v:
            return v
        time.sleep(0.005)
    raise TimeoutError(f"gave up waiting for {what}")


def sim_tuned() -> Any:
    from ucat_console.config import load_config

    return load_config("sim-tuned")


def take_pilot(app: Any, sup: Any, **kw: Any) -> Any:
    from ucat_console.bench.raw_page import RawPage

    page = RawPage(app.url, **kw)
    page.wait_for("Take control", timeout=120.0)
    before = sup.access.pilot
    page.take_control(TOKEN)
    wait_until(lambda: sup.access.pilot not in (None, before), 60.0, "the pilot taking control")
    return page


def event_time(events: list, after: int, source: str, code: str, timeout: float) -> float | None:
    """The time (monotonic) of the first event ``source``/``code`` from event ``after`` on,
    waiting up to ``timeout`` s for it (None: none came)."""
    try:
        return wait_until(lambda: next((t for t, e in events[after:] if e.source == source and e.code == code), None),
                     timeout, f"{source}/{code}")
    except TimeoutError:
        return None
