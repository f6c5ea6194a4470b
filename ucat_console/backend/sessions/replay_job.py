"""A counterfactual replay run away from the control loop: in a child process, at a lower
CPU priority, with progress and a cancel.

A replay re-plans every recorded fin plan (thousands of solves for a long session). Run in
the supervisor's process it would compete with the control loop for the interpreter; so
:class:`ReplayJob` runs :func:`~ucat_console.backend.sessions.replay.counterfactual` in a
process of its own (started with ``spawn``: nothing of the supervisor's threads is
inherited), lowered by ``nice`` steps, reporting progress over a pipe. :meth:`ReplayJob.cancel`
ends the child at once. :class:`ReplaySlot` lets one job run at a time in a console.
"""

from __future__ import annotations

import logging
import multiprocessing as mp
import os
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

from ucat_console.backend.sessions import limits
from ucat_console.backend.sessions.replay import ReplayResult

log = logging.getLogger(__name__)

#: how much lower than the console's the replay's CPU priority is (os.nice steps)
NICE = 10


def _child(conn: Any, session: str, directory: str, weights: dict[str, float], nice: int,
           review: limits.ReviewConfig) -> None:
    try:
        os.nice(nice)
    except OSError:
        pass
    try:
        from ucat_console.backend.sessions.reader import SessionParts
        from ucat_console.backend.sessions.replay import counterfactual
        from ucat_console.telemetry.channels import N_FINS, fin_plan

        # the console's [review] limits, not the defaults, in a budget of the process's own
        with SessionParts(session, directory, budget=limits.MemoryBudget(review)) as reader:
            counts = reader.message_counts()
            total = sum(counts.get(fin_plan(i), 0) for i in range(N_FINS))
            conn.send(("progress", 0, total))
            result = counterfactual(reader, weights, progress=lambda n: conn.send(("progress", n, total)))
        conn.send(("result", result))
    except Exception as e:  # the parent shows it
        conn.send(("error", f"{type(e).__name__}: {e}" if not isinstance(e, ValueError) else str(e)))
    finally:
        conn.close()


@dataclass(frozen=True)
class Progress:
    done: int
    total: int

    @property
    def fraction(self) -> float:
        return min(self.done / self.total, 1.0) if self.total > 0 else 0.0


class ReplayJob:
    """One replay of ``session`` (an id or a part file name in ``directory``) with ``weights``,
    reading the session within ``review``'s limits."""

    def __init__(self, session: str | Path, directory: str | Path, weights: Mapping[str, float],
                 *, owner: Any = None, nice: int = NICE, review: limits.ReviewConfig | None = None) -> None:
        self.session = str(session)
        self.weights = dict(weights)
        self.owner = owner
        ctx = mp.get_context("spawn")
        self._conn, child_conn = ctx.Pipe(duplex=False)
        self._proc = ctx.Process(target=_child, args=(child_conn, self.session, str(directory), self.weights, nice,
                                       review if review is not None else limits.ReviewConfig()),
                                 name="ucat-replay", daemon=True)
        self._proc.start()
        child_conn.close()
        self._lock = threading.Lock()
        self._progress = Progress(0, 0)
        self.result: ReplayResult | None = None
        self.error = ""
        self.cancelled = False
        self.cancelled_by: str | None = None
        self._done = threading.Event()
        self._reader = threading.Thread(target=self._read, name="replay-job", daemon=True)
        self._reader.start()

    def _read(self) -> None:
        try:
            while True:
                try:
                    msg = self._conn.recv()
                except (EOFError, OSError):
                    break
                if msg[0] == "progress":
                    with self._lock:
                        self._progress = Progress(int(msg[1]), int(msg[2]))
                elif msg[0] == "result":
                    self.result = msg[1]
                    with self._lock:
                        self._progress = Progress(self._progress.total, self._progress.total)
                elif msg[0] == "error":
                    self.error = str(msg[1])
            self._proc.join(timeout=5.0)
            if self.result is None and not self.error and not self.cancelled:
                self.error = f"the replay process ended without a result (exit code {self._proc.exitcode})"
        finally:
            self._conn.close()
            self._done.set()

    @property
    def progress(self) -> Progress:
        with self._lock:
            return self._progress

    @property
    def done(self) -> bool:
        return self._done.is_set()

    def wait(self, timeout: float | None = None) -> bool:
        return self._done.wait(timeout)

    def cancel(self, by: str | None = None) -> None:
        """End the replay now (nothing is kept of it); ``by`` says who for its page."""
        if self.done:
            return
        self.cancelled = True
        self.cancelled_by = by
        self._proc.terminate()
        self._proc.join(timeout=5.0)
        if self._proc.is_alive():
            self._proc.kill()
        self._done.wait(5.0)


class ReplaySlot:
    """At most one replay at a time (per console), each reading within ``review``'s limits."""

    def __init__(self, review: limits.ReviewConfig | None = None) -> None:
        self.review = review if review is not None else limits.ReviewConfig()
        self._lock = threading.Lock()
        self.job: ReplayJob | None = None

    def start(self, session: str | Path, directory: str | Path, weights: Mapping[str, float],
              owner: Any = None, *, preempt: bool = False) -> ReplayJob:
        """A new job; while another one runs, ValueError, unless ``preempt`` (the pilot's
        page), which cancels the running one first."""
        with self._lock:
            running = self.job
            if running is not None and not running.done:
                if not preempt:
                    raise ValueError(f"a counterfactual replay of {running.session} is running; "
                                     "wait for it or cancel it first")
                running.cancel("the pilot's page started one")
            self.job = ReplayJob(session, directory, weights, owner=owner, review=self.review)
            return self.job

    def cancel(self) -> None:
        job = self.job
        if job is not None:
            job.cancel()
