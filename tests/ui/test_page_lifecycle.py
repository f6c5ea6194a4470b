"""A page's resources let go of whenever it goes, at any moment of its construction: what the
console keeps per page (the guard's pages and input rules, the app's panels, pages and
reviews, viser's clients, the page's elements in the shared tabs) comes back to where it was.

The pages are raw websocket clients on a console running the simulated robot in real time;
the random churn is :func:`ucat_console.bench.pages.churn`.
"""

from __future__ import annotations

import gc
import logging
import threading
import tracemalloc
import weakref
from typing import Any, Callable

import pytest
import viser
from support import TOKEN, Console, console_config, wait_for

from ucat_console.bench.pages import churn, counts, rss_mb, settled
from ucat_console.bench.raw_page import RawPage
from ucat_console.ui import panels
from ucat_console.ui.app import ConsoleApp
from ucat_console.ui.compare_panel import ComparePanel
from ucat_console.ui.playback import PlaybackPanel


@pytest.fixture
def console(make_console: Callable[..., Console]) -> Console:
    return make_console(console_config(TOKEN, 5.0, scene_rate=10.0, plot_rate=2.0, heartbeat_period=0.1),
                        serve=True)


def _baseline(console: Console) -> dict[str, int]:
    """The counts with no page, after one page came and went (what the first page fills)."""
    empty = counts(console.app)
    console.page().close()
    return _back_to(console, empty)


def _back_to(console: Console, baseline: dict[str, int]) -> dict[str, int]:
    now = settled(console.app, baseline, timeout=30.0)
    assert now == baseline, f"kept after the pages went: {now}, before: {baseline}"
    return now


#: what a page is made of that must go with it: viser's handle and the console's panels
_PAGE_PARTS = (viser.ClientHandle, panels.ControlPanel, PlaybackPanel, ComparePanel)


def _track(monkeypatch: pytest.MonkeyPatch) -> weakref.WeakSet[Any]:
    """Every page part made from now on, held weakly. (Not ``gc.get_objects()``: called while
    the console's threads build tuples, it hands out a tuple still being built, and CPython
    then fails that thread's ``tuple(...)`` with a SystemError.)"""
    made: weakref.WeakSet[Any] = weakref.WeakSet()

    def tracking(real: Callable[..., None]) -> Callable[..., None]:
        def __init__(self: Any, *args: Any, **kwargs: Any) -> None:
            real(self, *args, **kwargs)
            made.add(self)
        return __init__

    for cls in _PAGE_PARTS:
        monkeypatch.setattr(cls, "__init__", tracking(cls.__init__))
    return made


def _pages_alive(made: weakref.WeakSet[Any]) -> list[str]:
    """What is alive (after a collection) of the page parts made."""
    gc.collect()
    return sorted(type(o).__name__ for o in list(made))


def _holders(made: weakref.WeakSet[Any]) -> str:
    """What is alive of the page parts and, for a few, the types of what refers to them (the diagnosis)."""
    gc.collect()
    alive = list(made)
    lines = []
    for o in alive[:3]:
        refs = []
        for r in gc.get_referrers(o):
            if r is alive:
                continue
            name = type(r).__name__
            if isinstance(r, (dict, list)):
                owners = [type(x).__name__ for x in gc.get_referrers(r) if x is not alive][:3]
                name += f"({len(r)}) of {owners}"
            elif name == "frame":
                name += f" {r.f_code.co_filename.rsplit('/', 1)[-1]}:{r.f_lineno} {r.f_code.co_name}"
            if name != "cell":
                refs.append(name)
        lines.append(f"{type(o).__name__} held by {refs}")
    return f"{len(alive)} objects; " + "; ".join(lines)


def _all_gone(console: Console) -> bool:
    return not console.app.server.get_clients() and not console.app.guard.clients


@pytest.mark.parametrize("moment", ["its controls", "its review"])
def test_a_page_that_goes_while_its_controls_are_built_leaves_nothing(
        console: Console, monkeypatch: pytest.MonkeyPatch, moment: str) -> None:
    baseline = _baseline(console)
    app = console.app
    opened: list[RawPage] = []
    went = threading.Event()

    def close_first(real: Callable[..., Any]) -> Callable[..., Any]:
        def closing(*args: Any, **kwargs: Any) -> Any:  # in the build, before this part of it
            wait_for(lambda: opened, what="the page")
            opened[0].close()
            wait_for(lambda: _all_gone(console), what="the page gone")
            went.set()
            return real(*args, **kwargs)
        return closing

    if moment == "its controls":  # before its inputs are registered with the guard
        monkeypatch.setattr(panels.ControlPanel, "_register_inputs",
                            close_first(panels.ControlPanel._register_inputs))
    else:  # its controls built, its review not yet
        monkeypatch.setattr(app, "build_review", close_first(app.build_review))
    opened.append(RawPage(console.url))
    wait_for(went.is_set, timeout=30.0, what="the page gone during its build")
    _back_to(console, baseline)


