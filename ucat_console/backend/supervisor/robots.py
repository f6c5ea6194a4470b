"""Where the supervisor's robot comes from, and the clock it runs on in real time.

The robot is the registered one the configuration names (``backend.robots``); a test may
hand the supervisor a robot factory of its own, ``(app_config, event_sink) -> (robot_io,
close)``.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Callable

from ucat_console.backend.loop.clock import PacedClock
from ucat_console.config import AppConfig
from ucat_console.robot.interface import RobotIO
from ucat_console.telemetry.events import EventSink

if TYPE_CHECKING:
    from ucat_console.backend.sim_rig import SimRig

RobotFactory = Callable[[AppConfig, EventSink], tuple[RobotIO, Callable[[], None]]]


def simulated_rig(robot_io: RobotIO) -> SimRig | None:
    """The simulated rig behind ``robot_io`` (fault injection), None for any other robot."""
    if getattr(robot_io, "rig", None) is None:
        return None  # no device stack to import for the in-process simulator
    from ucat_console.backend.rig import rig_of

    return rig_of(robot_io)


class SteadyPacedClock(PacedClock):
    """A :class:`PacedClock` anchored once (and again after a stall it skips): the loop
    runs in chunks without drifting."""

    def __init__(self, pace: float = 1.0, early: float = 0.0, max_lag: float = math.inf) -> None:
        super().__init__(pace, early, max_lag)
        self._anchored = False

    def start(self, t0: float) -> bool:
        if not self._anchored:
            self._anchored = True
            return super().start(t0)
        self._wake.clear()
        return False
