"""The robots the console can drive: one live registry, read wherever the set is needed.

``AppConfig.robot`` names one entry; the configuration's choices, the supervisor and
``build_robot_io`` read the registry when they need it, so a robot registered before the
console starts (``register(Robot(...))`` from your own module) is taken everywhere, as a
mode is. An entry says how to build the robot from the drivers' and the plant's
configuration, whether it is the simulated plant, whether its readings are computed in the
console's process (the clock may then take them a little early, ``console.sim_early``), and
where it starts: a simulated robot at ``devices.start`` (the one start of the simulated
U-CAT, in-process or behind the emulators), the hardware where the robot is (the depth
setpoint starts at the surface, 0 m).

The built-in robots (``backend.rig`` builds them; imported only when one is built):

    sim          the simulated U-CAT in the console's process
    sim-devices  the simulated U-CAT behind the device emulators, through the drivers
    hardware     the drivers on the robot's devices (``[devices]``)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from ucat_console.backend.devices.config import DevicesConfig
from ucat_console.backend.sim.params import PlantConfig
from ucat_console.robot.interface import RobotIO
from ucat_console.telemetry.events import EventSink
from ucat_console.registry import Registry

Close = Callable[[], None]
#: ``build(devices, plant, event_sink) -> (robot_io, close)``: the robot, started
Build = Callable[[DevicesConfig, PlantConfig, "EventSink | None"], tuple[RobotIO, Close]]


@dataclass(frozen=True)
class Robot:
    """One robot the console can drive (module docstring)."""

    name: str
    doc: str
    build: Build
    simulated: bool
    computed_readings: bool = False

    def start_depth(self, devices: DevicesConfig) -> float:
        """Where the depth setpoint starts: the simulated robot's start depth, else the surface."""
        return devices.start.depth if self.simulated else 0.0


ROBOTS: Registry[Robot] = Registry("robot", Robot)
#: add a robot (ValueError if its name is taken); returns it
register = ROBOTS.register
#: take a robot out (a test's, or a plug-in's going away)
unregister = ROBOTS.unregister
#: the registered robot ``name``, else ValueError naming the robots there are
robot = ROBOTS.get_entry
#: the registered robots' names, in the order registered (read live)
robot_names = ROBOTS.names


def build_robot_io(
    name: str,
    devices: DevicesConfig,
    *,
    plant: PlantConfig | None = None,
    event_sink: EventSink | None = None,
) -> tuple[RobotIO, Close]:
    """The registered robot ``name`` (``AppConfig.robot``) with the devices ``devices``,
    started, and the function that shuts it down (the built-in ones: ``backend.rig``'s
    ``build_sim``, ``build_sim_devices`` or ``build_hardware``).

    ``plant`` configures the simulated plant. ``event_sink`` receives
    the robot's fault events from the start (more sinks: ``backend.rig.connect_events``). Bad configuration fails here with a
    ValueError naming the key (the drivers' ``start``); nothing is left running.
    """
    entry = robot(name)
    if not isinstance(devices, DevicesConfig):
        raise ValueError(f"devices: expected a DevicesConfig, got {type(devices).__name__}")
    return entry.build(devices, plant if plant is not None else PlantConfig(), event_sink)


def _rig(kind: str) -> Build:
    def build(devices: DevicesConfig, plant: PlantConfig, event_sink: EventSink | None) -> tuple[RobotIO, Close]:
        from ucat_console.backend import rig

        return getattr(rig, kind)(devices, plant, event_sink)

    return build


register(Robot("sim", "the simulated U-CAT in the console's process", _rig("build_sim"),
               simulated=True, computed_readings=True))
register(Robot("sim-devices", "the simulated U-CAT behind the device emulators, through the drivers",
               _rig("build_sim_devices"), simulated=True))
register(Robot("hardware", "the drivers on the robot's devices ([devices])", _rig("build_hardware"),
               simulated=False))
