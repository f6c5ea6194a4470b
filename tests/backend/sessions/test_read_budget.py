"""Each console reads session files within its own memory budget, set by its ``[review]``."""

from __future__ import annotations

from pathlib import Path

from ucat_console.backend.sessions.limits import ReviewConfig
from ucat_console.backend.supervisor import Supervisor
from ucat_console.config import AppConfig

MIB = 1024 * 1024


def test_two_consoles_in_one_process_keep_their_own_limits_and_budgets(tmp_path: Path) -> None:
    small = ReviewConfig(max_message=4096, max_chunk=1 * MIB, memory=16 * MIB)
    a = Supervisor(AppConfig(review=small), sessions_dir=tmp_path / "a")
    b = Supervisor(AppConfig(), sessions_dir=tmp_path / "b")
    try:
        assert a.readers.budget.config == small and b.readers.budget.config == ReviewConfig()
        a.readers.budget.reserve(8 * MIB, "a test")
        assert b.readers.budget.used == 0  # what one console holds, the other does not count
    finally:
        a.readers.budget.release(8 * MIB)
        a.stop()
        b.stop()
