"""Loading (or compiling) the planners and the closed loop's per-sample kernels without a robot.

:func:`warm_up` makes one plan of each planner kind (the MPC in each formulation, the
baseline scored with each).

:func:`warm_up_loop` runs a :class:`~ucat_console.backend.loop.closed_loop.ClosedLoop` for
half a second on :class:`_StubRobot`, which delivers every kind of reading the loop takes
(the fins' feedback together and one by one), so every kernel the loop calls is compiled
for the argument types it meets at run time: the per-sample core (``control.loop_core``:
the body-frame loops, the stroke-end table, the power estimate, dead reckoning) and the
baseline's scoring.
"""

from __future__ import annotations

import time

import numpy as np

from ucat_console.backend.loop.closed_loop import ClosedLoop
from ucat_console.backend.loop.config import LoopConfig
from ucat_console.backend.loop.planners import BaselineFinPlanner, MpcFinPlanner, PlanInputs
from ucat_console.control.params import FORMULATIONS
from ucat_console.robot.fins import N_FINS
from ucat_console.robot.interface import RobotIO
from ucat_console.robot.readings import DepthReading, DvlVelocity, FinFeedback, FinFeedbacks, ImuReading, Reading

_PERIOD = 0.01


class _StubRobot(RobotIO):
    """Readings every 10 ms from fins beating at 2 Hz on a level, steady hull."""

    def __init__(self) -> None:
        self._k = 0

    def command_fin(self, fin: int, target_rad: float, profile_velocity_rad_s: float) -> None:
        pass

    def next_reading_time(self) -> float:
        return self._k * _PERIOD

    def advance_to(self, t: float) -> list[Reading]:
        out: list[Reading] = []
        while self._k * _PERIOD <= t + 1e-9:
            k, tk = self._k, self._k * _PERIOD
            self._k += 1
            out.append(ImuReading(tk, (0.0, 0.0, -1.0), (0.0, 0.0, 0.01), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0)))
            if k % 5 == 0:
                out.append(DepthReading(tk, 1.0, 1.1e5))
            if k % 10 == 0:
                out.append(DvlVelocity(tk, 0.1, 0.0, 0.0, True, 2.0, 0.005))
            angle = 0.4 * np.sin(4.0 * np.pi * tk)
            rate = 1.6 * np.pi * np.cos(4.0 * np.pi * tk)
            if k % 7 == 3:  # one fin at a time, as drives that report on their own deliver them
                out += [FinFeedback(tk, f, float(angle), float(rate)) for f in range(N_FINS)]
            else:
                fb = np.array([angle] * N_FINS + [rate] * N_FINS)
                fb.flags.writeable = False
                out.append(FinFeedbacks(tk, fb[:N_FINS], fb[N_FINS:]))
        return out


def warm_up(cfg: LoopConfig | None = None, formulations: tuple[str, ...] | None = None) -> float:
    """One plan of each kind: the MPC in ``formulations`` (default: every formulation, as
    either may be switched to live) and the baseline scored with each: loads the compiled
    solver from numba's on-disk cache, or compiles it (a minute or more a formulation, once
    per machine) and fills that cache. Seconds taken."""
    cfg = cfg or LoopConfig()
    x = PlanInputs(t=0.0, fins=(0,), target=(-0.3, 0.0), v_body=0.0, theta0=0.0,
                   u_prev=cfg.initial_u_prev)
    if formulations is None:
        formulations = FORMULATIONS if cfg.mpc.solver == "numba" else (cfg.mpc.formulation,)
    t0 = time.perf_counter()
    for formulation in formulations:
        m = cfg.mpc.replace(formulation=formulation)
        MpcFinPlanner(m, 0)(x)
        BaselineFinPlanner(m, cfg.baseline, cfg.executor)(x)
    return time.perf_counter() - t0


def warm_up_loop(cfg: LoopConfig | None = None) -> float:
    """Half a second of the closed loop (mode baseline) on the stub robot; seconds taken."""
    cfg = cfg or LoopConfig()
    t0 = time.perf_counter()
    with ClosedLoop(cfg.replace(mode="baseline"), _StubRobot()) as loop:
        loop.run_until(0.5)
    return time.perf_counter() - t0
