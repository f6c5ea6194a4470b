"""What machine a benchmark ran on, how fast it was at the time, and pinning it to one core.

The speed of this project's development machines (shared virtual machines) varies from
hour to hour by up to a factor of three, so a benchmark's figures say little on their own.
:func:`speed_probe` times two fixed workloads, pure Python and compiled, at the time of the
benchmark; the figures of two benchmark runs compare through it, and docs/performance.md keeps it
beside them.
"""

from __future__ import annotations

import os
import platform
import statistics
import sys
import time

from numba import njit


def pin_to_one_core(cpu: int | None = None) -> int | None:
    """Restrict this process to one CPU (the last allowed one by default)."""
    if not hasattr(os, "sched_setaffinity"):
        return None
    allowed = sorted(os.sched_getaffinity(0))
    chosen = allowed[-1] if cpu is None else cpu
    if chosen not in allowed:
        raise ValueError(f"--cpu: {chosen} is not one of the allowed CPUs {allowed}")
    os.sched_setaffinity(0, {chosen})
    return chosen


@njit(cache=True)
def _chain(n: int, a: float, b: float) -> float:
    x = 1.0
    for _ in range(n):
        x = x * a + b  # each step waits for the one before: latency-bound
    return x


def _python_loop(n: int) -> int:
    s = 0
    for i in range(n):
        s += i
    return s


def speed_probe(repeats: int = 5) -> dict[str, float]:
    """Medians of ``repeats`` timings of two fixed workloads: a Python loop of a million
    additions (``python_ms``) and ten million dependent multiply-adds compiled by numba
    (``compiled_ns_per_op``)."""
    _chain(10, 0.5, 0.1)
    py, comp = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        _python_loop(1_000_000)
        t1 = time.perf_counter()
        _chain(10_000_000, 0.9999999, 1e-7)
        t2 = time.perf_counter()
        py.append(t1 - t0)
        comp.append(t2 - t1)
    return {"python_ms": 1e3 * statistics.median(py), "compiled_ns_per_op": 1e9 * statistics.median(comp) / 1e7}


def machine_info(cpu: int | None) -> dict:
    model = platform.processor()
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    import numba
    import numpy
    import scipy

    return {
        "cpu_model": model,
        "logical_cpus": os.cpu_count(),
        "pinned_cpu": cpu,
        "platform": platform.platform(),
        "python": sys.version.split()[0],
        "numpy": numpy.__version__,
        "scipy": scipy.__version__,
        "numba": numba.__version__,
        "loadavg": os.getloadavg() if hasattr(os, "getloadavg") else None,
        "speed_probe": speed_probe(),
    }


def speed_line(machine: dict) -> str:
    """The machine and its speed at the time, for a benchmark's output."""
    p = machine["speed_probe"]
    return (f"machine: {machine['cpu_model']}, {machine['logical_cpus']} CPUs; speed now: a million Python "
            f"additions {p['python_ms']:.0f} ms, a compiled multiply-add {p['compiled_ns_per_op']:.2f} ns")
