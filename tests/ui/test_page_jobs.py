"""The pages' expensive actions on their own worker: one of a kind per page at a time, the
rest refused with a reason or (coalescing) replaced by the latest; pages take turns; a page
that has gone leaves nothing behind. And the sessions folder listed once for every page."""

from __future__ import annotations

import shutil
import threading
from pathlib import Path
from typing import Iterator

import pytest
from support import Console, wait_for

from ucat_console.backend.access import LOCAL
from ucat_console.backend.sessions import index
from ucat_console.config import AppConfig
from ucat_console.ui.page_jobs import PageJobs
from ucat_console.ui.session_list import SessionList


@pytest.fixture
def jobs() -> Iterator[PageJobs]:
    j = PageJobs(interval=0.0, duty=1.0)
    yield j
    j.stop()


class Gate:
    """A job that waits until released, recording that it ran."""

    def __init__(self, name: str, log: list[str]) -> None:
        self.name, self.log = name, log
        self.started = threading.Event()
        self.release = threading.Event()

    def __call__(self) -> None:
        self.started.set()
        self.log.append(self.name)
        assert self.release.wait(30.0)


def test_a_kind_waiting_or_running_for_a_page_is_refused_with_a_reason(jobs: PageJobs) -> None:
    ran: list[str] = []
    first = Gate("first", ran)
    assert jobs.submit("p", "Refresh list", first) is None
    wait_for(first.started.is_set, what="the first job running")
    why = jobs.submit("p", "Refresh list", Gate("again", ran))
    assert why is not None and why.startswith("Refresh list: the last one is still running")
    second = Gate("open", ran)
    assert jobs.submit("p", "Open", second) is None  # another kind waits its turn
    why = jobs.submit("p", "Open", Gate("open again", ran))
    assert why is not None and "still waiting" in why
    assert jobs.refused == 2
    first.release.set()
    wait_for(second.started.is_set, what="the page's next job")
    second.release.set()
    wait_for(lambda: not jobs.busy("p"), what="the page's jobs done")
    assert ran == ["first", "open"]  # one at a time, in order


def test_a_coalescing_job_is_replaced_by_the_latest(jobs: PageJobs) -> None:
    ran: list[str] = []
    block = Gate("block", ran)
    jobs.submit("p", "Seek", block)
    wait_for(block.started.is_set, what="the page's job running")
    for k in range(5):  # a dragged timeline: each position replaces the one waiting
        assert jobs.submit("p", "Seek", lambda k=k: ran.append(f"seek {k}"), coalesce=True) is None
    block.release.set()
    wait_for(lambda: not jobs.busy("p"), what="the page's jobs done")
    assert ran == ["block", "seek 4"]


def test_pages_take_turns_and_one_page_cannot_hold_the_worker(jobs: PageJobs) -> None:
    ran: list[str] = []
    block = Gate("a0", ran)
    jobs.submit("a", "x", block)
    wait_for(block.started.is_set, what="page a's job running")
    jobs.submit("a", "y", lambda: ran.append("a1"))
    jobs.submit("a", "z", lambda: ran.append("a2"))
    jobs.submit("b", "x", lambda: ran.append("b0"))
    block.release.set()
    wait_for(lambda: len(ran) == 4, what="every job")
    assert ran.index("b0") < ran.index("a2")  # b did not wait for all of a's


def test_a_page_that_goes_leaves_no_job_behind_and_is_refused_after(jobs: PageJobs) -> None:
    ran: list[str] = []
    block = Gate("running", ran)
    jobs.submit("p", "x", block)
    wait_for(block.started.is_set, what="the job running")
    jobs.submit("p", "y", lambda: ran.append("waiting"))
    jobs.forget("p")
    assert jobs.submit("p", "z", lambda: ran.append("late")) is not None
    block.release.set()
    wait_for(lambda: jobs.done == 1, what="the running job finished")
    jobs.submit("q", "x", lambda: ran.append("q"))
    wait_for(lambda: "q" in ran, what="another page's job")
    assert ran == ["running", "q"]


def test_a_pages_jobs_start_at_least_the_interval_apart() -> None:
    t = [0.0]
    jobs = PageJobs(interval=10.0, duty=1.0, clock=lambda: t[0])
    try:
        ran: list[str] = []
        jobs.submit("p", "Refresh list", lambda: ran.append("1"))
        wait_for(lambda: ran == ["1"], what="the first job")
        jobs.submit("p", "Refresh list", lambda: ran.append("2"))
        jobs.submit("q", "Refresh list", lambda: ran.append("q"))  # another page is not held
        wait_for(lambda: "q" in ran, what="the other page's job")
        assert ran == ["1", "q"] and jobs.busy("p")
        t[0] = 10.0
        with jobs._cond:
            jobs._cond.notify()  # the clock moved on
        wait_for(lambda: ran == ["1", "q", "2"], what="the page's next job after the interval")
    finally:
        jobs.stop()


def test_a_failing_job_is_logged_and_the_worker_goes_on(jobs: PageJobs, caplog) -> None:
    ran: list[str] = []

    def fail() -> None:
        raise RuntimeError("boom")

    jobs.submit("p", "x", fail)
    jobs.submit("p", "y", lambda: ran.append("after"))
    wait_for(lambda: ran == ["after"], what="the next job")
    assert any("page job 'x' failed" in r.getMessage() for r in caplog.records)


# ---------------------------------------------------------------------- the shared listing
@pytest.fixture(scope="module")
def session_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("sessions")
    sup = Console(AppConfig(), d).sup
    try:
        sup.start_recording(LOCAL, "listed")
        sup.step(0.3)
        [path] = sup.stop_recording(LOCAL)
    finally:
        sup.stop()
    return path


def test_the_folder_is_listed_again_only_when_it_changed(session_file: Path, tmp_path: Path, monkeypatch) -> None:
    shutil.copy(session_file, tmp_path / session_file.name)
    calls = [0]
    real = index.scan

    def counted(directory: object = None, budget: object = None) -> index.Listing:
        calls[0] += 1
        return real(directory, budget)

    monkeypatch.setattr(index, "scan", counted)
    listing = SessionList(tmp_path)
    first = listing.sessions()
    assert [s.session_id for s in first] == [s.session_id for s in real(tmp_path).sessions]
    assert listing.sessions() == first and calls[0] == 1  # unchanged: not read again
    (tmp_path / session_file.name).unlink()
    assert listing.sessions() == [] and calls[0] == 2  # a file went: read again
    assert SessionList(tmp_path / "missing").sessions() == []
