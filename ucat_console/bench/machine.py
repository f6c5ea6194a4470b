"""What machine a benchmark ran on, and pinning it to one core."""

from __future__ import annotations

import os
import platform
import sys


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
    }
