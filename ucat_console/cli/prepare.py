"""``ucat-console prepare``: compile (or load) everything a configuration runs, before it runs.

The same preparation as the console's first start (``backend.prepare``), every step
waited for, in up to two child processes, with each step's time: run it once after an
install (the Docker image does, at build time) so that no start compiles.
``ucat-console bench compile`` measures the same steps cold, in a cache of its own.
numba's cache is keyed by the compiled sources (``compiled_cache``): after an edit or a
pull this compiles afresh, and it removes the cache of the older sources.
"""

from __future__ import annotations

import argparse
import tempfile
import time


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("prepare", help="compile (or load) the planners, the loop and the plant before a run")
    p.add_argument("--config", default=None, metavar="NAME|FILE",
                   help="the configuration to prepare for (a shipped one's name or a TOML file)")
    p.add_argument("--workers", type=int, default=None, help="child processes (default: cores, at most 2)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ucat_console import compiled_cache
    from ucat_console import compiled
    from ucat_console.config import load_config

    if args.workers is not None and args.workers < 1:
        raise ValueError(f"--workers: {args.workers} must be >= 1")
    cfg = load_config(args.config)
    try:  # the steps the console needs first, each shown as it starts
        prep = compiled.prepare(cfg, compiled.console_steps(cfg), workers=args.workers)
    except RuntimeError as e:
        print(e)
        return 1
    prep.wait_all()  # the others: logged as each is done
    for s in prep.steps:
        if s.key in prep.seconds:
            print(f"  {s.text}: {prep.seconds[s.key]:.1f} s{'' if s.needed else ' (may wait: compiled after the start)'}")
    if prep.error:
        print(f"preparing failed: {prep.error}")
        return 1
    print(f"ready for the console in {prep.ready_after:.1f} s, everything in {prep.complete_after:.1f} s")
    removed = compiled_cache.prune()
    print(f"compiled code in {compiled_cache.cache_dir()}"
          + (f" ({len(removed)} entries of older sources removed)" if removed else ""))
    return 0


def measure_cold(cfg, workers: int) -> dict:
    """Every step compiled from nothing (a numba cache of its own, removed afterwards) by
    ``workers`` processes: per-step seconds, and the wall time to ready and to complete."""
    from ucat_console.backend.prepare import Preparation
    from ucat_console.compiled import console_steps

    with tempfile.TemporaryDirectory(prefix="ucat-numba-cache-") as cache:
        t0 = time.perf_counter()
        prep = Preparation(cfg, console_steps(cfg), workers=workers, env={"NUMBA_CACHE_DIR": cache})
        prep.wait_all()
        wall = time.perf_counter() - t0
    if prep.error:
        raise RuntimeError(f"compiling failed: {prep.error}")
    return {"workers": workers, "seconds": dict(prep.seconds), "ready_s": prep.ready_after,
            "complete_s": prep.complete_after, "wall_s": wall,
            "steps": [{"key": s.key, "text": s.text, "needed": s.needed} for s in prep.steps]}
