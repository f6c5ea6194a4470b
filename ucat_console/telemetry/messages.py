"""Telemetry messages: what the supervisor publishes and a session file holds.

Every message is a frozen dataclass with a time ``t`` in seconds on the stream's clock
(the wall clock, UNIX epoch, for live and real-time runs; simulated time from 0 for
headless runs, which the recorder offsets to an epoch). Values are SI; angles in
radians. Fin indices are the plant's (0 front-right, 1 back-right, 2 back-left,
3 front-left).
"""

from __future__ import annotations

from dataclasses import dataclass

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]  # (w, x, y, z)
Vec4 = tuple[float, float, float, float]


@dataclass(frozen=True)
class BodyState:
    """The estimator's vehicle state (and the simulator's truth, when simulated)."""

    t: float
    position: Vec3  # NED, m (x north, y east, z down = depth)
    orientation: Quat  # body to NED
    velocity: Vec3  # body frame u, v, w, m/s
    rates: Vec3  # body frame p, q, r, rad/s
    depth: float  # m, positive down


@dataclass(frozen=True)
class Setpoints:
    t: float
    velocity: float  # forward, m/s
    depth: float  # m
    yaw_rate: float  # rad/s, positive clockwise seen from above (NED z down)


@dataclass(frozen=True)
class BodyCommand:
    """Outputs of the body-frame PIDs before allocation."""

    t: float
    force_x: float  # F_x*, fin-model convention (forward thrust < 0), N
    force_y: float  # F_y*, N
    yaw: float  # yaw thrust differential, N


@dataclass(frozen=True)
class FinState:
    """One fin's measured and commanded motion."""

    t: float
    fin: int
    angle: float  # measured, rad
    rate: float  # measured, rad/s
    angle_cmd: float  # target of the stroke being executed, rad
    rate_cmd: float  # its profile velocity, rad/s


@dataclass(frozen=True)
class FinPlan:
    """One planned cycle of one fin, with every input needed to replay it."""

    t: float
    fin: int
    mode: str  # "mpc", "mpc_sync", "baseline"
    target: tuple[float, float]  # (f_x*, f_y*), N
    v_body: float  # measured forward speed used, m/s
    theta0: float  # fin angle the plan starts from, rad
    u_prev: Vec4
    u: Vec4  # [d_1, d_2, w_1, w_2]
    commands: Vec4  # [theta_1, w_1, theta_2, w_2]
    cost_total: float
    cost_force: float
    cost_strouhal: float
    cost_amplitude: float
    cost_smoothness: float
    st: float
    mean_force: tuple[float, float]
    solve_time: float  # s
    late: bool  # the plan arrived after its fin went idle
    amplitude: float = 0.0  # baseline only: theta_max, rad
    centre: float = 0.0  # baseline only: oscillation centre, rad
    seed: int = -1  # the planner's seed for this plan (-1: none), so a replay is exact


@dataclass(frozen=True)
class Power:
    """Mechanical power from encoder positions (control.md section 9)."""

    t: float
    per_fin: Vec4  # W
    total: float  # W
    mean_total: float  # running mean over the time the fins were driven (armed), W
    energy: float  # J spent while armed
    distance: float  # m travelled while armed
    energy_per_metre: float  # J/m (NaN until the vehicle has moved)


@dataclass(frozen=True)
class Status:
    """The supervisor's state, published at a low rate and on every change."""

    t: float
    armed: bool
    mode: str
    pilot: str  # client id of the pilot, "" when none
    failsafes: tuple[str, ...]  # active failsafe names
    late_plans: int
    source: str  # "sim", "robot", "playback"
