"""``ucat-console bench sim``: the closed loop on the simulated robot, simulated seconds per
wall-clock second, headless.

The loop runs as the experiments run it: the simulated U-CAT at 1 kHz physics with its
sensors, four fins (three logical fins in sync mode) planning every cycle, and every
telemetry message built and published on a stream (with no subscriber).
"""

from __future__ import annotations

import time

from ucat_console.backend.loop.closed_loop import ClosedLoop
from ucat_console.backend.loop.config import MODES, LoopConfig
from ucat_console.backend.sim.robot_io import SimRobotIO
from ucat_console.control.allocation import BodySetpoints
from ucat_console.telemetry.stream import TelemetryStream


def measure_realtime_factor(mode: str, seconds: float = 30.0, warmup_s: float = 2.0,
                            v_ref: float = 0.2, depth: float = 1.0) -> float:
    """Headless real-time factor of the closed loop in ``mode`` over ``seconds`` of simulation
    (after ``warmup_s`` simulated seconds, which also load the compiled kernels)."""
    if mode not in MODES:
        raise ValueError(f"mode: {mode!r} is not one of {', '.join(MODES)}")
    if not seconds > 0.0:
        raise ValueError(f"seconds: {seconds!r} must be > 0")
    io = SimRobotIO(depth=depth, velocity=v_ref)
    loop = ClosedLoop(LoopConfig(mode=mode), io, TelemetryStream(),
                      setpoints=BodySetpoints(velocity=v_ref, depth=depth))
    loop.run_until(warmup_s)
    start = time.perf_counter()
    loop.run_until(warmup_s + seconds)
    wall = time.perf_counter() - start
    loop.close()
    return seconds / wall
