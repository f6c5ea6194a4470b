"""The ``experiments`` extra: what the experiments, the sweeps and some benchmarks import
beyond the console (matplotlib for figures, dask.distributed for runs, tqdm for progress),
``pip install 'ucat-console[experiments]'``."""

from __future__ import annotations

import importlib.util

#: the extra's modules
EXTRA_MODULES = ("matplotlib", "dask", "distributed", "tqdm")


def require_extra(*modules: str) -> None:
    """ValueError naming the install command when a module of the ``experiments`` extra is
    missing (default: all of them)."""
    missing = [m for m in modules or EXTRA_MODULES if importlib.util.find_spec(m) is None]
    if missing:
        raise ValueError(f"{', '.join(missing)} not installed: this command needs the "
                         "experiments extra (pip install 'ucat-console[experiments]')")
