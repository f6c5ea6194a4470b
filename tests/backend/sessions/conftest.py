"""Fixtures of the session tests; the helpers live in session_helpers.py beside this file."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))  # for ``import session_helpers``


@pytest.fixture
def sessions(tmp_path: Path) -> Path:
    """An empty sessions directory."""
    d = tmp_path / "sessions"
    d.mkdir()
    return d
