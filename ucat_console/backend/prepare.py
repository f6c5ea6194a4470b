"""Getting the compiled code ready: in child processes, what the console needs first.

numba compiles the planners, the plant and the loop's kernels on their first call and keeps
them in its on-disk cache (``cache=True``); the first start on a machine compiles for a
minute or more, later starts load them in a fraction of a second. A compile holds the
interpreter the whole time, so it never runs in the console's process while the page is
served or the drivers are supervised: :func:`start` runs the :class:`Step` s a
configuration needs in child processes (started with ``spawn``, as many as the machine
has cores, two at most: independent kernels compile side by side, and numba's cache takes
each from whichever process wrote it).

The steps the console needs before it serves (:attr:`Step.needed`: the configured
formulation's planner, the closed loop's kernels, the page's plot series, and the
simulated robot where the robot is simulated) go first; :meth:`Preparation.wait` returns when they are done. The rest (the
other formulation's planner, which the operator may switch to live) compiles on in the
background; :meth:`Preparation.done` tells whether a step is done, and the supervisor
refuses a switch to a formulation whose planner is not compiled yet (a compile in the
console's process would hold the loop for a minute). ``ucat-console bench compile``
measures each step cold.
"""

from __future__ import annotations

import logging
import multiprocessing as mp
import os
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable

from ucat_console.config import AppConfig

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Step:
    """One thing to compile: its key, what it is (for people), whether the console needs it
    before it serves."""

    key: str
    text: str
    needed: bool


def planner_step(formulation: str) -> str:
    return f"planner:{formulation}"


def _formulation_text(formulation: str) -> str:
    return "the paper's MPC" if formulation == "paper" else f"the {formulation.replace('_', '-')} MPC"


def steps_for(cfg: AppConfig) -> list[Step]:
    """The steps ``cfg`` needs, the ones needed before serving first."""
    from ucat_console.control.params import FORMULATIONS

    mine = cfg.mpc.formulation
    steps = [Step(planner_step(mine), f"{_formulation_text(mine)} and the baseline", True),
             Step("loop", "the closed loop's per-sample kernels", True)]
    if simulated(cfg):
        steps.append(Step("plant", "the simulated robot", True))
    steps.append(Step("page", "the page's plot series", True))
    if cfg.mpc.solver == "numba":
        steps += [Step(planner_step(f), _formulation_text(f), False) for f in FORMULATIONS if f != mine]
    return steps


def simulated(cfg: AppConfig) -> bool:
    """Whether the robot is (or is behind the emulators of) the simulated plant."""
    return cfg.robot == "sim" or cfg.devices.robot == "sim-devices"


def run_step(key: str, cfg: AppConfig) -> None:
    """Compile (or load) what step ``key`` stands for."""
    if key.startswith("planner:"):
        from ucat_console.backend.loop.kernels_warm_up import warm_up

        warm_up(cfg.loop, formulations=(key.split(":", 1)[1],))
    elif key == "loop":
        from ucat_console.backend.loop.kernels_warm_up import warm_up_loop

        warm_up_loop(cfg.loop)
    elif key == "page":
        from ucat_console.ui.plots import warm_up

        warm_up()
    elif key == "plant":
        from ucat_console.backend.loop.closed_loop import ClosedLoop
        from ucat_console.backend.sim_robot_io import SimRobotIO

        io = SimRobotIO(cfg.plant, depth=1.0, velocity=0.1)
        io.advance_to(0.05)  # the plant one event at a time (behind the console's arming gate)
        io.plant.advance(0.002)
        io.plant.sample_sensors()
        # the plant running the loop's core (headless runs), before any plan is due
        with ClosedLoop(cfg.loop.replace(mode="baseline"), SimRobotIO(cfg.plant, depth=1.0)) as loop:
            loop.run_until(0.05)
    else:
        raise ValueError(f"step: {key!r} is not a preparation step")


