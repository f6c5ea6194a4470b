"""Shared fixtures of the device tests: waiting on a condition, collecting events."""

from __future__ import annotations

from typing import Any, Callable

import pytest
from support import Collector
from support import wait_for as _wait_for


@pytest.fixture
def wait_for() -> Callable[..., Any]:
    return _wait_for


@pytest.fixture
def collector() -> Callable[[], Collector]:
    return Collector
