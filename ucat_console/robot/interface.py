"""The closed loop's view of the robot: fin commands out, sensor readings in.

:class:`RobotIO` is deliberately small, like python-can's ``BusABC``: the loop never knows
whether the readings come from the in-process simulator (``backend.sim_robot_io.SimRobotIO``),
from the device drivers talking to emulators (``backend.devices.device_robot_io``), or from
the real robot. It lives here, in the robot's description, so that the loop, the plant and
the drivers meet on it without importing each other.

Contract:

* Fins are numbered in the robot's order (the plant's and the drivers': 0 front-right,
  1 back-right, 2 back-left, 3 front-left), as in the telemetry. The loop maps the
  controller's (paper) order with ``robot.fins.PAPER_TO_ROBOT``.
* :meth:`RobotIO.command_fin` is a profile-position set-point that acts at once (the
  EPOS2's "change set immediately"): target angle (rad) and profile velocity (rad/s).
  A robot sends each command as given, unless it says otherwise through
  :meth:`RobotIO.report_sent`: one that may hold commands back or send set-points of its
  own (the arming gate) reports each set-point a fin is actually sent.
* :meth:`RobotIO.advance_to` lets the robot reach time ``t`` (the simulator steps its
  physics; a device-backed robot simply returns when its clock reaches ``t``) and returns
  the readings taken since the last call, in time order: ``ImuReading``, ``DvlVelocity``,
  ``DepthReading``, ``FinFeedback`` (encoder angle and rate of one fin).
* :meth:`RobotIO.next_reading_time` says when the next reading is due, so the loop can run
  the physics in chunks from event to event. A device-backed robot, whose readings arrive
  on their own, returns the time it next wants to be polled.
* :meth:`RobotIO.resync` tells the robot that the loop's time ``t`` is due now: the paced
  loop anchored its clock to the wall clock, at its start or after a stall it skipped. A
  robot whose readings come on the wall clock maps them to loop time from then on.
* :meth:`RobotIO.truth` is the simulator's true state (None on a real robot); only
  experiments and the 3-D view's "truth" overlay read it, never the controller.
* A robot whose readings are computed in-process (the simulator) may say
  :attr:`RobotIO.runs_core` and run the loop's compiled per-sample core itself
  (:meth:`RobotIO.run_core`, ``control.loop_core``): it advances to each event the core
  asks for and hands it the readings as rows (``robot.reading_rows``), all in compiled
  code, until the core has something for the loop to do. Every other robot is driven
  through :meth:`RobotIO.advance_to`, one event at a time.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, Callable

from ucat_console.robot.readings import Reading


@dataclass(frozen=True)
class RobotTruth:
    """The simulator's true state at ``t`` (fins in the robot's order)."""

    t: float
    position: tuple[float, float, float]  # NED, m
    orientation: tuple[float, float, float, float]  # body -> NED (w, x, y, z)
    euler: tuple[float, float, float]  # roll, pitch, yaw (rad)
    velocity: tuple[float, float, float, float, float, float]  # u, v, w, p, q, r (body)
    fin_angles: tuple[float, ...]
    fin_rates: tuple[float, ...]
    fin_strouhal: tuple[float, ...]
    fin_energy: tuple[float, ...]  # true shaft energy since start, J
    #: each fin's fin-frame force (f_x, f_y) integrated since start, N s (the simulator's)
    fin_impulse: tuple[tuple[float, float], ...] = ()
    #: battery energy each fin drive drew since start, J (the simulator's drive model)
    fin_battery_energy: tuple[float, ...] = ()

    @property
    def depth(self) -> float:
        return self.position[2]


class RobotIO(ABC):
    """Fin commands out, readings in (see the module docstring for the contract)."""

    @abstractmethod
    def command_fin(self, fin: int, target_rad: float, profile_velocity_rad_s: float) -> None:
        """Profile-position set-point for ``fin`` (robot order), acting at once."""

    @abstractmethod
    def next_reading_time(self) -> float:
        """When the next reading is due (or the robot next wants to be polled), s."""

    @abstractmethod
    def advance_to(self, t: float) -> list[Reading]:
        """Let the robot reach time ``t`` (s); the readings taken since the last call."""

    #: the fins are moved by motor drives with power stages, powered only while armed
    has_drives: bool = False
    #: the robot runs the loop's compiled core itself (:meth:`run_core`)
    runs_core: bool = False

    def report_sent(self, report: Callable[[int, float, float], None]) -> bool:
        """Have ``report(fin, target_rad, profile_velocity_rad_s)`` called with each
        set-point a fin is actually sent, in the thread that drives the robot; whether this
        robot reports them. False (this one): every command is sent as given, the caller
        knows what each fin was sent."""
        return False

    def run_core(self, core: Any) -> int:
        """Run the loop's core (a ``control.loop_core.LoopCore``) with this robot
        delivering its readings, until the core returns something other than "readings";
        that status. Only for a robot that :attr:`runs_core`."""
        raise NotImplementedError(f"{type(self).__name__} does not run the loop's core")

    def resync(self, t: float) -> None:
        """The loop's time ``t`` is due now (module docstring); nothing to do for a robot
        that runs in loop time (the simulator)."""

    def enable_drives(self) -> bool:
        """Power the fin drives for set-points (on arming); False when a drive did not come
        up (its events say why). The simulator has nothing to power."""
        return True

    def stop_drives(self) -> bool:
        """Stop every fin drive on its quick-stop ramp and turn its power stage off (on
        disarming); False when a drive did not confirm (its events say why)."""
        return True

    def reset_drive_faults(self) -> bool:
        """Reset the drives that are in fault (after an EMCY), leaving them unpowered; False
        when one stays in fault (its events say why)."""
        return True

    def zero_depth(self) -> float:
        """Take the present pressure as the surface's (the robot floating at the surface);
        returns that pressure (Pa). ValueError when there is no pressure sensor to zero, or
        too few readings came (the sensor's events say why; the old zero stays)."""
        raise ValueError("depth zeroing: this robot has no pressure sensor to zero "
                         "(the simulator's depth is exact)")

    def truth(self) -> RobotTruth | None:
        """The simulator's true state; None when the robot is real."""
        return None

    def close(self) -> None:
        """Release devices (nothing to do for the simulator)."""
