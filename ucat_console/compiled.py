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
their arguments are checked. Outside the tool packages' layers (``cli`` > ``experiments`` >
``bench`` > ``ui`` > ``backend``): the command line and the benchmarks both call it, and a
step may compile the page's code.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any, Callable

#: seconds between the "still preparing" lines while one step takes long
STILL_EVERY = 15.0


def planner_step(formulation: str) -> str:
    """The key of the step that compiles ``formulation``'s planner."""
    return f"planner:{formulation}"


def _formulation_text(formulation: str) -> str:
    return "the paper's MPC" if formulation == "paper" else f"the {formulation.replace('_', '-')} MPC"


def console_steps(cfg: Any) -> list[Any]:
    """The steps ``cfg``'s console runs, the ones it needs before it serves first (the
    configured formulation's planner, the closed loop's kernels, the simulated robot where
    the robot is simulated, the page's plot series); the other formulations' planners, which
    the operator may switch to live, after."""
    from ucat_console.backend.prepare import Step
    from ucat_console.control.params import FORMULATIONS

    here = __name__
    mine = cfg.loop.mpc.formulation
    steps = [Step(planner_step(mine), f"{_formulation_text(mine)} and the baseline", True,
                  f"{here}:compile_planner", (mine,)),
             Step("loop", "the closed loop's per-sample kernels", True, f"{here}:compile_loop")]
    if cfg.simulated:
        steps.append(Step("plant", "the simulated robot", True, f"{here}:compile_plant"))
    steps.append(Step("page", "the page's plot series", True, f"{here}:compile_page"))
    if cfg.loop.mpc.solver == "numba":
        steps += [Step(planner_step(f), _formulation_text(f), False, f"{here}:compile_planner", (f,))
                  for f in FORMULATIONS if f != mine]
    return steps


def every_step(cfg: Any) -> list[Any]:
    """Every step ``cfg`` may run, each waited for (what a command that runs any
    formulation needs)."""
    return [dataclasses.replace(s, needed=True) for s in console_steps(cfg)]


def needed_steps(cfg: Any) -> list[Any]:
    """The steps ``cfg``'s console needs to start, the others left out (a headless run,
    which switches no formulation)."""
    return [s for s in console_steps(cfg) if s.needed]


# ---------------------------------------------------------------- what each step compiles
# (called in the preparing child processes: ``backend.prepare.run_step``)


def compile_planner(cfg: Any, formulation: str) -> None:
    from ucat_console.backend.loop.kernels_warm_up import warm_up

    warm_up(cfg.loop, formulations=(formulation,))


def compile_loop(cfg: Any) -> None:
    from ucat_console.backend.loop.kernels_warm_up import warm_up_loop

    warm_up_loop(cfg.loop)


def compile_page(cfg: Any) -> None:
    from ucat_console.ui.plots import warm_up

    warm_up()


def compile_plant(cfg: Any) -> None:
    from ucat_console.backend.loop.closed_loop import ClosedLoop
    from ucat_console.backend.sim_robot_io import SimRobotIO

    io = SimRobotIO(cfg.plant, depth=1.0, velocity=0.1)
    io.advance_to(0.05)  # the plant one event at a time (behind the console's arming gate)
    io.plant.advance(0.002)
    io.plant.sample_sensors()
    # the plant running the loop's core (headless runs), before any plan is due
    with ClosedLoop(cfg.loop.replace(mode="baseline"), SimRobotIO(cfg.plant, depth=1.0)) as loop:
        loop.run_until(0.05)


def prepare_all(config: Any = None) -> Any:
    """:func:`prepare` every step of the configuration ``config`` names (the defaults: the
    simulated robot, every formulation)."""
    from ucat_console.config import load_config

    cfg = load_config(config)
    return prepare(cfg, every_step(cfg))


def prepare(cfg: Any, steps: list[Any],
            on_progress: Callable[[Any], None] | None = None, workers: int | None = None) -> Any:
    """Compile (or load) ``steps`` (e.g. :func:`console_steps`) in child processes, printing the progress, and return the preparation once the needed
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

    prep = backend_prepare.start(cfg, steps, progress, workers)
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
