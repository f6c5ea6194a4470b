"""Fixtures of every test: recordings of runs given no folder of their own (in this process
or in a child) go to a temporary folder, never into the user's data folder."""

from __future__ import annotations

import pytest

from ucat_console.backend.sessions import files


@pytest.fixture(autouse=True, scope="session")
def _sessions_folder(tmp_path_factory: pytest.TempPathFactory):
    patch = pytest.MonkeyPatch()
    patch.setenv(files.SESSIONS_ENV, str(tmp_path_factory.mktemp("sessions")))
    yield
    patch.undo()
