"""Configuration of the closed loop: controller mode, hand-over latency, rates, envelope.

One :class:`LoopConfig` holds everything the loop needs besides the robot: the controller
blocks of ``control/params.py`` and the loop's own values below. It is the only holder of
the controller blocks: the application's configuration (``config.AppConfig``) keeps them
here and reads them from here.
"""

from __future__ import annotations

from dataclasses import dataclass

from ucat_console.backend.loop.modes import mode_names
from ucat_console.control.params import (
    BaselineConfig,
    BodyConfig,
    ExecutorConfig,
    ManoeuvreConfig,
    MpcConfig,
    PowerConfig,
)
from ucat_console.typedconf import Config, param


@dataclass(frozen=True)
class LoopConfig(Config):
    """The closed loop (control.md sections 7-9)."""

    # the registry is read at each check: a mode registered after this import is a choice too
    mode: str = param("mpc", choices=mode_names, doc="fin controller (a mode of ``modes.MODES``)")
    plan_latency: float = param(
        0.02, lo=0.0, hi=1.0, unit="s",
        doc="a plan requested at t is handed to its executor at t + plan_latency "
        "(simulated time; real time waits for the planner thread if it is not done)",
    )
    control_rate: float = param(50.0, lo=1.0, hi=1000.0, unit="Hz", doc="body-frame PID rate")
    state_rate: float = param(
        50.0, lo=1.0, hi=1000.0, unit="Hz", doc="BodyState / FinState / BodyCommand telemetry rate"
    )
    power_rate: float = param(10.0, lo=0.1, hi=1000.0, unit="Hz", doc="Power telemetry rate")
    status_rate: float = param(1.0, lo=0.1, hi=100.0, unit="Hz", doc="Status / Setpoints telemetry rate")
    max_velocity: float = param(
        0.5, lo=0.0, hi=5.0, lo_open=True, unit="m/s", doc="envelope: largest |forward velocity| setpoint"
    )
    max_depth: float = param(50.0, lo=0.0, hi=1000.0, lo_open=True, unit="m", doc="envelope: deepest depth setpoint")
    max_yaw_rate: float = param(
        0.5, lo=0.0, hi=10.0, lo_open=True, unit="rad/s", doc="envelope: largest |yaw rate| setpoint"
    )
    attitude: str = param(
        "imu", choices=("imu", "ekf"),
        doc="attitude from the IMU's own filter, or from the console's EKF on gyro and accel",
    )
    planner_seed: int = param(0, lo=0, hi=2**31 - 1, doc="seed of the planners' random streams")
    initial_u_prev: tuple[float, float, float, float] = param(
        (0.5, -0.5, 2.0, 2.0), doc="u_prev of a fin's first plan (the benchmark protocol's start)"
    )
    mpc: MpcConfig = MpcConfig()
    baseline: BaselineConfig = BaselineConfig()
    body: BodyConfig = BodyConfig()
    executor: ExecutorConfig = ExecutorConfig()
    power: PowerConfig = PowerConfig()
    manoeuvre: ManoeuvreConfig = ManoeuvreConfig()

    def _check(self) -> None:
        if len(self.initial_u_prev) != 4:
            raise ValueError(f"initial_u_prev: expected 4 numbers, got {self.initial_u_prev!r}")
