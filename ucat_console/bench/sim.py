"""``ucat-console bench sim``: the closed loop on the simulated robot, simulated seconds per
wall-clock second, headless.

The loop runs as the experiments run it: the simulated U-CAT at 1 kHz physics with its
sensors, four fins (three logical fins in sync mode) planning every cycle. Two ways of
taking its telemetry are measured:

* ``headless``: nothing subscribes to the stream, as in the experiments and sweeps, so the
  loop builds no message that nobody takes (``TelemetryStream.wants``);
* ``subscribed``: a subscriber takes every channel (as the supervisor does for the console
  and the recorder), so every message is built and delivered.

The run is cut into chunks of simulated time; the figure is the median of the chunks'
real-time factors (one noisy moment on a shared machine moves one chunk, not the figure).
"""

from __future__ import annotations

import statistics
import time

from ucat_console.backend.loop.closed_loop import ClosedLoop
from ucat_console.backend.loop.config import LoopConfig
from ucat_console.backend.loop.modes import mode as registered_mode
from ucat_console.backend.sim_robot_io import SimRobotIO
from ucat_console.control.allocation import BodySetpoints
from ucat_console.telemetry.stream import TelemetryStream

TELEMETRY = ("headless", "subscribed")


def measure_realtime_factor(mode: str, seconds: float = 30.0, warmup_s: float = 2.0,
                            v_ref: float = 0.2, depth: float = 1.0, telemetry: str = "headless",
                            chunks: int = 10) -> tuple[float, list[float]]:
    """(median, per chunk) headless real-time factor of the closed loop in ``mode`` over
    ``seconds`` of simulation cut into ``chunks`` (after ``warmup_s`` simulated seconds,
    which also load the compiled kernels)."""
    registered_mode(mode)  # else ValueError naming the modes
    if telemetry not in TELEMETRY:
        raise ValueError(f"telemetry: {telemetry!r} is not one of {', '.join(TELEMETRY)}")
    if not seconds > 0.0:
        raise ValueError(f"seconds: {seconds!r} must be > 0")
    if chunks < 1:
        raise ValueError(f"chunks: {chunks!r} must be >= 1")
    stream = TelemetryStream()
    taken = [0]
    if telemetry == "subscribed":
        stream.subscribe(lambda channel, message: taken.__setitem__(0, taken[0] + 1))
    io = SimRobotIO(depth=depth, velocity=v_ref)
    loop = ClosedLoop(LoopConfig(mode=mode), io, stream, setpoints=BodySetpoints(velocity=v_ref, depth=depth))
    loop.run_until(warmup_s)
    step = seconds / chunks
    factors = []
    for k in range(chunks):
        start = time.perf_counter()
        loop.run_until(warmup_s + (k + 1) * step)
        factors.append(step / (time.perf_counter() - start))
    loop.close()
    if telemetry == "subscribed" and taken[0] == 0:
        raise RuntimeError("the subscriber took no message")
    return statistics.median(factors), factors
