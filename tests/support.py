"""Helpers shared by the tests, one of each: waiting on a condition (:func:`wait_for`), a
clock the test sets (:class:`FakeClock`), a console (:class:`Console`: the supervisor on the
simulated robot, with its page when served; the ``make_console`` fixture of
``conftest.py``), collecting events, readings and stream messages."""

from __future__ import annotations

import json
import math
import threading
import time
from pathlib import Path
from typing import Any, Callable

import pytest

from ucat_console.backend.loop.clock import Clock
from ucat_console.telemetry.events import Event

#: the pilot token of the consoles the tests build
TOKEN = "pool-side-token"


class Collector:
    """Thread-safe list used as a reading callback or an event sink."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._items: list[Any] = []

    def __call__(self, item: Any) -> None:
        with self._lock:
            self._items.append(item)

    @property
    def items(self) -> list[Any]:
        with self._lock:
            return list(self._items)

    def __len__(self) -> int:
        with self._lock:
            return len(self._items)

    def codes(self) -> list[str]:
        return [e.code for e in self.items if isinstance(e, Event)]

    def with_code(self, code: str) -> list[Event]:
        return [e for e in self.items if isinstance(e, Event) and e.code == code]

    def find(self, source: str, codes: tuple[str, ...], after: int = 0) -> Event | None:
        """The first event from ``source`` with one of ``codes``, from item ``after`` on."""
        return next((e for e in self.items[after:]
                     if isinstance(e, Event) and e.source == source and e.code in codes), None)


class StreamSink:
    """Every ``(channel, message)`` published on a telemetry stream, taken in batches."""

    def __init__(self, stream: Any) -> None:
        self.got: list[tuple[str, object]] = []
        self._lock = threading.Lock()
        stream.subscribe(self)

    def __call__(self, channel: str, msg: object) -> None:
        with self._lock:
            self.got.append((channel, msg))

    def take(self) -> list[tuple[str, object]]:
        """What arrived since the last take."""
        with self._lock:
            out, self.got = self.got, []
        return out


def wait_for(predicate: Callable[[], Any], timeout: float = 10.0, what: str = "condition",
             poll: float = 0.01) -> Any:
    """Poll until ``predicate()`` is truthy and return its value; fail the test (not a
    timing assertion: the deadline is for a machine that never gets there) if it never is."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            pytest.fail(f"gave up waiting for {what} ({timeout:g} s)")
        time.sleep(poll)


class FakeClock(Clock):
    """Time the test sets, for whatever takes a clock.

    * A wall clock (``clock()`` is :attr:`now`; :meth:`advance` moves it): the access
      control's lockouts, the devices' faults, the page link's answers.
    * A paced loop clock whose wall time is what the loop waited for: every event waits,
      whatever the machine's speed (a paced clock on a busy machine may run behind and wait
      for none), and no plan is ever late by it.
    """

    threaded = True
    paced = True

    def __init__(self, now: float = 0.0) -> None:
        self.now = now

    def __call__(self) -> float:
        return self.now

    def advance(self, dt: float) -> float:
        self.now += dt
        return self.now

    def start(self, t0: float) -> bool:
        self.now = t0
        return False

    def wait_until(self, t: float) -> None:
        self.now = max(self.now, t)

    def wall_deadline(self, t: float) -> float:
        return math.inf

    def horizon(self, t_done: float) -> float:
        return self.now


def console_config(token: str = TOKEN, pilot_gone: Any = None, base: str | None = None, **console: Any) -> Any:
    """The tests' console configuration: the simulated robot (the defaults, or the shipped
    configuration ``base``: "sim-tuned" for a robot that swims), a fixed pilot token, a free
    port, no recording at arming and no report after a recording (unless given), ``console``
    settings and, when given, the pilot-gone failsafe rule (a FailsafeRule, or its timeout in
    s: hold)."""
    from ucat_console.backend.failsafe_config import FailsafeRule
    from ucat_console.config import load_config

    cfg = load_config(base)
    cfg = cfg.replace(access=cfg.access.replace(token=token),
                      console=cfg.console.replace(**{"port": 0, "record_on_arm": False, "write_reports": False,
                                                     **console}))
    if pilot_gone is not None:
        rule = pilot_gone if isinstance(pilot_gone, FailsafeRule) else FailsafeRule("hold", float(pilot_gone))
        cfg = cfg.replace(failsafe=cfg.failsafe.replace(pilot_gone=rule))
    return cfg


