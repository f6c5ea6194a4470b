"""Helpers shared by the tests: waiting on a condition, collecting events, readings and
stream messages."""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path
from typing import Any, Callable

import pytest

from ucat_console.telemetry.events import Event


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


def wait_for(predicate: Callable[[], Any], timeout: float = 10.0, what: str = "condition") -> Any:
    """Poll until ``predicate()`` is truthy; fail the test (not a timing assertion) if it never is."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            pytest.fail(f"gave up waiting for {what}")
        time.sleep(0.01)


def sim_config(directory: Path) -> Path:
    """The shipped sim-tuned recording into ``directory`` (a headless run records from
    arming), for runs of the command in a child process."""
    from ucat_console import shipped

    cfg = directory / "sim.toml"
    cfg.write_text(shipped.config_path("sim-tuned").read_text()
                   + f"\n[console]\nsessions_dir = {json.dumps(str(directory))}\n")
    return cfg