def test_a_page_that_goes_while_waiting_for_its_build_is_never_built(
        console: Console, monkeypatch: pytest.MonkeyPatch) -> None:
    baseline = _baseline(console)
    app = console.app
    built: list[int] = []
    real = ConsoleApp.build_review
    monkeypatch.setattr(ConsoleApp, "build_review",
                        lambda self, *a, **kw: built.append(1) or real(self, *a, **kw))
    with app._build_lock:  # another page being built
        page = RawPage(console.url)
        wait_for(lambda: app.server.get_clients(), what="the page shown")
        page.close()
        wait_for(lambda: _all_gone(console), what="the page gone")
    _back_to(console, baseline)
    assert not built


def test_a_page_that_goes_after_its_build_leaves_nothing(console: Console) -> None:
    baseline = _baseline(console)
    pages = [console.page() for _ in range(3)]
    assert console.app.guard.rules > baseline["guard_rules"]
    for p in pages:
        p.close()
    _back_to(console, baseline)


def test_a_job_of_a_page_that_goes_while_it_runs_ends_quietly(
        console: Console, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    """The page's listing for its comparison runs on the page jobs; the page goes meanwhile:
    the job finds its elements removed and ends without an error, and nothing of the page stays."""
    baseline = _baseline(console)
    running, release = threading.Event(), threading.Event()
    real = ComparePanel.refresh

    def held(self: ComparePanel) -> None:
        running.set()
        release.wait(30.0)
        real(self)

    monkeypatch.setattr(ComparePanel, "refresh", held)
    page = console.page()
    wait_for(running.is_set, what="the page's listing running")
    page.close()
    wait_for(lambda: _all_gone(console), what="the page gone")
    release.set()
    _back_to(console, baseline)  # the page jobs too: the job has ended
    errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert not errors


@pytest.mark.slow
@pytest.mark.timeout(1500)  # 1,200 pages under tracemalloc: minutes on a busy machine
def test_a_thousand_pages_closing_at_random_moments_leave_nothing_and_memory_flat(
        console: Console, caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch) -> None:
    """1,000 pages, 8 at a time, each closed at a seeded random moment: a fifth before it
    shows, the others while or after their controls are built, half of them dropping the
    connection; after 200 such pages to warm up (caches, viser's thread pool). No page's
    handle or controls stay, nothing logs an error, and the Python allocations grow by less
    than a quarter of what the pages' panels and elements would hold had each stayed (about
    40 kB a page): the rest is the supervisor's own windows filling while the pages come and go."""
    app = console.app
    made = _track(monkeypatch)
    empty = counts(app)
    churn(console.url, 200, seed=1)
    baseline = _back_to(console, empty)
    gc.collect()
    tracemalloc.start()
    rss = rss_mb()
    try:
        kinds = churn(console.url, 1000, seed=0)
        _back_to(console, baseline)
        # the builds of the last pages, gone while they waited for their turn, end meanwhile
        try:
            wait_for(lambda: not _pages_alive(made), timeout=300.0, poll=0.5,
                     what="nothing alive of the pages gone")
        except pytest.fail.Exception:
            pytest.fail(f"alive after the pages went: {_holders(made)}")
        grown = tracemalloc.get_traced_memory()[0] / 2**20
        resident = rss_mb()
        # the loop's watchdog reports a loop the busy machine held back (tracemalloc slows every
        # thread): the failsafe doing its work, not a page's error
        errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR
                  and r.name.startswith(("ucat_console", "viser"))
                  and not r.getMessage().startswith("failsafe loop_watchdog")]
    finally:
        # the console stops first: its plots and planners run compiled code that allocates
        # without holding the GIL, and CPython before 3.13 can crash when tracemalloc stops
        # meanwhile (python/cpython#128679)
        console.stop()
        tracemalloc.stop()
    print(f"1000 pages: {kinds}; Python allocations +{grown:.1f} MB, resident {rss:.0f} -> {resident:.0f} MB")
    assert kinds["never_shown"] > 100 and kinds["shown"] > 600 and kinds["dropped"] > 300
    assert not errors, f"{len(errors)} errors logged, the first: {errors[0]}"
    assert grown < 10.0, f"{grown:.1f} MB of Python allocations kept after 1000 pages"
