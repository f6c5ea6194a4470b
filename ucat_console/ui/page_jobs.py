"""The pages' expensive actions (listing, opening, repairing, seeking and replaying sessions)
on a worker of their own, rationed per page.

viser runs a page's callbacks in one thread pool shared by every page, first come first
served; the pilot's safety commands do not go through it (:mod:`ucat_console.ui.guard`),
but everything else does, and an action that reads session files takes a tenth of a second
to seconds of the interpreter. A page clicking "Refresh list" twenty times a second used to
fill that pool: every other page's callbacks waited behind its listings, and the control
loop lost the interpreter to them. Here a page's callback only hands such an action to
:class:`PageJobs` and returns:

* a page has at most one job of each kind waiting, and one running; a job of a kind that is
  already waiting or running for the page is refused (:meth:`PageJobs.submit` returns why,
  the page shows it), except a *coalescing* one (a seek while the timeline is dragged, a
  listing the console itself asks for), which replaces the waiting one: the latest wins;
* a page's jobs start at least :data:`INTERVAL` s apart;
* the worker (one thread) takes the pages in turn and runs at most :data:`DUTY` of the
  time: after a job of ``d`` seconds it rests ``d (1 - DUTY) / DUTY``, so however many pages
  ask, these actions leave the interpreter to the loop and the other pages most of the time.

``clock`` (the pages' intervals) is an argument; the worker waits on wall time.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass, field
from typing import Callable

log = logging.getLogger(__name__)

#: least time between the starts of two jobs of one page (s)
INTERVAL = 0.5
#: the most of the time the worker runs jobs
DUTY = 0.5


@dataclass
class _PageState:
    pending: dict[str, Callable[[], object]] = field(default_factory=dict)  # kind -> job, oldest first
    running: str | None = None
    next_start: float = float("-inf")
    gone: bool = False


class PageJobs:
    """One worker for every page's expensive actions (module docstring)."""

    def __init__(self, *, interval: float = INTERVAL, duty: float = DUTY,
                 clock: Callable[[], float] = time.monotonic, name: str = "page-jobs") -> None:
        if not 0.0 < duty <= 1.0:
            raise ValueError(f"duty: {duty!r} must be in (0, 1]")
        self.interval = float(interval)
        self.duty = float(duty)
        self.clock = clock
        self._cond = threading.Condition()
        self._pages: dict[object, _PageState] = {}
        self._turn = 0  # round-robin position among the pages
        self._rest_until = float("-inf")
        self._stopped = False
        self.done = 0  # jobs run
        self.refused = 0
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------ any thread
    def submit(self, page: object, what: str, job: Callable[[], object], *, coalesce: bool = False) -> str | None:
        """Queue ``job`` (a kind ``what``) for ``page``; None when queued, else why not."""
        with self._cond:
            if self._stopped:
                return f"{what}: the console is stopping"
            st = self._pages.get(page)
            if st is None:
                st = self._pages[page] = _PageState()
            elif st.gone:
                return f"{what}: the page has gone"
            if what in st.pending and coalesce:
                st.pending[what] = job
                return None
            if what in st.pending or (st.running == what and not coalesce):
                self.refused += 1
                state = "waiting" if what in st.pending else "running"
                return (f"{what}: the last one is still {state}; a page runs one at a time, "
                        f"at most one every {self.interval:g} s")
            st.pending[what] = job
            self._cond.notify()
            return None

    def forget(self, page: object) -> None:
        """Drop the jobs ``page`` has waiting (it has gone); a running one finishes."""
        with self._cond:
            st = self._pages.get(page)
            if st is not None:
                st.pending.clear()
                st.gone = True
                if st.running is None:
                    del self._pages[page]

    def busy(self, page: object) -> bool:
        """Whether ``page`` has a job waiting or running."""
        with self._cond:
            st = self._pages.get(page)
            return st is not None and (bool(st.pending) or st.running is not None)

    @property
    def pages(self) -> int:
        """How many pages the jobs keep a state of (a page's, until it has gone)."""
        with self._cond:
            return len(self._pages)

    def stop(self) -> None:
        with self._cond:
            self._stopped = True
            for st in self._pages.values():
                st.pending.clear()
            self._cond.notify_all()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout=5.0)

    # ------------------------------------------------------------------ worker
    def _next(self, now: float) -> tuple[object, str, Callable[[], object]] | float | None:
        """The job to run now, or the time to wait until (None: nothing queued)."""
        pages = list(self._pages.items())
        wake = float("inf")
        for k in range(len(pages)):
            page, st = pages[(self._turn + k) % len(pages)]
            if not st.pending or st.running is not None:
                continue
            due = max(st.next_start, self._rest_until)
            if due <= now:
                self._turn = (self._turn + k + 1) % len(pages)
                what = next(iter(st.pending))
                return page, what, st.pending.pop(what)
            wake = min(wake, due)
        return wake if wake < float("inf") else None

    def _run(self) -> None:
        while True:
            with self._cond:
                while True:
                    if self._stopped:
                        return
                    now = self.clock()
                    nxt = self._next(now)
                    if isinstance(nxt, tuple):
                        break
                    self._cond.wait(None if nxt is None else max(nxt - now, 0.001))
                page, what, job = nxt
                st = self._pages[page]
                st.running = what
                st.next_start = now + self.interval
            t0 = time.perf_counter()
            try:
                job()
            except Exception:  # the job shows its own refusals; a bug is logged, not fatal
                log.exception("page job %r failed", what)
            took = time.perf_counter() - t0
            with self._cond:
                st.running = None
                self.done += 1
                if st.gone and self._pages.get(page) is st:
                    del self._pages[page]
                self._rest_until = self.clock() + took * (1.0 - self.duty) / self.duty
            # nothing of the job stays while the worker waits: it may hold a page that has gone
            del nxt, job, st
