"""Getting the compiled code ready before the console starts: in a child process.

numba compiles the planners, the plant and the loop's kernels on their first call and keeps
them in its on-disk cache (``cache=True``); the first start on a machine compiles for a
minute or more, later starts load them in a fraction of a second. A compile holds the
interpreter the whole time, so it must not run in the console's process while the page is
served or the drivers are supervised. :func:`start` runs the compile in a child process
(started with ``spawn``) that goes through :data:`STEPS` for the configuration (the
planners of every mode; on the simulated robot, a short headless closed loop, which calls
every kernel once) and reports each step; the console's process then loads everything
from the cache.
"""

from __future__ import annotations

import logging
import multiprocessing as mp
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable

from ucat_console.config import AppConfig

log = logging.getLogger(__name__)


def _planners(cfg: AppConfig) -> None:
    from ucat_console.backend.loop.planners import warm_up

    warm_up(cfg.loop)


def _closed_loop(cfg: AppConfig) -> None:
    import tempfile

    from ucat_console.backend.loop.clock import SimulatedClock
    from ucat_console.backend.supervisor import Supervisor

    with tempfile.TemporaryDirectory() as d:
        sup = Supervisor(cfg.replace(console=cfg.console.replace(record_on_arm=False)), clock=SimulatedClock(),
                         sessions_dir=d)
        try:
            sup.step(0.5)
        finally:
            sup.stop()


#: the steps, by name: the planners first (the longest compile)
STEPS: tuple[tuple[str, Callable[[AppConfig], None]], ...] = (
    ("the planners", _planners),
    ("the simulated robot and the closed loop", _closed_loop),
)


def steps_for(cfg: AppConfig) -> list[str]:
    """The steps a configuration needs (the closed-loop run only on the simulated robot)."""
    return [name for name, _ in STEPS if cfg.robot == "sim" or name == "the planners"]


def _child(conn: Any, cfg_toml: str) -> None:
    import tomllib

    try:
        cfg = AppConfig.from_dict(tomllib.loads(cfg_toml))
        wanted = steps_for(cfg)
        for i, (name, fn) in enumerate((n, f) for n, f in STEPS if n in wanted):
            conn.send(("step", i, name))
            t0 = time.perf_counter()
            fn(cfg)
            conn.send(("done", i, name, time.perf_counter() - t0))
        conn.send(("ready",))
    except Exception as e:
        conn.send(("error", f"{type(e).__name__}: {e}"))
    finally:
        conn.close()


@dataclass(frozen=True)
class Progress:
    done: int
    total: int
    step: str  # what is being prepared now ("" when ready)

    def text(self) -> str:
        if self.done >= self.total:
            return "ready"
        return f"preparing {self.step} (step {self.done + 1} of {self.total})"


class Preparation:
    """A compile running in a child process (:func:`start`)."""

    def __init__(self, cfg: AppConfig, on_progress: Callable[[Progress], None] = lambda p: None) -> None:
        self.total = len(steps_for(cfg))
        self.on_progress = on_progress
        self.error = ""
        self.seconds: dict[str, float] = {}
        self._progress = Progress(0, self.total, steps_for(cfg)[0])
        self._done = threading.Event()
        ctx = mp.get_context("spawn")
        self._conn, child = ctx.Pipe(duplex=False)
        self._proc = ctx.Process(target=_child, args=(child, cfg.to_toml()), name="ucat-prepare", daemon=True)
        self._proc.start()
        child.close()
        threading.Thread(target=self._read, name="prepare", daemon=True).start()

    @property
    def progress(self) -> Progress:
        return self._progress

    def _set(self, p: Progress) -> None:
        self._progress = p
        try:
            self.on_progress(p)
        except Exception:
            log.exception("progress callback failed")

    def _read(self) -> None:
        try:
            while True:
                try:
                    msg = self._conn.recv()
                except (EOFError, OSError):
                    break
                if msg[0] == "step":
                    self._set(Progress(msg[1], self.total, msg[2]))
                elif msg[0] == "done":
                    self.seconds[msg[2]] = float(msg[3])
                elif msg[0] == "ready":
                    self._set(Progress(self.total, self.total, ""))
                elif msg[0] == "error":
                    self.error = msg[1]
            self._proc.join(timeout=10.0)
            if self._progress.done < self.total and not self.error:
                self.error = f"the preparing process ended early (exit code {self._proc.exitcode})"
        finally:
            self._conn.close()
            self._done.set()

    def wait(self, timeout: float | None = None) -> bool:
        """True when done (ready, or failed: see ``error``)."""
        return self._done.wait(timeout)

    def cancel(self) -> None:
        if self._proc.is_alive():
            self._proc.terminate()
            self._proc.join(timeout=5.0)


def start(cfg: AppConfig, on_progress: Callable[[Progress], None] = lambda p: None) -> Preparation:
    """Start preparing what ``cfg`` needs, in a child process."""
    return Preparation(cfg, on_progress)
