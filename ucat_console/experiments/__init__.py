"""The paper's experiments E1-E5 and their reports.

They need the ``experiments`` extra (matplotlib for the figures, dask.distributed for the
runs, tqdm for progress): ``pip install 'ucat-console[experiments]'``. The console itself
imports none of them.
"""

from __future__ import annotations

__all__ = ["EXPERIMENTS", "NAMED_ONLY"]

EXPERIMENTS = ("E1", "E2", "E3", "E4", "E4R", "E5", "E6")
#: experiments run only when named (not by "all"): E7 and E8 (docs/experiments/e7-declaration.md,
#: e8-declaration.md)
NAMED_ONLY = ("E7", "E8")
