"""The built-in robots behind the closed loop, built from configuration (``backend.robots``
registers them; ``robots.build_robot_io`` builds any registered one).

The built-in robots (``backend.robots``, the registry the configuration's ``robot`` names
one of) share one interface (``robot.interface.RobotIO``)::

    sim          SimRobotIO ------------------------------------> Plant (in process)
    sim-devices  DeviceRobotIO -> drivers -> virtual CAN / pty / 127.0.0.1 -> emulators -> Plant
    hardware     DeviceRobotIO -> drivers -> socketcan can0 / /dev/tty* / DVL address -> devices

The closed loop cannot tell them apart; the supervisor connects the robot's fault events
to its telemetry stream with :func:`connect_events` and reaches the simulated rig (for
fault injection from the developer panel) with :func:`rig_of`.
"""

from __future__ import annotations

import logging
from typing import Callable

from ucat_console.backend.devices.config import DevicesConfig
from ucat_console.backend.devices.device_robot_io import DeviceRobotIO
from ucat_console.backend.sim_rig import SimRig
from ucat_console.backend.sim_robot_io import SimRobotIO
from ucat_console.robot.interface import RobotIO
from ucat_console.backend.sim.params import PlantConfig
from ucat_console.telemetry.events import EventSink

log = logging.getLogger(__name__)

Close = Callable[[], None]


def build_sim(devices: DevicesConfig, plant: PlantConfig, event_sink: EventSink | None) -> tuple[RobotIO, Close]:
    """The in-process :class:`SimRobotIO` at ``devices.start`` (no devices; events only of
    readings its plausibility checks drop)."""
    s = devices.start
    io = SimRobotIO(plant, depth=s.depth, yaw=s.yaw, velocity=s.velocity,
                    seed=None if s.seed < 0 else s.seed, plausibility=devices.plausibility, on_event=event_sink)
    return io, io.close


def build_sim_devices(devices: DevicesConfig, plant: PlantConfig,
                      event_sink: EventSink | None) -> tuple[RobotIO, Close]:
    """A :class:`SimRig` (plant + emulators, starting at ``devices.start``) and a
    :class:`DeviceRobotIO` on the rig's endpoints, at the rig's pace."""
    cfg = devices
    rig = SimRig(cfg, plant)
    driver_cfg = rig.start()
    try:
        dev = DeviceRobotIO(driver_cfg, pace=cfg.rig.pace, truth=rig.truth, on_event=event_sink,
                            device_time=rig.device_time)
        dev.rig = rig
        rig.on_event = dev.publish_event
        dev.start()
    except BaseException:
        rig.stop()
        raise

    def close_sim_devices() -> None:
        try:
            dev.close()
        finally:
            rig.stop()

    log.info("robot: simulated U-CAT behind the device emulators (pace %g)", cfg.rig.pace)
    return dev, close_sim_devices


def build_hardware(devices: DevicesConfig, plant: PlantConfig, event_sink: EventSink | None) -> tuple[RobotIO, Close]:
    """A :class:`DeviceRobotIO` on the configured endpoints (``plant`` unused)."""
    cfg = devices
    dev = DeviceRobotIO(cfg, pace=1.0, on_event=event_sink)
    dev.start()
    log.info("robot: hardware (CAN %s %s, IMU %s, DVL %s:%d, pressure %s)", cfg.epos2.interface,
             cfg.epos2.channel, cfg.imu.port, cfg.dvl.host, cfg.dvl.port, cfg.pressure.port)
    return dev, dev.close


def connect_events(robot_io: RobotIO, sink: EventSink) -> Close:
    """Send the robot's fault events to ``sink`` (e.g. publishing them on the telemetry
    stream's events channel); returns the function that disconnects. The in-process
    simulator raises none."""
    add = getattr(robot_io, "add_event_sink", None)
    if add is None:
        return lambda: None
    return add(sink)


def rig_of(robot_io: RobotIO) -> SimRig | None:
    """The simulated rig behind a ``sim-devices`` robot (its ``inject``/``clear`` start and
    end emulator faults); None for the other robots."""
    rig = getattr(robot_io, "rig", None)
    return rig if isinstance(rig, SimRig) else None
