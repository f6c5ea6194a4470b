"""``ucat-console bench pages``: pages opened and closed at random moments, and what the
console keeps of them afterwards.

Raw websocket pages (viser's protocol, as :mod:`ucat_console.bench.raw_page` speaks it)
connect to a console on the simulated robot, a few at a time, and close at seeded random
moments (:func:`churn`): some before they show (their first camera message, at which the
console builds a page's controls), some while their controls are being built, some after;
half of them close with the websocket's closing handshake, half drop the connection. Once
they are all gone, what the console keeps per page (:func:`counts`: the guard's pages and
input rules, the app's panels, pages and reviews, the page jobs' pages, viser's clients, the
pages' elements in the shared tabs) must be back where it was, and its memory with it: the Python allocations
(tracemalloc) and the process's resident size, measured after a warm-up (the first pages
fill caches and viser's thread pool).

The test ``tests/ui/test_page_lifecycle.py`` runs :func:`churn` against a console of its
own; the figures of docs/pages.md come from :func:`measure`.
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import random
import socket
import tempfile
import threading
import time
import tracemalloc
from pathlib import Path
from typing import Any, Callable

#: pages connected at once
AT_ONCE = 8
#: the longest a page stays open (s): its controls take tens of milliseconds to build
LONGEST = 0.15
#: share of the pages that close before they show
NEVER_SHOWN = 0.2


def churn(url: str, pages: int, *, seed: int = 0, at_once: int = AT_ONCE, longest: float = LONGEST) -> dict[str, int]:
    """Open ``pages`` raw pages on the console at ``url``, ``at_once`` at a time, each closed
    at a random moment within ``longest`` s (module docstring); how many did what."""
    import msgspec
    import websockets.sync.client

    from ucat_console.bench.raw_page import CAMERA, SUBPROTOCOL

    rng = random.Random(seed)
    ws_url = url.replace("http://", "ws://", 1)
    done = {"never_shown": 0, "shown": 0, "dropped": 0, "refused": 0}
    lock = threading.Lock()

    def page(show_after: float | None, close_after: float, drop: bool) -> None:
        try:
            ws = websockets.sync.client.connect(ws_url, subprotocols=[SUBPROTOCOL], compression=None,
                                                max_size=None, close_timeout=2.0)
        except Exception:  # over the cap of this address (a page closing is not yet gone)
            with lock:
                done["refused"] += 1
            return
        # read what the console sends, as a page does (else its closing handshake waits behind it)
        reader = threading.Thread(target=_drain, args=(ws,), name="bench-page", daemon=True)
        reader.start()
        try:
            if show_after is not None:
                time.sleep(show_after)
                ws.send(msgspec.msgpack.encode(CAMERA))
            time.sleep(close_after)
        except Exception:
            pass  # closed by the console meanwhile
        finally:
            if drop:  # the connection drops: no closing handshake
                try:
                    ws.socket.shutdown(socket.SHUT_RDWR)
                except OSError:
                    pass
                ws.socket.close()
            else:
                ws.close()
            reader.join(timeout=5.0)
        with lock:
            done["never_shown" if show_after is None else "shown"] += 1
            done["dropped"] += drop

    running: list[threading.Thread] = []
    for _ in range(pages):
        show_after = None if rng.random() < NEVER_SHOWN else rng.uniform(0.0, 0.02)
        t = threading.Thread(target=page, args=(show_after, rng.uniform(0.0, longest), rng.random() < 0.5),
                             name="bench-pages", daemon=True)
        t.start()
        running.append(t)
        if len(running) >= at_once:
            running.pop(0).join()
    for t in running:
        t.join()
    return done


def _drain(ws: Any) -> None:
    try:
        for _ in ws:
            pass
    except Exception:
        pass


def counts(app: Any) -> dict[str, int]:
    """What the console ``app`` keeps per page, counted."""
    return {
        "guard_pages": len(app.guard.clients),
        "guard_rules": app.guard.rules,
        "panels": len(app.panels),
        "pages": len(app.pages),
        "reviews": len(app.reviews),
        "job_pages": app.jobs.pages,
        "viser_clients": len(app.server.get_clients()),
        "shared_tab_elements": sum(len(tab._children) for tab in app.shared_tabs),
    }


def settled(app: Any, baseline: dict[str, int], timeout: float = 120.0) -> dict[str, int]:
    """Wait until :func:`counts` is back at ``baseline`` (the last pages' closing is seen
    asynchronously); the counts then, or at ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while True:
        now = counts(app)
        if now == baseline or time.monotonic() > deadline:
            return now
        time.sleep(0.05)


