"""The closed loop's view of the robot: fin commands out, sensor readings in.

:class:`RobotIO` is deliberately small, like python-can's ``BusABC``: the loop never knows
whether the readings come from the in-process simulator (:class:`SimRobotIO`), from the
device drivers talking to emulators, or from the real robot.

Contract:

* Fins are numbered in the robot's order (the plant's and the drivers': 0 front-right,
  1 back-right, 2 back-left, 3 front-left), as in the telemetry. The loop maps the
  controller's (paper) order with ``PAPER_TO_PLANT_FIN``.
* :meth:`RobotIO.command_fin` is a profile-position set-point that acts at once (the
  EPOS2's "change set immediately"): target angle (rad) and profile velocity (rad/s).
* :meth:`RobotIO.advance_to` lets the robot reach time ``t`` (the simulator steps its
  physics; a device-backed robot simply returns when its clock reaches ``t``) and returns
  the readings taken since the last call, in time order: ``ImuReading``, ``DvlVelocity``,
  ``DepthReading``, ``FinFeedback`` (encoder angle and rate of one fin).
* :meth:`RobotIO.next_reading_time` says when the next reading is due, so the loop can run
  the physics in chunks from event to event. A device-backed robot, whose readings arrive
  on their own, returns the time it next wants to be polled.
* :meth:`RobotIO.truth` is the simulator's true state (None on a real robot); only
  experiments and the 3-D view's "truth" overlay read it, never the controller.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass

from ucat_console.backend.devices.readings import DepthReading, DvlVelocity, FinFeedback, ImuReading
from ucat_console.backend.sim.params import PlantConfig
from ucat_console.backend.sim.plant import Plant

Reading = ImuReading | DvlVelocity | DepthReading | FinFeedback


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


class SimRobotIO(RobotIO):
    """The in-process simulated U-CAT (``backend.sim.Plant``), headless or paced.

    The plant starts level at ``depth`` (m) with heading ``yaw`` (rad), surging at
    ``velocity`` (m/s, body x; 0: at rest), all fins at rest at angle 0; ``seed`` restarts
    the sensor noise (default: the plant configuration's seed).
    """

    def __init__(
        self, cfg: PlantConfig | None = None, *, depth: float = 0.0, yaw: float = 0.0,
        velocity: float = 0.0, seed: int | None = None,
    ) -> None:
        if not math.isfinite(depth) or depth < 0.0:
            raise ValueError(f"depth: the start depth must be finite and >= 0 m, got {depth!r}")
        if not math.isfinite(velocity) or abs(velocity) > 5.0:
            raise ValueError(f"velocity: the start surge must be finite and within 5 m/s, got {velocity!r}")
        self.plant = Plant(cfg)
        self.plant.reset(
            position_ned=(0.0, 0.0, float(depth)), euler=(0.0, 0.0, float(yaw)),
            body_velocity=(float(velocity), 0.0, 0.0, 0.0, 0.0, 0.0), seed=seed,
        )

    def command_fin(self, fin: int, target_rad: float, profile_velocity_rad_s: float) -> None:
        self.plant.command_fin(fin, target_rad, profile_velocity_rad_s)

    def next_reading_time(self) -> float:
        return self.plant.next_sensor_time()

    def advance_to(self, t: float) -> list[Reading]:
        self.plant.advance_to(t)
        return self.plant.sample_sensors()

    def truth(self) -> RobotTruth:
        p = self.plant
        pos, q = p.pose()
        return RobotTruth(
            t=p.time,
            position=pos,
            orientation=q,
            euler=p.euler(),
            velocity=p.body_velocity(),
            fin_angles=p.fin_angles(),
            fin_rates=p.fin_rates(),
            fin_strouhal=p.fin_strouhal(),
            fin_energy=p.fin_energy(),
        )
