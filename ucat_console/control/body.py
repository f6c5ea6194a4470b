# Over 600 lines: both body layers (the paper's and the designed one) and their schedule run in one compiled step over one state row.
"""The body-frame layer: the loops on speed, depth and heading, and their allocation.

Control.md section 7; ``BodyConfig.layer`` picks one of two layers over the same readings:

* ``designed`` (``control.body_design`` for the gains, ``docs/control.md``): physical
  demands, each loop tracking a reference with the hull's model as feed-forward. The
  references close on their setpoints at ``reference_rate`` per second, their rates limited
  (``max_acceleration``, ``max_dive_rate``, ``max_yaw_acceleration``; the speed's
  acceleration rising to its limit over ``acceleration_rise``), starting from what is
  measured: a setpoint step becomes a ramp the loops can follow, with no kick and no
  windup. Velocity: ``X = M_x u_ref' + D_x(u_ref) + PI(u_ref - u)``. Depth: ``Z = Z_trim +
  D_z(z_ref') + PI(z_ref - z)`` (down > 0). Heading: ``N = J r_ref' + N_r(r_ref) + kp e +
  ki int e + kd (r_ref - r)`` with ``e = psi_ref - psi`` (wrapped), ``psi_ref`` integrating
  the yaw-rate reference from the heading measured when the loop started (a zero setpoint
  holds that heading whatever pushes the robot off it; in a turn ``psi_ref`` never runs more
  than ``max_heading_lead`` ahead of the robot, and the loop never sees more error than that). The wrench goes to :func:`~ucat_console.control.allocation.allocate_wrench`; an
  axis it cut has its loop's last integration undone (anti-windup fed by the allocation),
  and each loop's output limit is what the fins can deliver on its axis. Fins that make
  ``force_scale_from`` times the fin model's force or more (measured from the surge balance,
  :func:`_measure_scale`) are asked for that much less on every axis. A fin asked for less
  than ``direction_hold`` (by the fin model) keeps the direction of the cycle it runs
  (:func:`_held`).
* ``paper`` (section IV.B): ``F_x* = -PID_v(v_ref - v)``, ``F_y* = depth_sign *
  PID_z(z_ref - z)``, a yaw thrust differential ``m = PID_r(r_ref - r)``, allocated by
  :func:`~ucat_console.control.allocation.fin_targets`.

Readings: DVL velocity and depth are median filtered (``median_window``); the yaw rate is
the gyro's z; the heading is the attitude estimate's yaw, set by the caller at each control
step (:func:`body_set_heading`). A loop runs only on a new sample; otherwise its output is
held. A DVL report with ``valid=False`` is missing data: it is counted and never enters the
filter as a zero velocity.

All numbers are one array (its declared layout :data:`BODY`, columns ``B_*``) that the
``body_*`` functions work on: :class:`BodyController` runs them as Python, the closed
loop's compiled core runs the same functions compiled on the loop's controller's array. Over 500 lines because the layer's
compiled functions and the Python controller that runs them share that one array's layout
and its loops; split, one layer would be spread over files.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba.extending import register_jitable

from ucat_console.control.allocation import (
    A_ARM,
    A_COS,
    A_GAIN,
    NA,
    NW,
    W_N,
    W_TARGETS,
    W_X,
    W_Z,
    Allocation,
    BodySetpoints,
    CUT_HEAVE,
    CUT_SURGE,
    CUT_COAST,
    CUT_YAW,
    allocate,
    allocate_wrench,
    cut_names,
    fin_targets,
    wrench_params,
    _logical,
)
from ucat_console.control.argcheck import finite
from ucat_console.control.filters import MedianFilter, median_clear, median_push, median_size, median_value
from ucat_console.control.body_design import gain_schedule
from ucat_console.control.params import DESIGN_DELAY, DESIGN_FACTOR, BodyConfig, ExecutorConfig, MpcConfig
from ucat_console.control.pid import EARLIER, NPID, Pid, pid_reset, pid_step, pid_step_rate, pid_unwind
from ucat_console.control.stroke_timing import deliverable_force
from ucat_console.robot.fins import PAPER_SIDES
from ucat_console.robot.geometry import ARM_YAW, MOUNTING_ANGLE_DEG
from ucat_console.robot.layout import Layout
from ucat_console.robot.readings import DepthReading, DvlVelocity, ImuReading

# the declared layout of the body-frame layer's numbers (one float array): what the readings
# left, the loops' outputs, the designed layer's parameters and state, the allocation's
# parameters and output, then the three PIDs (``pid.PID_ROW`` each) and the two median filters
H_SURGE_D, H_SURGE_DQ, H_HEAVE_D, H_HEAVE_DQ, H_YAW_D, H_YAW_DQ, H_SURGE_M, H_HEAVE_M, H_YAW_J = range(9)
NH = 9
BODY = Layout("the body-frame layer's array", [
    ("dvl_missing", 1, "DVL reports without bottom lock since the reset"),
    ("last_dvl_t", 1, "time of the last valid DVL report (NaN: none)"),
    ("last_depth_t", 1, "time of the last depth"), ("last_imu_t", 1, "time of the last IMU reading"),
    ("yaw_rate", 1, "the last gyro rate (NaN: none)"),
    ("new_v", 1, "1.0: a speed sample the loop has not run on yet"), ("new_z", 1, "a depth sample"),
    ("new_r", 1, "a yaw rate sample"),
    ("fx", 1, "paper layer: the loops' last output F_x* (held while a loop has no new sample)"),
    ("fy", 1, "F_y*"), ("yaw", 1, "m"), ("depth_sign", 1, "the depth loop's sign"),
    ("window", 1, "the median filters' length"), ("layer", 1, "0.0 paper, 1.0 designed"),
    ("heading", 1, "the attitude estimate's heading (rad; NaN: none)"),
    ("heading_ref", 1, "the heading reference (NaN: take the present heading)"),
    ("t_ref", 1, "when the references last moved (NaN: not yet)"), ("trim", 1, "heave trim (N)"),
    ("hull", NH, "the hull model (H_* offsets)"), ("lead", 1, "the largest heading lead (rad)"),
    ("ref_rate", 1, "how fast the references close on their setpoints (1/s)"),
    ("max_dive", 1, "the references' rate limits: depth rate"), ("max_acc", 1, "acceleration"),
    ("max_yaw_acc", 1, "yaw acceleration"),
    ("acc_rise", 1, "how long the speed reference's acceleration takes to rise to its limit (s)"),
    ("v_ref", 1, "the speed reference"), ("v_ref_rate", 1, "its rate of change"), ("z_ref", 1, "the depth reference"),
    ("z_ref_rate", 1, "its rate"), ("r_ref", 1, "the yaw rate reference"), ("r_ref_rate", 1, "its rate"),
    ("x", 1, "designed: the loops' demand: surge (N)"), ("z", 1, "heave (N, down > 0)"), ("n", 1, "yaw moment (N m)"),
    ("applied", 3, "what the allocation applied (the order of x, z, n)"), ("cut", 1, "its cut bits (allocation.CUT_*)"),
    ("speed_tau", 1, "designed: the speed low-pass's time constant (s; 0: none)"),
    ("v_lp", 1, "the low-passed speed (NaN: no sample yet)"), ("v_lp_t", 1, "the time of its last sample"),
    ("alloc", NA, "the allocation's parameters (allocation.A_*)"), ("out", NW, "its output (allocation.W_*)"),
    ("cycle_target", 8, "each paper fin's running cycle: the force it was asked (f_x, f_y; NaN: none yet)"),
    ("cycle_force", 8, "the force its plan makes by the fin model (f_x, f_y)"),
    ("cycle_bias", 8, "what its last executed cycle made short of its plan, by the fin model (f_x, f_y)"),
    ("bias_weight", 1, "designed: 1.0 the executed cycles correct the plans' force, 0.0 not"),
    ("shortfall", 3, "designed: the fins' shortfall fed forward (surge N, heave N, yaw N m)"),
    ("shortfall_cap", 3, "its bound on each axis"), ("shortfall_tau", 1, "its time constant (s; < 0: none)"),
    ("shortfall_t", 1, "when it last moved (NaN: not yet)"),
    ("scale", 1, "designed: the fins' force per unit of the fin model's that the allocation divides the demand by"),
    ("scale_from", 1, "the measured scale from which it follows the measurement (<= 0: never)"),
    ("scale_max", 1, "the largest it follows"), ("scale_est", 1, "the measured scale (the surge balance)"),
    ("scale_v", 1, "the speed low-passed at SCALE_FILTER (NaN: no sample yet)"),
    ("scale_drag", 1, "the hull's drag at the speed, low-passed the same"),
    ("scale_given", 1, "the surge the fins were given by the fin model, through their lag (N)"),
    ("scale_given_f", 1, "that low-passed the same"), ("scale_xy", 1, "running mean of given x made (N^2)"),
    ("scale_xx", 1, "running mean of given^2 (N^2)"), ("scale_t", 1, "when it last moved (NaN: not yet)"),
    ("scale_t0", 1, "when its filters started"),
    ("hold", 1, "designed: a fin's target below this (N, by the fin model) keeps its running cycle's "
             "direction (0: never)"),
    ("asked", 3, "the loops' demand and the shortfall"),
    ("pids", 3 * NPID, "velocity, depth, yaw rate or heading: a PID row each"),
    ("filters", 1, "velocity filter, then depth filter: median_size(window) numbers each (the array's rest)"),
])
B_DVL_MISSING, B_LAST_DVL_T, B_LAST_DEPTH_T, B_LAST_IMU_T, B_YAW_RATE, B_NEW_V, B_NEW_Z, B_NEW_R = (
    BODY.at(f) for f in BODY.fields[:8])
B_FX, B_FY, B_YAW, B_DEPTH_SIGN, B_WINDOW, B_LAYER, B_HEADING, B_HEADING_REF, B_T_REF, B_TRIM, B_HULL = (
    BODY.at(f) for f in BODY.fields[8:19])
B_LEAD, B_REF_RATE, B_MAX_DIVE, B_MAX_ACC, B_MAX_YAW_ACC, B_ACC_RISE, B_V_REF, B_V_REF_RATE, B_Z_REF, \
    B_Z_REF_RATE = (BODY.at(f) for f in BODY.fields[19:29])
B_R_REF, B_R_REF_RATE, B_X, B_Z, B_N, B_APPLIED, B_CUT, B_SPEED_TAU, B_V_LP, B_V_LP_T, B_ALLOC, B_OUT = (
    BODY.at(f) for f in BODY.fields[29:41])
B_CYCLE_TARGET, B_CYCLE_FORCE, B_CYCLE_BIAS, B_BIAS_WEIGHT, B_SHORTFALL, B_SHORTFALL_CAP, B_SHORTFALL_TAU, \
    B_SHORTFALL_T = (BODY.at(f) for f in BODY.fields[41:49])
B_SCALE, B_SCALE_FROM, B_SCALE_MAX, B_SCALE_EST, B_SCALE_V, B_SCALE_DRAG, B_SCALE_GIVEN, B_SCALE_GIVEN_F, \
    B_SCALE_XY, B_SCALE_XX, B_SCALE_T, B_SCALE_T0, B_HOLD, B_ASKED, B_PIDS, B_FILTERS = (
        BODY.at(f) for f in BODY.fields[49:])
#: what the body functions return: all is well, or which input was not a finite number
BODY_OK, BAD_DVL_VX, BAD_DVL_T, BAD_DEPTH, BAD_DEPTH_T, BAD_GYRO, BAD_IMU_T, BAD_T, EARLIER_T = range(9)
#: the field each bad input is named by
BODY_FIELDS = {BAD_DVL_VX: "dvl.vx", BAD_DVL_T: "dvl.t", BAD_DEPTH: "depth.depth_m", BAD_DEPTH_T: "depth.t",
               BAD_GYRO: "imu.gyro[2]", BAD_IMU_T: "imu.t", BAD_T: "t"}
LAYERS = {"paper": 0.0, "designed": 1.0}
#: how close (s) the scheduled delay comes to a fin's period before it takes it
PERIOD_SNAP = 1e-3
#: the force scale's measurement (:func:`_measure_scale`): the low-pass both sides of the
#: surge balance go through (s), the lag the fins' force follows the surge they are given
#: with (s; they take a new demand up at their next cycle, half a second at the 2-Hz beat),
#: how long the fit remembers (s), and the least mean square of the surge given (N^2) below
#: which the balance tells nothing and the last measurement holds
SCALE_FILTER, SCALE_LAG, SCALE_MEMORY, SCALE_EXCITATION = 1.0, 0.5, 5.0, 0.01


def body_size(window: int) -> int:
    return B_FILTERS + 2 * median_size(window)


@register_jitable
def body_reset(b: np.ndarray) -> None:
    """Forget every reading, output and held heading (the gains and parameters stay)."""
    for k in range(3):
        pid_reset(b[B_PIDS + k * NPID:B_PIDS + (k + 1) * NPID])
    median_clear(b, B_FILTERS)
    median_clear(b, B_FILTERS + median_size(int(b[B_WINDOW])))
    b[B_DVL_MISSING] = 0.0
    b[B_LAST_DVL_T] = math.nan
    b[B_LAST_DEPTH_T] = math.nan
    b[B_LAST_IMU_T] = math.nan
    b[B_YAW_RATE] = math.nan
    b[B_NEW_V] = 0.0
    b[B_NEW_Z] = 0.0
    b[B_NEW_R] = 0.0
    b[B_FX] = 0.0
    b[B_FY] = 0.0
    b[B_YAW] = 0.0
    b[B_HEADING] = math.nan
    b[B_HEADING_REF] = math.nan
    b[B_T_REF] = math.nan
    b[B_V_LP] = math.nan
    b[B_V_LP_T] = math.nan
    for k in range(B_V_REF, B_R_REF_RATE + 1):
        b[k] = math.nan
    b[B_X] = 0.0
    b[B_Z] = b[B_TRIM]
    b[B_N] = 0.0
    for k in range(3):
        b[B_APPLIED + k] = 0.0
    b[B_CUT] = 0.0
    for k in range(NW):
        b[B_OUT + k] = 0.0
    for k in range(8):
        b[B_CYCLE_TARGET + k] = math.nan
        b[B_CYCLE_FORCE + k] = math.nan
        b[B_CYCLE_BIAS + k] = 0.0
    for k in range(3):
        b[B_SHORTFALL + k] = 0.0
    b[B_SHORTFALL_T] = math.nan
    # the force scale found stays (the fins did not change); its filters start again
    b[B_SCALE_V] = math.nan
    b[B_SCALE_T] = math.nan
    b[B_ASKED] = 0.0
    b[B_ASKED + 1] = b[B_TRIM]
    b[B_ASKED + 2] = 0.0


@register_jitable
def body_on_dvl(b: np.ndarray, valid: bool, v: float, t: float) -> int:
    """A DVL report (forward velocity ``v``): missing data when not ``valid`` (counted,
    never a zero velocity)."""
    if not valid:
        b[B_DVL_MISSING] += 1.0
        return BODY_OK
    if not math.isfinite(v):
        return BAD_DVL_VX
    if not math.isfinite(t):
        return BAD_DVL_T
    w = int(b[B_WINDOW])
    median_push(b, B_FILTERS, w, v)
    m = median_value(b, B_FILTERS, w)
    tau = b[B_SPEED_TAU]
    if math.isnan(b[B_V_LP]) or not tau > 0.0:
        b[B_V_LP] = m
    else:
        b[B_V_LP] += (1.0 - math.exp(-max(0.0, t - b[B_V_LP_T]) / tau)) * (m - b[B_V_LP])
    b[B_V_LP_T] = t
    b[B_LAST_DVL_T] = t
    b[B_NEW_V] = 1.0
    return BODY_OK


@register_jitable
def body_on_depth(b: np.ndarray, z: float, t: float) -> int:
    if not math.isfinite(z):
        return BAD_DEPTH
    if not math.isfinite(t):
        return BAD_DEPTH_T
    w = int(b[B_WINDOW])
    median_push(b, B_FILTERS + median_size(w), w, z)
    b[B_LAST_DEPTH_T] = t
    b[B_NEW_Z] = 1.0
    return BODY_OK


@register_jitable
def body_on_imu(b: np.ndarray, r: float, t: float) -> int:
    """An IMU sample: its yaw rate (gyro z) ``r``."""
    if not math.isfinite(r):
        return BAD_GYRO
    if not math.isfinite(t):
        return BAD_IMU_T
    b[B_YAW_RATE] = r
    b[B_LAST_IMU_T] = t
    b[B_NEW_R] = 1.0
    return BODY_OK


@register_jitable
def body_set_heading(b: np.ndarray, qw: float, qx: float, qy: float, qz: float) -> None:
    """The attitude estimate (body -> NED quaternion) at this control step: its heading."""
    if math.isfinite(qw + qx + qy + qz):
        b[B_HEADING] = math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))


@register_jitable
def body_sensors_reported(b: np.ndarray) -> bool:
    return not math.isnan(b[B_LAST_DEPTH_T]) and (not math.isnan(b[B_LAST_DVL_T]) or b[B_DVL_MISSING] > 0.0)


@register_jitable
def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@register_jitable
def _paper_loops(b: np.ndarray, t: float, sp_v: float, sp_z: float, sp_r: float, v: float, z: float,
                 r: float) -> int:
    status = BODY_OK
    if b[B_NEW_V] != 0.0 and not math.isnan(v):
        out = pid_step(b[B_PIDS:B_PIDS + NPID], sp_v - v, v, t)
        if out == EARLIER:
            status = EARLIER_T
        else:
            b[B_FX] = -out
    if b[B_NEW_Z] != 0.0 and not math.isnan(z):
        out = pid_step(b[B_PIDS + NPID:B_PIDS + 2 * NPID], sp_z - z, z, t)
        if out == EARLIER:
            status = EARLIER_T
        else:
            b[B_FY] = b[B_DEPTH_SIGN] * out
    if b[B_NEW_R] != 0.0 and not math.isnan(r):
        out = pid_step(b[B_PIDS + 2 * NPID:B_PIDS + 3 * NPID], sp_r - r, r, t)
        if out == EARLIER:
            status = EARLIER_T
        else:
            b[B_YAW] = out
    return status


@register_jitable
def _approach(ref: float, rate_before: float, rate_of: float, target: float, k: float, limit: float, rise: float,
              dt: float) -> tuple[float, float]:
    """A reference closing on ``target`` at ``k`` per second, its rate at most ``limit`` and
    moving from ``rate_before`` by at most ``limit`` in ``rise`` seconds (0, or no rate
    before: at once): (the reference after ``dt``, its rate). NaN stays NaN until
    ``rate_of`` starts it."""
    if math.isnan(ref):
        if math.isnan(rate_of):
            return math.nan, math.nan
        ref = rate_of
    rate = min(limit, max(-limit, k * (target - ref)))
    if rise > 0.0 and not math.isnan(rate_before):
        most = limit * dt / rise
        rate = min(rate_before + most, max(rate_before - most, rate))
    return ref + rate * dt, rate


@register_jitable
def _move_references(b: np.ndarray, t: float, sp_v: float, sp_z: float, sp_r: float, v: float, z: float,
                     r: float) -> None:
    """The designed layer's references move on to ``t``: speed and depth close on their
    setpoints from the first measurement (the speed's acceleration rising over
    ``acceleration_rise``), the yaw rate from the first gyro rate, the heading integrates the
    yaw-rate reference from the first heading."""
    dt = 0.0 if math.isnan(b[B_T_REF]) else max(0.0, t - b[B_T_REF])
    k = b[B_REF_RATE]
    b[B_V_REF], b[B_V_REF_RATE] = _approach(b[B_V_REF], b[B_V_REF_RATE], v, sp_v, k, b[B_MAX_ACC], b[B_ACC_RISE], dt)
    b[B_Z_REF], b[B_Z_REF_RATE] = _approach(b[B_Z_REF], b[B_Z_REF_RATE], z, sp_z, k, b[B_MAX_DIVE], 0.0, dt)
    r_before = b[B_R_REF]
    b[B_R_REF], b[B_R_REF_RATE] = _approach(r_before, b[B_R_REF_RATE], r, sp_r, k, b[B_MAX_YAW_ACC], 0.0, dt)
    if math.isnan(b[B_HEADING_REF]):
        b[B_HEADING_REF] = b[B_HEADING]
    elif not math.isnan(r_before):
        b[B_HEADING_REF] = _wrap(b[B_HEADING_REF] + 0.5 * (r_before + b[B_R_REF]) * dt)
    b[B_T_REF] = t


@register_jitable
def _designed_loops(b: np.ndarray, t: float, sp_v: float, sp_z: float, sp_r: float, v: float, z: float,
                    r: float) -> int:
    _move_references(b, t, sp_v, sp_z, sp_r, v, z, r)
    h = B_HULL
    status = BODY_OK
    v_ref = b[B_V_REF]
    if b[B_NEW_V] != 0.0 and not math.isnan(v):
        _measure_scale(b, v, t)
    if b[B_NEW_V] != 0.0 and not math.isnan(v) and not math.isnan(v_ref):
        out = pid_step(b[B_PIDS:B_PIDS + NPID], v_ref - v, v, t)
        if out == EARLIER:
            status = EARLIER_T
        else:
            b[B_X] = (b[h + H_SURGE_M] * b[B_V_REF_RATE] + b[h + H_SURGE_D] * v_ref
                      + b[h + H_SURGE_DQ] * v_ref * abs(v_ref) + out)
    z_ref = b[B_Z_REF]
    if b[B_NEW_Z] != 0.0 and not math.isnan(z) and not math.isnan(z_ref):
        out = pid_step(b[B_PIDS + NPID:B_PIDS + 2 * NPID], z_ref - z, z, t)
        if out == EARLIER:
            status = EARLIER_T
        else:
            w = b[B_Z_REF_RATE]
            b[B_Z] = b[B_TRIM] + b[h + H_HEAVE_D] * w + b[h + H_HEAVE_DQ] * w * abs(w) + out
    psi, psi_ref, r_ref = b[B_HEADING], b[B_HEADING_REF], b[B_R_REF]
    if b[B_NEW_R] != 0.0 and not math.isnan(r) and not math.isnan(psi) and not math.isnan(psi_ref) \
            and not math.isnan(r_ref):
        lead = b[B_LEAD]
        e_full = _wrap(psi_ref - psi)
        e = min(lead, max(-lead, e_full))
        out = pid_step_rate(b[B_PIDS + 2 * NPID:B_PIDS + 3 * NPID], e, r_ref - r, t)
        if out == EARLIER:
            status = EARLIER_T
        else:
            if e != e_full and sp_r != 0.0:  # turning faster than the robot: the reference waits
                b[B_HEADING_REF] = _wrap(psi + e)
            b[B_N] = (b[h + H_YAW_J] * b[B_R_REF_RATE] + b[h + H_YAW_D] * r_ref
                      + b[h + H_YAW_DQ] * r_ref * abs(r_ref) + out)
    return status


@register_jitable
def _measure_scale(b: np.ndarray, v: float, t: float) -> None:
    """The fins' force scale moves on to a speed ``v`` at ``t``: the hull's surge equation
    ``M u' + D(u) = s X`` read as a least-squares fit of ``s``, ``X`` the surge the
    allocation gave the fins by the fin model (before the scale) through a first-order lag
    of ``SCALE_LAG``, both sides low-passed at ``SCALE_FILTER`` (``M u'`` as ``M (u -
    u_f) / SCALE_FILTER``, no differentiated noise), the sums forgotten over
    ``SCALE_MEMORY``. While the fins were given too little surge to tell, the last
    measurement holds. The allocation follows it from ``scale_from`` on (within
    ``scale_max``) and leaves it when it falls back below halfway to 1."""
    if not b[B_SCALE_FROM] > 0.0:
        return
    h = B_HULL
    given = b[B_OUT + W_X] if not math.isnan(b[B_V_REF]) else 0.0
    drag = b[h + H_SURGE_D] * v + b[h + H_SURGE_DQ] * v * abs(v)
    if math.isnan(b[B_SCALE_T]):
        b[B_SCALE_V], b[B_SCALE_DRAG] = v, drag
        b[B_SCALE_GIVEN] = b[B_SCALE_GIVEN_F] = drag
        b[B_SCALE_T0] = t
    else:
        dt = max(0.0, t - b[B_SCALE_T])
        a = 1.0 - math.exp(-dt / SCALE_FILTER)
        b[B_SCALE_GIVEN] += (1.0 - math.exp(-dt / SCALE_LAG)) * (given - b[B_SCALE_GIVEN])
        b[B_SCALE_GIVEN_F] += a * (b[B_SCALE_GIVEN] - b[B_SCALE_GIVEN_F])
        b[B_SCALE_V] += a * (v - b[B_SCALE_V])
        b[B_SCALE_DRAG] += a * (drag - b[B_SCALE_DRAG])
        made = b[h + H_SURGE_M] * (v - b[B_SCALE_V]) / SCALE_FILTER + b[B_SCALE_DRAG]
        x = b[B_SCALE_GIVEN_F]
        k = 1.0 - math.exp(-dt / SCALE_MEMORY)
        if t - b[B_SCALE_T0] < SCALE_MEMORY:  # a plain mean until it has a memory's worth
            k = max(k, dt / max(dt, t - b[B_SCALE_T0]))
        b[B_SCALE_XY] += k * (x * made - b[B_SCALE_XY])
        b[B_SCALE_XX] += k * (x * x - b[B_SCALE_XX])
        if b[B_SCALE_XX] > SCALE_EXCITATION:
            b[B_SCALE_EST] = b[B_SCALE_XY] / b[B_SCALE_XX]
    b[B_SCALE_T] = t
    est, start = b[B_SCALE_EST], b[B_SCALE_FROM]
    if est >= start or (b[B_SCALE] > 1.0 and est >= 0.5 * (1.0 + start)):
        b[B_SCALE] = min(b[B_SCALE_MAX], max(1.0, est))
    else:
        b[B_SCALE] = 1.0


@register_jitable
def body_on_cycle(b: np.ndarray, k: int, tx: float, ty: float, fx: float, fy: float) -> None:
    """Paper fin ``k`` begins a cycle asked for ``(tx, ty)`` whose plan makes ``(fx, fy)``
    by the fin model (N, the fin model's frame)."""
    b[B_CYCLE_TARGET + 2 * k] = tx
    b[B_CYCLE_TARGET + 2 * k + 1] = ty
    b[B_CYCLE_FORCE + 2 * k] = fx
    b[B_CYCLE_FORCE + 2 * k + 1] = fy


@register_jitable
def body_on_executed(b: np.ndarray, k: int, px: float, py: float, ex: float, ey: float) -> None:
    """Paper fin ``k`` finished a cycle whose plan made ``(px, py)`` by the fin model and whose
    executed strokes made ``(ex, ey)``: what it fell short is taken off its next plans' force
    (a weak or lagging drive)."""
    w = b[B_BIAS_WEIGHT]
    b[B_CYCLE_BIAS + 2 * k] = w * (ex - px)
    b[B_CYCLE_BIAS + 2 * k + 1] = w * (ey - py)


@register_jitable
def _fin_wrench(b: np.ndarray, fx: float, fy: float, k: int) -> tuple[float, float, float]:
    """The physical wrench (surge, heave down > 0, yaw) of paper fin ``k``'s model force."""
    if fx < 0.0:
        fx *= b[B_ALLOC + A_GAIN]
    s = b[B_SCALE]
    return -s * b[B_ALLOC + A_COS] * fx, -s * fy, s * PAPER_SIDES[k] * b[B_ALLOC + A_ARM] * fx


@register_jitable
def _move_shortfall(b: np.ndarray, t: float) -> None:
    """The fins' shortfall moves on to ``t``: the wrench the running cycles were asked for
    minus the one their plans make by the fin model (each corrected by what the fin's last
    executed cycle fell short of its plan), low-passed, within its bounds."""
    tau = b[B_SHORTFALL_TAU]
    if tau < 0.0:
        return
    sx = sz = sn = 0.0
    for k in range(4):
        tx, ty = b[B_CYCLE_TARGET + 2 * k], b[B_CYCLE_TARGET + 2 * k + 1]
        fx, fy = b[B_CYCLE_FORCE + 2 * k], b[B_CYCLE_FORCE + 2 * k + 1]
        if math.isnan(tx + ty + fx + fy):
            continue
        ax, az, an = _fin_wrench(b, tx, ty, k)
        mx, mz, mn = _fin_wrench(b, fx + b[B_CYCLE_BIAS + 2 * k], fy + b[B_CYCLE_BIAS + 2 * k + 1], k)
        sx += ax - mx
        sz += az - mz
        sn += an - mn
    dt = 0.0 if math.isnan(b[B_SHORTFALL_T]) else max(0.0, t - b[B_SHORTFALL_T])
    a = 1.0 if tau == 0.0 else 1.0 - math.exp(-dt / tau)
    for k, v in ((0, sx), (1, sz), (2, sn)):
        cap = b[B_SHORTFALL_CAP + k]
        y = b[B_SHORTFALL + k] + a * (v - b[B_SHORTFALL + k])
        b[B_SHORTFALL + k] = min(cap, max(-cap, y))
    b[B_SHORTFALL_T] = t


@register_jitable
def body_allocate(b: np.ndarray, sp_v: float, sync: bool) -> int:
    """The designed layer's allocation of its loops' demand with the fins' shortfall (in
    ``b[B_OUT:]``), and the cut fed back to the loops; the cut bits."""
    # before a speed is measured the velocity loop is silent: no surge is made up, and the
    # fins may push either way for yaw (nothing says the robot is under way)
    moving = not math.isnan(b[B_V_REF])
    x = b[B_X] + (b[B_SHORTFALL] if moving else 0.0)
    z = b[B_Z] + b[B_SHORTFALL + 1]
    n = b[B_N] + b[B_SHORTFALL + 2]
    b[B_ASKED], b[B_ASKED + 1], b[B_ASKED + 2] = x, z, n
    direction = 0.0 if not moving else 1.0 if sp_v > 0.0 else -1.0 if sp_v < 0.0 else 0.0
    s = b[B_SCALE]  # the fins make s times the fin model's force: ask them for 1/s of the demand
    cut = allocate_wrench(x / s, z / s, n / s, direction, sync, b[B_ALLOC:B_ALLOC + NA], b[B_OUT:B_OUT + NW])
    b[B_APPLIED] = s * b[B_OUT + W_X]
    b[B_APPLIED + 1] = s * b[B_OUT + W_Z]
    b[B_APPLIED + 2] = s * b[B_OUT + W_N]
    b[B_CUT] = cut
    if cut & (CUT_SURGE | CUT_COAST):
        pid_unwind(b[B_PIDS:B_PIDS + NPID], x - b[B_APPLIED])
    if cut & CUT_HEAVE:
        pid_unwind(b[B_PIDS + NPID:B_PIDS + 2 * NPID], z - b[B_APPLIED + 1])
    if cut & CUT_YAW:
        pid_unwind(b[B_PIDS + 2 * NPID:B_PIDS + 3 * NPID], n - b[B_APPLIED + 2])
    return cut


@register_jitable
def body_update(b: np.ndarray, t: float, sp_v: float, sp_z: float, sp_r: float,
                sync: bool) -> tuple[int, float, float]:
    """One control step at ``t``: each loop that has a new sample runs (else its output is
    held), then the designed layer allocates. Returns (BODY_OK or what was wrong, the
    filtered velocity, the filtered depth: NaN before a sample). The paper layer's outputs
    are ``b[B_FX]``, ``b[B_FY]``, ``b[B_YAW]``; the designed layer's are in ``b[B_OUT:]``
    (:func:`body_targets` reads either)."""
    if not math.isfinite(t):
        return BAD_T, math.nan, math.nan
    w = int(b[B_WINDOW])
    v = median_value(b, B_FILTERS, w) if b[B_LAYER] == 0.0 else b[B_V_LP]
    z = median_value(b, B_FILTERS + median_size(w), w)
    r = b[B_YAW_RATE]
    if b[B_LAYER] == 0.0:
        status = _paper_loops(b, t, sp_v, sp_z, sp_r, v, z, r)
    else:
        status = _designed_loops(b, t, sp_v, sp_z, sp_r, v, z, r)
        _move_shortfall(b, t)
        body_allocate(b, sp_v, sync)
    b[B_NEW_V] = 0.0
    b[B_NEW_Z] = 0.0
    b[B_NEW_R] = 0.0
    return status, v, z


@register_jitable
def body_targets(b: np.ndarray, k: int) -> tuple[float, float]:
    """Paper fin ``k``'s force target (f_x, f_y) from the last step (either layer)."""
    if b[B_LAYER] == 0.0:
        sx, sy, px, py, rx, ry = fin_targets(b[B_FX], b[B_FY], b[B_YAW])
        if k == 0:
            return sx, sy
        if k == 1:
            return px, py
        return rx, ry
    return _held(b, k, b[B_OUT + W_TARGETS + 2 * k], b[B_OUT + W_TARGETS + 2 * k + 1])


@register_jitable
def _held(b: np.ndarray, k: int, tx: float, ty: float) -> tuple[float, float]:
    """Paper fin ``k``'s designed target ``(tx, ty)``, or, when it is below the hold, the
    part of it along the direction of the cycle the fin runs (at least a thousandth of the
    hold, so the direction stays)."""
    hold = b[B_HOLD]
    if not tx * tx + ty * ty < hold * hold:
        return tx, ty
    px, py = b[B_CYCLE_TARGET + 2 * k], b[B_CYCLE_TARGET + 2 * k + 1]
    pm = math.hypot(px, py)
    if not pm > 0.0:  # no cycle yet (NaN), or one asked for nothing
        return tx, ty
    d = max((tx * px + ty * py) / pm, 1e-3 * hold)
    return d * px / pm, d * py / pm


@register_jitable
def body_wrench(b: np.ndarray) -> tuple[float, float, float]:
    """The physical wrench (surge N, heave N down > 0, yaw N m) the last step's fin targets
    make (forward forces ``thrust_gain`` times the model's, all of them the measured force
    scale times): the paper layer's, in the designed layer's terms."""
    g, cos_a, arm = b[B_ALLOC + A_GAIN], b[B_ALLOC + A_COS], b[B_ALLOC + A_ARM]
    x = z = n = 0.0
    for k in range(4):
        fx, fy = body_targets(b, k)
        if fx < 0.0:
            fx *= g
        x -= cos_a * fx
        z -= fy
        n += PAPER_SIDES[k] * arm * fx
    s = b[B_SCALE]
    return s * x, s * z, s * n


@register_jitable
def body_references(b: np.ndarray, sp_v: float, sp_z: float, sp_r: float) -> tuple[float, float, float, float]:
    """(speed, depth, heading, yaw rate) the layer holds the robot to now: the designed
    layer's references, the paper layer's setpoints (no heading: NaN); a reference not
    started yet is its setpoint."""
    if b[B_LAYER] == 0.0:
        return sp_v, sp_z, math.nan, sp_r
    v, z, r = b[B_V_REF], b[B_Z_REF], b[B_R_REF]
    return (sp_v if math.isnan(v) else v, sp_z if math.isnan(z) else z, b[B_HEADING_REF],
            sp_r if math.isnan(r) else r)


def _none(x: float) -> float | None:
    return None if math.isnan(x) else float(x)


@dataclass(frozen=True)
class BodyStep:
    """Output of one body-frame step.

    ``allocation`` holds the fins' targets; ``outputs`` the loops' outputs in the layer's
    terms (paper: F_x*, F_y*, the yaw differential; designed: the wrench asked);
    ``demand`` and ``applied`` the wrench (surge N, heave N down > 0, yaw N m) before and
    after the allocation, ``cut`` the axes it cut (the paper layer: the wrench its targets
    make, twice, nothing cut);
    ``velocity``, ``depth`` are the median-filtered measurements and ``yaw_rate`` the last
    gyro rate (None before the first sample); ``*_updated`` tell whether that loop ran on a
    new sample in this step (False: its output is held).
    """

    t: float
    allocation: Allocation
    outputs: tuple[float, float, float]
    demand: tuple[float, float, float]
    applied: tuple[float, float, float]
    cut: tuple[str, ...]
    velocity: float | None
    depth: float | None
    yaw_rate: float | None
    velocity_updated: bool
    depth_updated: bool
    yaw_updated: bool


@dataclass(frozen=True)
class AxisLimits:
    """The most the fins deliver on each axis (surge N forward, heave N, yaw N m)."""

    surge: float
    heave: float
    yaw: float


def axis_limits(cfg: BodyConfig, fmax: float) -> AxisLimits:
    """What the designed allocation can give each axis alone (independent fins), each fin
    at most ``fmax`` by the fin model."""
    rear = cfg.heave_rear_share
    h = max(0.5 * (1.0 - rear), 0.5 * rear)
    g = cfg.thrust_gain
    n_yaw = 4 if cfg.yaw_on_rear else 2
    return AxisLimits(
        surge=4.0 * math.cos(math.radians(MOUNTING_ANGLE_DEG)) * g * fmax,
        heave=fmax / h,
        yaw=n_yaw * ARM_YAW * 0.5 * (1.0 + g) * fmax,
    )


class BodyController:
    """The body-frame layer (module docstring): readings in, fin targets out.

    Feed readings with :meth:`on_dvl`, :meth:`on_depth`, :meth:`on_imu` (and the heading
    with :meth:`set_heading`) as they arrive and call :meth:`update` at the control rate.
    :meth:`on_cycle` (each fin's cycle as it begins, and when) schedules the designed loops
    on the fins' executed cycle periods (``BodyConfig.schedule``, ``control.body_design``).
    ``mpc`` and ``executor`` give the fin model and the drives' timing the designed layer's
    deliverable force comes from.
    """

    def __init__(self, cfg: BodyConfig, mpc: MpcConfig | None = None, executor: ExecutorConfig | None = None) -> None:
        self.cfg = cfg
        w = cfg.median_window
        self.state = np.zeros(body_size(w))
        b = self.state
        b[B_WINDOW] = w
        b[B_DEPTH_SIGN] = cfg.depth_sign
        b[B_LAYER] = LAYERS[cfg.layer]
        b[B_TRIM] = cfg.heave_trim
        hull = cfg.hull
        b[B_HULL:B_HULL + NH] = (hull.surge_damping, hull.surge_damping_quad, hull.heave_damping,
                                 hull.heave_damping_quad, hull.yaw_damping, hull.yaw_damping_quad,
                                 hull.surge_mass, hull.heave_mass, hull.yaw_inertia)
        b[B_LEAD] = cfg.max_heading_lead
        b[B_REF_RATE] = cfg.reference_rate
        b[B_MAX_DIVE], b[B_MAX_ACC], b[B_MAX_YAW_ACC] = cfg.max_dive_rate, cfg.max_acceleration, cfg.max_yaw_acceleration
        b[B_ACC_RISE] = cfg.acceleration_rise
        b[B_SPEED_TAU] = cfg.speed_filter
        b[B_SHORTFALL_TAU] = cfg.shortfall_filter if cfg.feed_shortfall else -1.0
        b[B_BIAS_WEIGHT] = 1.0 if cfg.feed_executed else 0.0
        b[B_SCALE] = b[B_SCALE_EST] = 1.0
        b[B_SCALE_FROM] = cfg.force_scale_from if cfg.layer == "designed" else 0.0
        b[B_SCALE_MAX] = cfg.force_scale_max
        b[B_HOLD] = cfg.direction_hold if cfg.layer == "designed" else 0.0
        self._executor = executor or ExecutorConfig()
        self.velocity_pid = Pid(cfg.velocity, b[B_PIDS:B_PIDS + NPID])
        self.depth_pid = Pid(cfg.depth, b[B_PIDS + NPID:B_PIDS + 2 * NPID])
        self.yaw_pid = Pid(cfg.yaw_rate, b[B_PIDS + 2 * NPID:B_PIDS + 3 * NPID])
        self.set_fin_model(mpc or MpcConfig())
        self.velocity_filter = MedianFilter(w, b, B_FILTERS)
        self.depth_filter = MedianFilter(w, b, B_FILTERS + median_size(w))
        self._scheduled = cfg.layer == "designed" and cfg.schedule
        self.reset()

    def set_scheduled(self, on: bool) -> None:
        """Whether the designed loops follow the fins' executed cycle periods now (the mode's
        planners' beat is the operator's choice: ``backend.loop.modes.Mode.schedules_body``),
        when ``BodyConfig.schedule`` allows it: on, from the longest delay as after a reset;
        off, the configured gains (the integrals kept)."""
        on = bool(on) and self.cfg.layer == "designed" and self.cfg.schedule
        if on == self._scheduled:
            return
        self._scheduled = on
        self._delay = math.nan
        if on:
            self._period = self.cfg.schedule_max_delay
            self._period_t = math.nan
            self._schedule(self._period)
        else:
            for pid in (self.velocity_pid, self.depth_pid, self.yaw_pid):
                pid.schedule((1.0, 1.0, 1.0))

    def set_fin_model(self, mpc: MpcConfig, planner_force: float | None = None) -> None:
        """The fin model the designed layer's limits come from (the MPC's configuration),
        and the largest force the fins' planners make, when less (a fixed beat frequency's
        peak, ``backend.loop.modes.Mode.fin_force``; None: the fin model's deliverable force)."""
        cfg = self.cfg
        ex = self._executor
        self.fin_force = deliverable_force(mpc, ex.acceleration, ex.max_rate)
        if cfg.max_fin_force > 0.0:
            self.fin_force = min(self.fin_force, cfg.max_fin_force)
        if planner_force is not None:
            if not (math.isfinite(planner_force) and planner_force > 0.0):
                raise ValueError(f"planner_force: expected a finite force > 0 N, got {planner_force!r}")
            self.fin_force = min(self.fin_force, planner_force)
        self.state[B_ALLOC:B_ALLOC + NA] = wrench_params(
            self.fin_force, cfg.thrust_gain, MOUNTING_ANGLE_DEG, ARM_YAW, cfg.heave_rear_share, cfg.yaw_on_rear)
        lim = axis_limits(cfg, self.fin_force)
        k = cfg.shortfall_limit
        self.state[B_SHORTFALL_CAP:B_SHORTFALL_CAP + 3] = (k * lim.surge, k * lim.heave, k * lim.yaw)
        if cfg.layer == "designed":
            for pid, cap in ((self.velocity_pid, lim.surge), (self.depth_pid, lim.heave), (self.yaw_pid, lim.yaw)):
                pid.cap = cap
                pid.set_gains(pid.gains)

    def pid(self, loop: str) -> Pid:
        """The PID of ``loop``: "velocity", "depth" or "yaw_rate"."""
        return {"velocity": self.velocity_pid, "depth": self.depth_pid, "yaw_rate": self.yaw_pid}[loop]

    def reset(self) -> None:
        """Forget every reading, output and held heading, and the fins' cycles: until the fins'
        cycles show shorter periods the scheduled loops run the gains of the longest delay (a
        loop designed for a longer delay stays stable with a shorter one)."""
        body_reset(self.state)
        # each paper fin's last cycle start (NaN: none yet); the executed period's estimate
        self._cycle_start = [math.nan] * 4
        self._period = self.cfg.schedule_max_delay
        self._period_t = math.nan
        self._delay = math.nan
        if self._scheduled:
            self._schedule(self._period)

    @property
    def delay(self) -> float:
        """The fins' delay the designed loops run the gains of (s): the executed cycle period,
        filtered and bounded (``BodyConfig.schedule``); the design delay unscheduled."""
        return self._delay if self._scheduled else DESIGN_DELAY

    def _schedule(self, delay: float) -> None:
        """The designed loops' gains for the fins' ``delay`` (s): the configured ones scaled by
        ``control.body_design.gain_schedule``; nothing changes while the delay stays the same."""
        if delay == self._delay:
            return
        self._delay = delay
        scale = gain_schedule(self.cfg.hull, delay, DESIGN_DELAY, DESIGN_FACTOR)
        for pid, loop in ((self.velocity_pid, "velocity"), (self.depth_pid, "depth"), (self.yaw_pid, "heading")):
            g = scale[loop]
            pid.schedule((g.kp, g.ki, g.kd))

    def _cycle_began(self, fin: int, t: float) -> None:
        """Paper fin ``fin`` began a cycle at ``t``: the time since its last one is an executed
        period, bounded. The scheduled delay follows it low-passed, a longer one quickly
        (``schedule_rise``), a shorter one slowly (``schedule_filter``): the loops stay
        scheduled for the longest of the fins' recent cycles, and their gains move smoothly."""
        cfg = self.cfg
        last, self._cycle_start[fin] = self._cycle_start[fin], t
        if not t > last:  # the first cycle, or not after the last
            return
        sample = min(cfg.schedule_max_delay, max(cfg.schedule_min_delay, t - last))
        tau = cfg.schedule_rise if sample > self._period else cfg.schedule_filter
        dt = t - last if math.isnan(self._period_t) else max(0.0, t - self._period_t)
        self._period += (1.0 if tau == 0.0 else 1.0 - math.exp(-dt / tau)) * (sample - self._period)
        if abs(self._period - sample) < PERIOD_SNAP:  # arrived (an exponential never quite does)
            self._period = sample
        self._period_t = t
        self._schedule(self._period)

    @property
    def dvl_missing(self) -> int:
        return int(self.state[B_DVL_MISSING])

    @property
    def last_dvl_t(self) -> float | None:
        return _none(self.state[B_LAST_DVL_T])

    @property
    def last_depth_t(self) -> float | None:
        return _none(self.state[B_LAST_DEPTH_T])

    @property
    def last_imu_t(self) -> float | None:
        return _none(self.state[B_LAST_IMU_T])

    @property
    def heading_ref(self) -> float | None:
        """The heading the designed layer holds or turns to (rad; None before it has one)."""
        return _none(self.state[B_HEADING_REF])

    @property
    def sensors_reported(self) -> bool:
        """A depth and a DVL report (with or without bottom lock) have arrived since the
        reset: the loops have seen what the robot can measure, and a speed still missing is
        the DVL's reported fault, not the start-up's."""
        return bool(body_sensors_reported(self.state))

    def _check(self, status: int, value: float, t: float) -> None:
        if status != BODY_OK:
            name = BODY_FIELDS[status]
            finite(name, t if name.endswith(".t") or name == "t" else value)

    def on_dvl(self, reading: DvlVelocity) -> None:
        self._check(body_on_dvl(self.state, bool(reading.valid), reading.vx, reading.t), reading.vx, reading.t)

    def on_depth(self, reading: DepthReading) -> None:
        self._check(body_on_depth(self.state, reading.depth_m, reading.t), reading.depth_m, reading.t)

    def on_imu(self, reading: ImuReading) -> None:
        r = reading.gyro[2]
        self._check(body_on_imu(self.state, r, reading.t), r, reading.t)
        if reading.quaternion is not None:
            self.set_heading(reading.quaternion)

    def on_cycle(self, fin: int, target: tuple[float, float], force: tuple[float, float], t: float) -> None:
        """Paper fin ``fin`` begins a cycle at ``t`` (s) asked for ``target`` whose plan makes
        ``force`` by the fin model (N): the designed layer feeds the difference forward, and
        schedules its loops on the fins' executed cycle period."""
        body_on_cycle(self.state, fin, finite("target[0]", target[0]), finite("target[1]", target[1]),
                      finite("force[0]", force[0]), finite("force[1]", force[1]))
        t = finite("t", t)
        if self._scheduled:
            self._cycle_began(fin, t)

    def on_executed(self, fin: int, planned: tuple[float, float], executed: tuple[float, float]) -> None:
        """Paper fin ``fin`` finished a cycle whose plan made ``planned`` and whose executed
        strokes made ``executed`` by the fin model (N)."""
        body_on_executed(self.state, fin, finite("planned[0]", planned[0]), finite("planned[1]", planned[1]),
                         finite("executed[0]", executed[0]), finite("executed[1]", executed[1]))

    @property
    def force_scale(self) -> tuple[float, float]:
        """(the fins' force per unit of the fin model's that the designed layer asks them for
        less by, the measured one): (1, 1) until measured."""
        b = self.state
        return float(b[B_SCALE]), float(b[B_SCALE_EST])

    @property
    def shortfall(self) -> tuple[float, float, float]:
        """The fins' shortfall the designed layer feeds forward (surge N, heave N, yaw N m)."""
        b = self.state
        return float(b[B_SHORTFALL]), float(b[B_SHORTFALL + 1]), float(b[B_SHORTFALL + 2])

    def set_heading(self, q: tuple[float, float, float, float]) -> None:
        """The attitude estimate (w, x, y, z; body -> NED): the heading the loop holds to."""
        body_set_heading(self.state, float(q[0]), float(q[1]), float(q[2]), float(q[3]))

    def update(self, t: float, setpoints: BodySetpoints, *, sync: bool = False) -> BodyStep:
        """One control step at time ``t`` (s): run the loops that have new data, allocate."""
        t = finite("t", t)
        b = self.state
        new_v, new_z, new_r = bool(b[B_NEW_V]), bool(b[B_NEW_Z]), bool(b[B_NEW_R])
        status, v, z = body_update(b, t, setpoints.velocity, setpoints.depth, setpoints.yaw_rate, sync)
        if status == EARLIER_T:
            raise ValueError(f"t: {t!r} is earlier than the last update of a body-frame loop")
        if b[B_LAYER] == 0.0:
            fx, fy, m = float(b[B_FX]), float(b[B_FY]), float(b[B_YAW])
            allocation = allocate(fx, fy, m, sync=sync)
            outputs = (fx, fy, m)
            demand = applied = tuple(float(x) for x in body_wrench(b))  # type: ignore[assignment]
            cut: tuple[str, ...] = ()
        else:
            per_fin = tuple(body_targets(b, k) for k in range(4))
            allocation = _logical(tuple((float(x), float(y)) for x, y in per_fin), sync)
            outputs = (float(b[B_X]), float(b[B_Z]), float(b[B_N]))
            demand = (float(b[B_ASKED]), float(b[B_ASKED + 1]), float(b[B_ASKED + 2]))
            applied = (float(b[B_APPLIED]), float(b[B_APPLIED + 1]), float(b[B_APPLIED + 2]))
            cut = cut_names(int(b[B_CUT]))
        return BodyStep(
            t=t, allocation=allocation, outputs=outputs, demand=demand, applied=applied, cut=cut,
            velocity=_none(v), depth=_none(z), yaw_rate=_none(b[B_YAW_RATE]),
            velocity_updated=new_v, depth_updated=new_z, yaw_updated=new_r,
        )