def rss_mb() -> float:
    """The process's resident set size (MB; Linux)."""
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def measure(pages: int = 1000, warmup: int = 200, seed: int = 0,
            progress: Callable[[str], None] = lambda s: None) -> dict[str, Any]:
    """Churn ``pages`` pages (after ``warmup`` of them) on a console of this process; what it
    kept before and after, and its memory growth."""
    from ucat_console.backend.supervisor import Supervisor
    from ucat_console.config import load_config
    from ucat_console.ui.app import ConsoleApp

    cfg = load_config("sim-tuned")
    cfg = cfg.replace(access=cfg.access.replace(token="bench-pages-token"),  # no page takes control
                      console=cfg.console.replace(port=0, record_on_arm=False))
    with tempfile.TemporaryDirectory() as tmp:
        sup = Supervisor(cfg, sessions_dir=tmp)
        app = ConsoleApp(sup)
        app.start()
        sup.start()
        try:
            empty = counts(app)
            churn(app.url, warmup, seed=seed + 1)
            baseline = settled(app, empty)
            gc.collect()
            tracemalloc.start()
            rss0 = rss_mb()
            progress(f"warmed up with {warmup} pages; {pages} pages now")
            t0 = time.monotonic()
            kinds = churn(app.url, pages, seed=seed)
            seconds = time.monotonic() - t0
            after = settled(app, baseline)
            gc.collect()
            traced = tracemalloc.get_traced_memory()[0] / 2**20
            tracemalloc.stop()
            rss1 = rss_mb()
        finally:
            sup.stop()
            app.stop()
    return {"pages": pages, "warmup": warmup, "seed": seed, "seconds": seconds, "kinds": kinds,
            "baseline": baseline, "after": after, "traced_growth_mb": traced, "rss_before_mb": rss0,
            "rss_after_mb": rss1}


def format_result(r: dict[str, Any]) -> str:
    k = r["kinds"]
    kept = ", ".join(f"{name} {r['baseline'][name]} -> {n}" for name, n in r["after"].items())
    return "\n".join([
        f"{r['pages']} pages in {r['seconds']:.0f} s (after {r['warmup']} to warm up; seed {r['seed']}): "
        f"{k['never_shown']} closed before they showed, {k['shown']} after, {k['dropped']} dropped without "
        f"a closing handshake, {k['refused']} refused",
        f"kept per page: {kept}",
        f"memory: Python allocations +{r['traced_growth_mb']:.1f} MB (tracemalloc), resident "
        f"{r['rss_before_mb']:.0f} -> {r['rss_after_mb']:.0f} MB",
    ])


def register_bench(kinds: argparse._SubParsersAction) -> None:
    p = kinds.add_parser("pages", help="pages opened and closed at random moments: what the console keeps of them")
    p.add_argument("--pages", type=int, default=1000, help="pages opened and closed")
    p.add_argument("--warmup", type=int, default=200, help="pages opened and closed first, not measured")
    p.add_argument("--seed", type=int, default=0, help="seed of the pages' moments")
    p.add_argument("--json", type=Path, default=None, help="write the results as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ucat_console.bench.machine import machine_info, speed_line

    if not 1 <= args.pages <= 1_000_000:
        raise ValueError(f"--pages: {args.pages} must be in [1, 1000000]")
    if not 0 <= args.warmup <= 1_000_000:
        raise ValueError(f"--warmup: {args.warmup} must be in [0, 1000000]")
    if args.json is not None and not args.json.parent.exists():
        raise ValueError(f"--json: directory {args.json.parent} does not exist")
    r = measure(args.pages, args.warmup, args.seed, progress=lambda s: print(s, flush=True))
    r["machine"] = machine_info(None)
    print(format_result(r))
    print(speed_line(r["machine"]))
    if args.json is not None:
        args.json.write_text(json.dumps(r, indent=2))
        print(f"wrote {args.json}")
    return 0 if r["after"] == r["baseline"] else 1
