"""Getting the compiled code ready: in child processes, what the console needs first.

numba compiles the planners, the plant and the loop's kernels on their first call and keeps
them in its on-disk cache (``cache=True``); the first start on a machine compiles for a
minute or more, later starts load them in a fraction of a second. A compile holds the
interpreter the whole time, so it never runs in the console's process while the page is
served or the drivers are supervised: :func:`start` runs the :class:`Step` s its caller
gives in child processes (started with ``spawn``, as many as the machine has cores, two at
most: independent kernels compile side by side, and numba's cache takes each from
whichever process wrote it). What the steps are, and which a configuration needs, is the
caller's (``ucat_console.compiled.console_steps``); a step names the function that compiles it.

The steps needed before serving (:attr:`Step.needed`) go first; :meth:`Preparation.wait`
returns when they are done. The rest compiles on in the background;
:meth:`Preparation.done` tells whether a step is done (the supervisor refuses a switch to
a formulation whose planner is not compiled yet: a compile in the console's process would
hold the loop for a minute). ``ucat-console bench compile`` measures each step cold.
"""

from __future__ import annotations

import importlib
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
    before it serves, and what compiles it: ``target`` names a function,
    ``"package.module:function"``, that the child process imports and calls as
    ``function(cfg, *args)``."""

    key: str
    text: str
    needed: bool
    target: str
    args: tuple[Any, ...] = ()


def run_step(step: Step, cfg: AppConfig) -> None:
    """Compile (or load) what ``step`` stands for; ValueError naming a target that is not a
    function."""
    module, _, name = step.target.partition(":")
    try:
        fn = getattr(importlib.import_module(module), name) if module and name else None
    except ImportError as e:
        raise ValueError(f"step {step.key}: target {step.target!r}: {e}") from None
    if not callable(fn):
        raise ValueError(f"step {step.key}: target {step.target!r} is not a 'package.module:function'")
    fn(cfg, *step.args)


def _worker(tasks: Any, results: Any, cfg: AppConfig, steps: list[Step]) -> None:
    # the parent's configuration as it is (pickled): a mode or a robot registered by a module
    # the parent imported is not in this process's registries, and no step needs them
    by_key = {s.key: s for s in steps}
    while True:
        key = tasks.get()
        if key is None:
            return
        results.put(("start", key, 0.0))
        t0 = time.perf_counter()
        try:
            run_step(by_key[key], cfg)
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

    def __init__(self, cfg: AppConfig, steps: list[Step], on_progress: Callable[[Progress], None] = lambda p: None,
                 workers: int | None = None, env: dict[str, str] | None = None) -> None:
        """``steps``: what to prepare, as the caller says (keys unique, one needed at least)."""
        self.steps = list(steps)
        if not any(s.needed for s in self.steps):
            raise ValueError("prepare: no step is needed before serving")
        keys = [s.key for s in self.steps]
        if len(set(keys)) != len(keys):
            raise ValueError(f"prepare: a step key given twice in {', '.join(keys)}")
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
                p = ctx.Process(target=_worker, args=(self._tasks, self._results, cfg, self.steps),
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


def start(cfg: AppConfig, steps: list[Step], on_progress: Callable[[Progress], None] = lambda p: None,
          workers: int | None = None) -> Preparation:
    """Start preparing ``steps`` for ``cfg``, in child processes."""
    return Preparation(cfg, steps, on_progress, workers=workers)
