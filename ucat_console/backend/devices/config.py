"""Where the robot's devices are: :class:`DevicesConfig`, for the built-in robots the
console can drive (``backend.robots``, the application configuration's one selector,
``robot``), behind the same closed loop:

* ``"sim"``: the in-process simulated U-CAT (``backend.sim_robot_io.SimRobotIO``), no devices;
* ``"sim-devices"``: the simulated U-CAT behind protocol-exact emulators (EPOS2 nodes on a
  python-can ``virtual`` bus, the IMU and the pressure ADC on ptys, the DVL on 127.0.0.1),
  reached through the same drivers as the real robot. The emulators' endpoints replace
  the addresses below; the rest of each driver block (rates, timeouts, units) applies;
* ``"hardware"``: the drivers on the endpoints below (``socketcan`` can0, ``/dev/tty*``,
  the DVL's address).

The driver blocks are the drivers' own configuration classes (one definition of each
parameter); ``plausibility`` what a sensor reading may show before the estimator takes it
(every robot's, the in-process simulator's too); ``start`` says where the simulated robot
starts and ``rig`` how its emulators behave.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ucat_console.backend.devices.dvl import DvlConfig
from ucat_console.backend.devices.dvl_emulator import DvlEmulatorConfig
from ucat_console.backend.devices.epos2 import Epos2Config
from ucat_console.backend.devices.imu import ImuConfig
from ucat_console.backend.devices.imu_emulator import ImuEmulatorConfig
from ucat_console.backend.devices.leak import LeakConfig
from ucat_console.backend.devices.plausibility import PlausibilityConfig
from ucat_console.backend.devices.pressure import PressureConfig
from ucat_console.backend.devices.pressure_emulator import PressureEmulatorConfig
from ucat_console.typedconf import Config, param

@dataclass(frozen=True)
class SimStartConfig(Config):
    """Where the simulated U-CAT starts (robot ``sim`` and ``sim-devices``)."""

    depth: float = param(0.5, lo=0.0, hi=1000.0, unit="m",
                         doc="start depth (positive down); the depth setpoint starts there too")
    yaw: float = param(0.0, lo=-math.pi, hi=math.pi, unit="rad", doc="start heading")
    velocity: float = param(0.0, lo=-5.0, hi=5.0, unit="m/s", doc="start surge (body x)")
    seed: int = param(
        -1, lo=-1, hi=2**63 - 1, doc="seed of the sensor noise; -1: the plant configuration's seed"
    )


@dataclass(frozen=True)
class SimRigConfig(Config):
    """The emulators the simulated U-CAT speaks through (robot ``sim-devices``)."""

    pace: float = param(
        1.0, lo=0.1, hi=10.0, unit="x",
        doc="simulated seconds per wall-clock second of the plant (the loop's paced clock "
        "must run at the same pace); the device protocols keep wall-clock timing",
    )
    tick_period_s: float = param(
        0.002, lo=0.0005, hi=0.05, unit="s",
        doc="the plant is stepped and the EPOS2 emulators ticked this often (wall clock)",
    )
    can_channel: str = param(
        "", doc="name of the virtual CAN bus; empty: a fresh name for each rig"
    )
    sdo_timeout_s: float = param(
        1.0, lo=0.01, hi=5.0, unit="s",
        doc="the drivers wait at least this long for an SDO reply from the emulated drives, "
        "which answer from Python threads on this computer: a busy machine delays them "
        "beyond a real EPOS2's answer (epos2.sdo_timeout)",
    )
    pressure_mount_depth: float = param(
        0.15, lo=0.0, hi=1.0, unit="m",
        doc="the emulated pressure transducer sits this far below the robot's depth reference, so it "
        "is under water (above 4 mA) while the robot floats at the surface; the drivers start zeroed for it",
    )
    imu: ImuEmulatorConfig = ImuEmulatorConfig()
    dvl: DvlEmulatorConfig = DvlEmulatorConfig()
    pressure: PressureEmulatorConfig = PressureEmulatorConfig()


@dataclass(frozen=True)
class DevicesConfig(Config):
    """The robot's devices (robot ``sim-devices`` and ``hardware``; ``plausibility`` and
    ``leak`` for every robot: the leak detector is read by the console itself)."""

    epos2: Epos2Config = Epos2Config()
    imu: ImuConfig = ImuConfig()
    dvl: DvlConfig = DvlConfig()
    pressure: PressureConfig = PressureConfig()
    leak: LeakConfig = LeakConfig()
    poll_period_s: float = param(
        0.005, lo=0.001, hi=0.1, unit="s",
        doc="the closed loop collects the drivers' readings this often (loop time)",
    )
    resync_s: float = param(
        0.5, lo=0.05, hi=10.0, unit="s",
        doc="the device clock is re-aligned with the loop's time when they differ by more "
        "than this (after the loop was paused)",
    )
    enable_at_start: bool = param(
        False,
        doc="bring every EPOS2 to operation enabled at start; otherwise the supervisor "
        "enables the drives when the robot is armed",
    )
    dvl_invalid_after: int = param(
        3, lo=1, hi=1000,
        doc="report lost bottom lock after this many consecutive velocity_valid=false reports",
    )
    plausibility: PlausibilityConfig = PlausibilityConfig()
    start: SimStartConfig = SimStartConfig()
    rig: SimRigConfig = SimRigConfig()
