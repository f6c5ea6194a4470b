"""The page's tests; their helpers live beside this file (``plots_reference.py``, the browser
harness ``browser_harness.py``), and the fixtures here: ``server`` (a viser server of its
own), ``browser`` (Playwright's headless Chromium, Debian's, one per module), ``chromium`` (a
headless Chromium in a process group of our own, one per module) with ``frozen_browser``
(Playwright connected to it over CDP), for a test that freezes the browser's processes."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any, Iterator

import pytest

sys.path.insert(0, str(Path(__file__).parent))  # for ``import plots_reference``, ``browser_harness``


@pytest.fixture
def server() -> Iterator[Any]:
    """A viser server of its own on a free loopback port (a page's panels built on it)."""
    import viser

    s = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    yield s
    s.stop()


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    """Playwright's headless Chromium (``bench.ui.CHROMIUM``, with the benchmark's flags)."""
    sync_api = pytest.importorskip("playwright.sync_api")
    from ucat_console.bench.ui import CHROMIUM, CHROMIUM_ARGS

    if not Path(CHROMIUM).exists():
        pytest.skip(f"no Chromium at {CHROMIUM}")
    with sync_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        yield b
        b.close()


@pytest.fixture(scope="module")
def chromium() -> Iterator[Any]:
    """A headless Chromium in a process group of its own (``freeze`` / ``thaw``: SIGSTOP and
    SIGCONT on every process of it, which Playwright's own launch does not expose)."""
    from ucat_console.bench.chromium import Chromium

    try:
        c = Chromium()
    except FileNotFoundError as e:
        pytest.skip(str(e))
    yield c
    if c.stopped:
        c.thaw()
    c.close()


@pytest.fixture(scope="module")
def frozen_browser(chromium: Any) -> Iterator[Any]:
    """Playwright connected to :func:`chromium` over CDP."""
    sync_api = pytest.importorskip("playwright.sync_api")
    with sync_api.sync_playwright() as p:
        b = p.chromium.connect_over_cdp(chromium.ws_url)
        yield b
        b.close()