class Console:
    """A supervisor (its events collected) and, when ``serve``, its page, both running in
    real time; otherwise the supervisor alone, on a simulated clock unless ``clock`` is
    given, stepped by the test (``sup.step``). :meth:`stop` stops both (once)."""

    def __init__(self, cfg: Any, sessions_dir: Path, serve: bool = False, **supervisor: Any) -> None:
        from ucat_console.backend.loop.clock import SimulatedClock
        from ucat_console.backend.supervisor import Supervisor
        from ucat_console.telemetry import channels as ch

        if not serve:
            supervisor.setdefault("clock", SimulatedClock())
        self.sup = Supervisor(cfg, sessions_dir=sessions_dir, **supervisor)
        self.events: list[Any] = []
        self.sup.stream.subscribe(lambda c, m: self.events.append(m), [ch.EVENTS])
        self.app: Any = None
        if serve:
            from ucat_console.ui.app import ConsoleApp

            try:
                self.app = ConsoleApp(self.sup)
                self.app.start()
                self.sup.start()
            except BaseException:
                self.stop()
                raise
        self.url: str = self.app.url if self.app is not None else ""

    def event(self, source: str, code: str, after: int = 0) -> Any:
        """The first event from ``source`` with ``code``, from event ``after`` on (None: none)."""
        return next((e for e in self.events[after:] if e.source == source and e.code == code), None)

    def codes(self, source: str | None = None) -> list[str]:
        return [e.code for e in self.events if source is None or e.source == source]

    def page(self, **kw: Any) -> Any:
        """A raw websocket page on the console (``bench.raw_page.RawPage``), its controls shown."""
        from ucat_console.bench.raw_page import RawPage

        p = RawPage(self.url, **kw)
        p.wait_for("Take control")
        return p

    def cid_of(self, page: Any) -> int:
        """The client id the console gave ``page`` (its role line names it)."""
        def find() -> list[int]:  # a list: client 0 is a valid id
            for el in list(page.elements.values()):
                text = str(el.get("_markdown", ""))
                if "(client " in text and "Read-only" in text:
                    return [int(text.split("(client ", 1)[1].split(")", 1)[0])]
            return []
        return wait_for(find, what="the page's role line")[0]

    def fly(self, pilot: int, token: str) -> None:
        """Start the supervisor (in real time when made with ``clock=None``) with page
        ``pilot`` connected and in control by ``token``."""
        self.sup.start()
        self.sup.client_connected(pilot)
        assert self.sup.take_control(pilot, token)

    def stop(self) -> None:
        app, self.app = self.app, None
        try:
            self.sup.stop()
        finally:
            if app is not None:
                app.stop()


def sim_config(directory: Path) -> Path:
    """The shipped sim-tuned recording into ``directory`` (a headless run records from
    arming), for runs of the command in a child process."""
    from ucat_console import shipped

    cfg = directory / "sim.toml"
    cfg.write_text(shipped.config_path("sim-tuned").read_text()
                   + f"\n[console]\nsessions_dir = {json.dumps(str(directory))}\n")
    return cfg


#: a short scripted manoeuvre for the tests that record one (two segments, the second in the baseline)
SHORT_LADDER = """\
depth = 0.5
settle = 1.0
measure = 2.0

[[segment]]
label = "slow"
velocity = 0.1

[[segment]]
label = "fast"
velocity = 0.25
mode = "baseline"
"""
