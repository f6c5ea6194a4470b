"""The in-process simulated U-CAT as a robot: :class:`SimRobotIO` (``robot.interface``)."""

from __future__ import annotations

import math

from ucat_console.backend.sim.params import PlantConfig
from ucat_console.backend.sim.plant import Plant
from ucat_console.robot.interface import RobotIO, RobotTruth
from ucat_console.robot.readings import Reading


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
        return self.plant.advance_and_sample(t)

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