def _worker(tasks: Any, results: Any, cfg_toml: str) -> None:
    import tomllib

    try:
        cfg = AppConfig.from_dict(tomllib.loads(cfg_toml))
    except Exception as e:
        results.put(("error", "", f"{type(e).__name__}: {e}"))
        return
    while True:
        key = tasks.get()
        if key is None:
            return
        results.put(("start", key, 0.0))
        t0 = time.perf_counter()
        try:
            run_step(key, cfg)
        except Exception as e:
            results.put(("error", key, f"{type(e).__name__}: {e}"))
            return
        results.put(("done", key, time.perf_counter() - t0))


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
    """Compiles running in child processes (:func:`start`)."""

    def __init__(self, cfg: AppConfig, on_progress: Callable[[Progress], None] = lambda p: None,
                 workers: int | None = None, env: dict[str, str] | None = None,
                 steps: list[Step] | None = None) -> None:
        """``steps``: what to prepare (default :func:`steps_for` ``cfg``)."""
        self.steps = steps_for(cfg) if steps is None else list(steps)
        if not any(s.needed for s in self.steps):
            raise ValueError("prepare: no step is needed before serving")
        self.needed = [s for s in self.steps if s.needed]
        self.total = len(self.needed)
        self.on_progress = on_progress
        self.error = ""
        self.seconds: dict[str, float] = {}
        self.started_at = time.perf_counter()
        self.ready_after: float | None = None  # s from start to the needed steps done
        self.complete_after: float | None = None  # s from start to every step done
        self._done: set[str] = set()
        self._running: list[str] = []
        self._lock = threading.Lock()
        self._progress = Progress(0, self.total, self.needed[0].text)
        self._ready = threading.Event()
        self._complete = threading.Event()
        n = workers if workers is not None else min(2, max(1, len(os.sched_getaffinity(0))
                                                              if hasattr(os, "sched_getaffinity") else 1))
        ctx = mp.get_context("spawn")
        self._tasks, self._results = ctx.Queue(), ctx.Queue()
        for s in self.steps:
            self._tasks.put(s.key)
        self._procs = []
        saved = dict(os.environ)
        try:
            os.environ.update(env or {})
            for i in range(max(1, min(n, len(self.steps)))):
                self._tasks.put(None)
                p = ctx.Process(target=_worker, args=(self._tasks, self._results, cfg.to_toml()),
                                name=f"ucat-prepare-{i}", daemon=True)
                p.start()
                self._procs.append(p)
        finally:
            os.environ.clear()
            os.environ.update(saved)
        threading.Thread(target=self._read, name="prepare", daemon=True).start()

    @property
    def progress(self) -> Progress:
        return self._progress

    def done(self, key: str) -> bool:
        """Whether step ``key`` is compiled (loaded from the cache from now on)."""
        with self._lock:
            return key in self._done

    @property
    def running(self) -> list[str]:
        """What the child processes are compiling now (for people)."""
        with self._lock:
            return [self._text(k) for k in self._running]

    @property
    def complete(self) -> bool:
        return self._complete.is_set()

    def _set(self, p: Progress) -> None:
        self._progress = p
        try:
            self.on_progress(p)
        except Exception:
            log.exception("progress callback failed")

    def _text(self, key: str) -> str:
        return next((s.text for s in self.steps if s.key == key), key)

    def _read(self) -> None:
        keys = {s.key for s in self.steps}
        needed = {s.key for s in self.needed}
        try:
            while True:
                with self._lock:
                    finished = self._done >= keys
                if finished or self.error:
                    break
                try:
                    kind, key, value = self._results.get(timeout=1.0)
                except Exception:  # queue.Empty: are the workers still there?
                    if not any(p.is_alive() for p in self._procs):
                        self.error = self.error or "the preparing processes ended early (exit codes " + \
                            ", ".join(str(p.exitcode) for p in self._procs) + ")"
                    continue
                if kind == "start":
                    with self._lock:
                        self._running.append(key)
                    if key in needed:
                        with self._lock:
                            n = len(self._done & needed)
                        self._set(Progress(n, self.total, self._text(key)))
                elif kind == "done":
                    with self._lock:
                        self._done.add(key)
                        if key in self._running:
                            self._running.remove(key)
                        n = len(self._done & needed)
                        running = [k for k in self._running if k in needed]
                    self.seconds[key] = float(value)
                    if n >= self.total and not self._ready.is_set():
                        self.ready_after = time.perf_counter() - self.started_at
                        self._set(Progress(n, self.total, ""))
                        self._ready.set()
                    elif key in needed:
                        self._set(Progress(n, self.total, self._text(running[0]) if running else ""))
                    if key not in needed:
                        log.info("compiled %s in the background (%.0f s)", self._text(key), value)
                elif kind == "error":
                    self.error = f"{self._text(key)}: {value}" if key else str(value)
            if not self.error:
                self.complete_after = time.perf_counter() - self.started_at
        finally:
            for p in self._procs:
                p.join(timeout=10.0)
            self._ready.set()
            self._complete.set()

    def wait(self, timeout: float | None = None) -> bool:
        """True when the needed steps are done (or failed: see ``error``)."""
        return self._ready.wait(timeout)

    def wait_all(self, timeout: float | None = None) -> bool:
        """True when every step is done (or failed)."""
        return self._complete.wait(timeout)

    def cancel(self) -> None:
        for p in self._procs:
            if p.is_alive():
                p.terminate()
                p.join(timeout=5.0)


def start(cfg: AppConfig, on_progress: Callable[[Progress], None] = lambda p: None,
          steps: list[Step] | None = None, workers: int | None = None) -> Preparation:
    """Start preparing what ``cfg`` needs (or ``steps``), in child processes."""
    return Preparation(cfg, on_progress, workers=workers, steps=steps)
