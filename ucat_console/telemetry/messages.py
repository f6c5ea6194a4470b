"""Telemetry messages: what the supervisor publishes and a session file holds.

Every message is a frozen dataclass with a time ``t`` in seconds on the stream's clock
(the wall clock, UNIX epoch, for live and real-time runs; simulated time from 0 for
headless runs, which the recorder offsets to an epoch). Values are SI; angles in
radians. Fin indices are the plant's (0 front-right, 1 back-right, 2 back-left,
3 front-left). Each field's meaning, unit and frame is its :class:`Doc` annotation (the
session schemas carry it as the field's description).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated

from ucat_console.robot.fields import WXYZ, XY, XYZ, Doc

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]  # (w, x, y, z)
Vec4 = tuple[float, float, float, float]

Time = Annotated[float, Doc("time on the stream's clock", unit="s")]
Fin = Annotated[int, Doc("fin index (0 front-right, 1 back-right, 2 back-left, 3 front-left)")]
#: a plan u = [d_1, d_2, w_1, w_2] and the stroke commands [theta_1, w_1, theta_2, w_2]
PLAN_NAMES = ("d_1", "d_2", "w_1", "w_2")
COMMAND_NAMES = ("theta_1", "w_1", "theta_2", "w_2")
PLAN_UNITS = ("rad", "rad", "rad/s", "rad/s")
COMMAND_UNITS = ("rad", "rad/s", "rad", "rad/s")


@dataclass(frozen=True)
class BodyState:
    """The estimator's vehicle state (and the simulator's truth, when simulated)."""

    t: Time
    position: Annotated[Vec3, Doc("position (x north, y east, z down = depth)", "m", "NED", XYZ)]
    orientation: Annotated[Quat, Doc("attitude, rotating body vectors into NED (held w first)",
                                     "1", "body to NED", WXYZ)]
    velocity: Annotated[Vec3, Doc("velocity u, v, w", "m/s", "body FRD", XYZ)]
    rates: Annotated[Vec3, Doc("angular rates p, q, r", "rad/s", "body FRD", XYZ)]
    depth: Annotated[float, Doc("depth, positive down", "m")]


@dataclass(frozen=True)
class Setpoints:
    t: Time
    velocity: Annotated[float, Doc("forward velocity setpoint", "m/s")]
    depth: Annotated[float, Doc("depth setpoint", "m")]
    yaw_rate: Annotated[float, Doc("yaw rate setpoint, positive clockwise seen from above",
                                   "rad/s", "NED")]


@dataclass(frozen=True)
class BodyCommand:
    """The body layer's demand in the fin model's terms: the sums over the four fins' force
    targets (the paper's F_x*, F_y* and front-pair yaw differential when its layer runs)."""

    t: Time
    force_x: Annotated[float, Doc("sum of the fins' f_x targets, fin-model convention (forward thrust < 0)", "N")]
    force_y: Annotated[float, Doc("sum of the fins' f_y targets (> 0 lifts)", "N")]
    yaw: Annotated[float, Doc("sum of the fins' f_x targets, starboard minus port (> 0 turns to starboard)",
                              "N")]


@dataclass(frozen=True)
class BodyAllocation:
    """The body wrench the loops asked for and what the allocation gave them: an axis whose
    demand the fins cannot meet is cut, in the priority heave, yaw, surge; "coast" means the
    fins do not push against the direction of travel (the hull's drag brakes)."""

    t: Time
    surge: Annotated[float, Doc("surge force asked (forward > 0)", "N")]
    heave: Annotated[float, Doc("heave force asked (down > 0)", "N")]
    yaw: Annotated[float, Doc("yaw moment asked (clockwise seen from above > 0)", "N m")]
    surge_applied: Annotated[float, Doc("surge force the fins were given", "N")]
    heave_applied: Annotated[float, Doc("heave force the fins were given", "N")]
    yaw_applied: Annotated[float, Doc("yaw moment the fins were given", "N m")]
    cut: Annotated[tuple[str, ...], Doc('axes cut: "heave", "yaw", "surge", "coast"')]


@dataclass(frozen=True)
class BodyTracking:
    """What the body layer holds the robot to now, and how far the robot is from it: the
    designed layer's references (which close on the setpoints at limited rates), the paper
    layer's setpoints. Errors are measured minus reference; NaN where there is none (and
    in the identification manoeuvre, whose fins ignore the loops)."""

    t: Time
    driving: Annotated[bool, Doc("the fins are driven (armed)")]
    speed_ref: Annotated[float, Doc("forward speed reference", "m/s")]
    depth_ref: Annotated[float, Doc("depth reference (positive down)", "m")]
    heading_ref: Annotated[float, Doc("heading reference (designed layer; NaN: none)", "rad", "NED")]
    yaw_rate_ref: Annotated[float, Doc("yaw rate reference, positive clockwise seen from above", "rad/s")]
    speed_error: Annotated[float, Doc("filtered forward speed minus its reference", "m/s")]
    depth_error: Annotated[float, Doc("filtered depth minus its reference", "m")]
    heading_error: Annotated[float, Doc("heading minus its reference, wrapped to (-pi, pi]", "rad")]


@dataclass(frozen=True)
class FinState:
    """One fin's measured and commanded motion."""

    t: Time
    fin: Fin
    angle: Annotated[float, Doc("measured fin angle (0 neutral, > 0 tip up)", "rad")]
    rate: Annotated[float, Doc("measured fin rate", "rad/s")]
    angle_cmd: Annotated[float, Doc("set-point angle the fin was last sent: the target of its stroke "
                                    "(disarmed: the last one sent, or the stop)", "rad")]
    rate_cmd: Annotated[float, Doc("profile velocity of that set-point (a stroke's is timed so the stroke "
                                   "takes its planned duration)", "rad/s")]


@dataclass(frozen=True)
class FinStrouhal:
    """The Strouhal number of each stroke as it starts, with the corridor it should keep to.

    ``st = w L_f / (2 max(V_B, v_floor))``: a stroke at mean rate ``w`` is half a cycle
    of frequency ``w / (2 |d|)`` and amplitude ``|d| L_f / 2`` (control.md section 2)."""

    t: Time
    fin: Fin
    st: Annotated[float, Doc("Strouhal number of the stroke at the measured speed", "1")]
    st_low: Annotated[float, Doc("lower edge of the efficient corridor", "1")]
    st_high: Annotated[float, Doc("upper edge of the efficient corridor", "1")]
    st_opt: Annotated[float, Doc("the optimal Strouhal number the MPC aims at", "1")]
    v_body: Annotated[float, Doc("measured forward speed used", "m/s")]
    stroke: Annotated[float, Doc("stroke angle d (target minus start)", "rad")]
    rate: Annotated[float, Doc("stroke rate w (the planned mean rate)", "rad/s")]


@dataclass(frozen=True)
class FinPlan:
    """One planned cycle of one fin, with every input needed to replay it."""

    t: Time
    fin: Fin
    mode: Annotated[str, Doc("fin controller (a mode of backend.loop.modes.MODES)")]
    target: Annotated[tuple[float, float], Doc("force target (f_x*, f_y*)", "N", "fin model", XY)]
    v_body: Annotated[float, Doc("measured forward speed used", "m/s")]
    theta0: Annotated[float, Doc("fin angle the plan starts from", "rad")]
    u_prev: Annotated[Vec4, Doc("previous plan [d_1, d_2, w_1, w_2]", PLAN_UNITS, "", PLAN_NAMES)]
    u: Annotated[Vec4, Doc("plan [d_1, d_2, w_1, w_2]: strokes and mean rates", PLAN_UNITS, "",
                           PLAN_NAMES)]
    commands: Annotated[Vec4, Doc("stroke commands [theta_1, w_1, theta_2, w_2]", COMMAND_UNITS,
                                  "", COMMAND_NAMES)]
    cost_total: Annotated[float, Doc("cost J", "1")]
    cost_force: Annotated[float, Doc("force term c_force (1-norm)", "N")]
    cost_strouhal: Annotated[float, Doc("Strouhal penalty c_St", "1")]
    cost_amplitude: Annotated[float, Doc("amplitude term c_amp", "m")]
    cost_smoothness: Annotated[float, Doc("smoothness term c_diff", "1")]
    st: Annotated[float, Doc("Strouhal number of the planned cycle", "1")]
    mean_force: Annotated[tuple[float, float], Doc("cycle-mean force (f_bar_x, f_bar_y)", "N",
                                                   "body", XY)]
    solve_time: Annotated[float, Doc("planner time", "s")]
    late: Annotated[bool, Doc("the plan arrived after its fin went idle")]
    amplitude: Annotated[float, Doc("baseline only: theta_max", "rad")] = 0.0
    centre: Annotated[float, Doc("baseline only: oscillation centre", "rad")] = 0.0
    seed: Annotated[int, Doc("the planner's seed for this plan (-1: none), so a replay is exact",
                             wide=True)] = -1
    lag: Annotated[float, Doc("how long after the other fins' beats this fin's last began when it was "
                              "planned (the baseline's phase lock)", "s")] = 0.0
    align: Annotated[float, Doc("how long the cycle would last to end when the fin across the hull ends "
                                "one (the MPC's alignment; NaN: none)", "s")] = math.nan


@dataclass(frozen=True)
class FinCycle:
    """One executed cycle of one fin: the force it was asked for, and the force its executed
    strokes (measured stroke-end angles and times) make by the controller's fin model.

    ``direction_error`` is the angle between the two forces (NaN when either is below
    1 mN); ``magnitude_error`` is |delivered| - |asked|."""

    t: Time
    fin: Fin
    mode: Annotated[str, Doc("fin controller that planned the cycle")]
    target: Annotated[tuple[float, float], Doc("force asked of the fin (f_x*, f_y*)", "N", "fin model", XY)]
    delivered: Annotated[tuple[float, float], Doc("cycle-mean force of the executed strokes by the fin model",
                                                  "N", "fin model", XY)]
    direction_error: Annotated[float, Doc("angle between the asked and the delivered force", "rad")]
    magnitude_error: Annotated[float, Doc("|delivered| - |asked|", "N")]
    duration: Annotated[float, Doc("executed cycle: first stroke sent to last stroke finished", "s")]
    planned_duration: Annotated[float, Doc("the plan's cycle: sum of |d_k| / w_k", "s")]


@dataclass(frozen=True)
class Power:
    """Mechanical power from encoder positions (control.md section 9)."""

    t: Time
    per_fin: Annotated[Vec4, Doc("power per fin, by fin index", "W")]
    total: Annotated[float, Doc("total power", "W")]
    mean_total: Annotated[float, Doc("running mean over the time the fins were driven (armed)",
                                     "W")]
    energy: Annotated[float, Doc("energy spent while armed", "J")]
    distance: Annotated[float, Doc("distance travelled while armed", "m")]
    energy_per_metre: Annotated[float, Doc("energy per metre (NaN until the vehicle has moved)",
                                           "J/m")]


@dataclass(frozen=True)
class ElectricalPower:
    """The fin drives' electrical input, beside the encoder estimate of :class:`Power`: the
    motor current each drive averages (the EPOS2's 0x2027, or the simulated drive's), the
    supply voltage at its power stage (0x2200 sub 1), and the battery power it draws, from its
    current and the fin's rate through its motor, gearhead and bridge plus its own consumption
    (``robot.motor``, ``backend.drive_power``). NaN for a drive that did not answer (and in
    ``total`` then)."""

    t: Time
    current: Annotated[Vec4, Doc("motor current averaged by each drive, by fin index", "A")]
    voltage: Annotated[Vec4, Doc("supply voltage at each drive, by fin index", "V")]
    per_fin: Annotated[Vec4, Doc("battery power each drive draws, by fin index", "W")]
    total: Annotated[float, Doc("battery power of the four drives", "W")]


@dataclass(frozen=True)
class Status:
    """The supervisor's state, published at a low rate and on every change."""

    t: Time
    armed: Annotated[bool, Doc("motors armed")]
    mode: Annotated[str, Doc("fin controller")]
    pilot: Annotated[str, Doc('client id of the pilot, "" when none')]
    failsafes: Annotated[tuple[str, ...], Doc("active failsafe names")]
    late_plans: Annotated[int, Doc("plans that arrived after their fin went idle")]
    source: Annotated[str, Doc('"sim", "robot" or "playback"')]


@dataclass(frozen=True)
class CameraImage:
    """One frame of the vehicle's camera, compressed (what ``foxglove.CompressedImage``
    holds: a session file writes it with that schema, its data in base64)."""

    t: Time
    frame_id: Annotated[str, Doc("the camera's frame of reference")]
    format: Annotated[str, Doc("the compression: jpeg")]
    data: Annotated[bytes, Doc("the compressed picture")]
