"""Where many runs execute: a dask.distributed cluster, local by default, remote on request.

:func:`task_client` yields a ``dask.distributed.Client``: on a ``LocalCluster`` of worker
processes (one per core, one thread each, bound to 127.0.0.1) by default, or connected to
the scheduler at ``address`` (e.g. ``tcp://10.0.0.5:8786``) with a short timeout. A
scheduler that cannot be reached is a :class:`SchedulerError` (a ``ValueError``, so the
CLI reports it and exits non-zero).

:func:`run_all` maps a picklable top-level function over items with a progress bar and
returns the results in the items' order.
"""

from __future__ import annotations

import logging
import os
import sys
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any, TypeVar

T = TypeVar("T")
R = TypeVar("R")

log = logging.getLogger(__name__)

#: seconds to wait for a remote scheduler before giving up
CONNECT_TIMEOUT_S = 5.0


class SchedulerError(ValueError):
    """The distributed scheduler could not be reached or started."""


@contextmanager
def task_client(address: str | None = None, n_workers: int | None = None,
                timeout_s: float = CONNECT_TIMEOUT_S) -> Iterator[Any]:
    """A dask client on a local process cluster, or on the scheduler at ``address``."""
    from dask.distributed import Client, LocalCluster

    for name in ("distributed", "distributed.worker", "distributed.scheduler", "distributed.nanny"):
        logging.getLogger(name).setLevel(logging.ERROR)
    cluster = None
    if address:
        try:
            client = Client(address, timeout=f"{timeout_s}s")
        except (OSError, TimeoutError, ValueError) as e:
            raise SchedulerError(
                f"--scheduler {address}: cannot reach the dask scheduler within {timeout_s:.0f} s ({e})"
            ) from None
    else:
        workers = n_workers or os.cpu_count() or 1
        try:
            cluster = LocalCluster(
                n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                dashboard_address=None, silence_logs=logging.ERROR,
            )
            client = Client(cluster)
        except (OSError, TimeoutError) as e:
            if cluster is not None:
                cluster.close()
            raise SchedulerError(f"local dask cluster: could not start {workers} workers ({e})") from None
    try:
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def run_all(client: Any, fn: Callable[..., R], items: Sequence[Any], desc: str,
            progress: bool = True, star: bool = False) -> list[R]:
    """``[fn(x) for x in items]`` on the cluster, with a tqdm bar; errors are raised here.
    With ``star``, each item is a tuple of arguments: ``fn(*x)``."""
    from dask.distributed import as_completed
    from tqdm import tqdm

    if not items:
        return []
    if star:
        futures = client.map(fn, *zip(*items), pure=False)
    else:
        futures = client.map(fn, list(items), pure=False)
    index = {f.key: i for i, f in enumerate(futures)}
    out: list[Any] = [None] * len(futures)
    with tqdm(total=len(futures), desc=desc, unit="run", file=sys.stderr, disable=not progress) as bar:
        for fut in as_completed(futures):
            out[index[fut.key]] = fut.result()
            bar.update()
    return out
