"""Fixtures of every test: recordings of runs given no folder of their own (in this process
or in a child) go to a temporary folder, never into the user's data folder; the one way to
build a console (``make_console``: ``support.Console``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Iterator

import pytest
from support import Console, console_config

from ucat_console.backend.sessions import files


@pytest.fixture(autouse=True, scope="session")
def _sessions_folder(tmp_path_factory: pytest.TempPathFactory):
    patch = pytest.MonkeyPatch()
    patch.setenv(files.SESSIONS_ENV, str(tmp_path_factory.mktemp("sessions")))
    yield
    patch.undo()


@pytest.fixture
def make_console(tmp_path: Path) -> Iterator[Callable[..., Console]]:
    """``make_console(cfg=None, serve=False, **supervisor)``: a :class:`support.Console`
    recording into the test's folder (``cfg`` default: ``support.console_config()``),
    stopped at the end of the test."""
    made: list[Console] = []

    def make(cfg: Any = None, serve: bool = False, **supervisor: Any) -> Console:
        supervisor.setdefault("sessions_dir", tmp_path)
        c = Console(cfg if cfg is not None else console_config(), serve=serve, **supervisor)
        made.append(c)
        return c

    yield make
    for c in reversed(made):
        c.stop()
