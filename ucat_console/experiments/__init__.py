"""The paper's experiments E1-E5 and their reports.

They need the ``experiments`` extra (matplotlib for the figures, dask.distributed for the
runs, tqdm for progress): ``pip install 'ucat-console[experiments]'``. The console itself
imports none of them.
"""

from __future__ import annotations

import importlib.util

EXPERIMENTS = ("E1", "E2", "E3", "E4", "E4R", "E5", "E6")
#: experiments run only when named (not by "all"): E7 (docs/experiments/e7-declaration.md)
NAMED_ONLY = ("E7",)
#: what the experiments, sweeps and the MPC benchmark import beyond the console
EXTRA_MODULES = ("matplotlib", "dask", "distributed", "tqdm")


def require_extra(*modules: str) -> None:
    """ValueError naming the install command when a module of the ``experiments`` extra is
    missing (default: all of them)."""
    missing = [m for m in modules or EXTRA_MODULES if importlib.util.find_spec(m) is None]
    if missing:
        raise ValueError(f"{', '.join(missing)} not installed: this command needs the "
                         "experiments extra (pip install 'ucat-console[experiments]')")
