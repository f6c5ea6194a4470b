"""The compiled code before a command runs, with its progress on the terminal.

numba compiles the planners, the loop's kernels and the plant at their first call (minutes
the first time on a machine, from its cache in seconds later: ``backend.prepare``). A
command that runs them prepares them first in child processes (:func:`prepare`), printing
each step as it starts and the time it has taken, so that a first run shows what it waits
for and nothing compiles inside a running loop (where the loop would not answer its
commands). ``ucat-console prepare`` does the same ahead of time.

``run`` prepares behind its loading page (or, for a headless run, only what the run needs);
``replay``, ``identify --run``, ``experiment``, ``sweep`` and the benchmarks but ``bench
compile`` (which times the compile itself) prepare every step (:func:`prepare_all`) once
their arguments are checked.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any, Callable

#: seconds between the "still preparing" lines while one step takes long
STILL_EVERY = 15.0


def every_step(cfg: Any) -> list[Any]:
    """Every step ``cfg`` may run, each waited for (what a command that runs any
    formulation needs)."""
    from ucat_console.backend.prepare import steps_for

    return [dataclasses.replace(s, needed=True) for s in steps_for(cfg)]


def needed_steps(cfg: Any) -> list[Any]:
    """The steps ``cfg``'s console needs to start, the others left out (a headless run,
    which switches no formulation)."""
    from ucat_console.backend.prepare import steps_for

    return [s for s in steps_for(cfg) if s.needed]


def prepare_all(config: Any = None) -> Any:
    """:func:`prepare` every step of the configuration ``config`` names (the defaults: the
    simulated robot, every formulation)."""
    from ucat_console.config import load_config

    cfg = load_config(config)
    return prepare(cfg, every_step(cfg))


def prepare(cfg: Any, steps: list[Any] | None = None,
            on_progress: Callable[[Any], None] | None = None, workers: int | None = None) -> Any:
    """Compile (or load) ``steps`` (default: the console's, ``backend.prepare.steps_for``)
    in child processes, printing the progress, and return the preparation once the needed
    ones are done (the others go on in the background). RuntimeError when a step fails;
    Ctrl-C stops the child processes. ``workers``: child processes (default: cores, at most 2)."""
    from ucat_console.backend import prepare as backend_prepare

    print("preparing the compiled code (the first run on a machine compiles it, minutes; "
          "`ucat-console prepare` does it ahead)", flush=True)
    t0 = time.monotonic()
    shown: set[str] = set()

    def progress(p: Any) -> None:
        if on_progress is not None:
            on_progress(p)
        if p.step and p.step not in shown:  # each step once, as it starts
            shown.add(p.step)
            print(f"  preparing {p.step} ({p.done} of {p.total} done, {time.monotonic() - t0:.0f} s)",
                  flush=True)

    prep = backend_prepare.start(cfg, progress, steps, workers)
    try:
        while not prep.wait(STILL_EVERY):  # a compile gives no progress of its own: the time it takes
            p = prep.progress
            print(f"  still preparing {'; '.join(prep.running) or p.step} ({p.done} of {p.total} done, "
                  f"{time.monotonic() - t0:.0f} s)", flush=True)
    except BaseException:
        prep.cancel()
        raise
    if prep.error:
        raise RuntimeError(f"preparing the compiled code failed: {prep.error}")
    print(f"compiled code ready in {time.monotonic() - t0:.1f} s", flush=True)
    return prep
