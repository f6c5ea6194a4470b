# Over 600 lines: the loop's per-sample step is one compiled, allocation-free function over the rows declared here.
"""The closed loop's per-sample core, compiled: readings in, body control, stroke ends out.

The closed loop (``backend/loop/closed_loop.py``) runs on the robot's readings: 100 IMU and
encoder samples a second, depth and DVL reports, body-frame control at 50 Hz, telemetry
ticks. Everything it does per sample is here, as one compiled, allocation-free step
function over arrays, :func:`core_step`: it schedules the loop's events (the robot's
readings, the control, state, power and status ticks, plan hand-overs) in simulated time,
and for each event

1. takes the robot's readings as rows (``robot.reading_rows``): the IMU's yaw rate and
   attitude, the depth and the DVL into the body-frame layer (``allocation.body_*``), the
   DVL into dead reckoning (``estimation.dead_reckon_into``), the encoders into the power
   estimate (``power``) and the executors' stroke-end table (``stroke_watch``);
2. runs the body-frame PIDs and the allocation at the control ticks;
3. keeps what the telemetry shows (sensor readings, body command, state, power) as rows in
   an outbox the loop publishes from.

It returns to the loop (Python) only where Python has something to do: a stroke ended (the
executor sends the next stroke, or asks for a plan), a plan is due to be handed over, the
robot must deliver readings (a robot that runs this core itself, the simulator, does that
in compiled code too: ``SimRobotIO.run_core``), a status tick, the outbox is full, and the
rarer cases below (``NEED_*``). The loop then calls it again and it goes on where it
stopped. So the order of everything within an event is the loop's (plan hand-overs,
readings in order, hand-over checks, control, state, power and status ticks), and a run
gives the same trajectory however often the core returns.

All numbers live in arrays the loop owns (:class:`LoopCore`): ``s`` (its declared layout
:data:`STATE`, whose columns are the constants ``C_*``: the estimate, the schedule, the loop's inputs), the body-frame layer's array
(``allocation.B_*``), the stroke-end table and the power table (one row per fin), the
readings of the event and the outbox. Time is an argument, like everywhere in the core:
the loop says how far it may run (``C_T_END``, and ``C_HORIZON`` when paced by a clock).
Over 500 lines because the step is one compiled state machine over one array: its declared
layouts, its phases and the steps between them are one piece.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ucat_console.control.body import (
    B_APPLIED,
    B_ASKED,
    B_CUT,
    B_HEADING,
    B_LAYER,
    BODY_OK,
    body_allocate,
    body_on_depth,
    body_on_dvl,
    body_on_imu,
    body_references,
    body_set_heading,
    body_targets,
    body_update,
    body_wrench,
)
from ucat_console.control.estimation import MAX_DEAD_RECKONING_GAP, dead_reckon_into
from ucat_console.control.power import (
    NOT_AFTER,
    P_DURATION,
    P_ENERGY,
    P_LAST_FIN,
    power_update,
    power_update_all,
)
from ucat_console.control.stroke_watch import BACKWARDS, feedback_kernel
from ucat_console.robot import reading_rows as rr
from ucat_console.robot.fins import N_FINS, PAPER_SIDES, ROBOT_TO_PAPER
from ucat_console.robot.layout import Layout

#: events closer than this (s) are simultaneous
EPS = 1e-7

# --- the scalar array ``s``: its declared layout, and its columns as constants ----------
STATE = Layout("the loop core's scalar array s", [
    # the estimate (what the readings say of the robot)
    ("t", 1, "simulated time of the last event processed"),
    ("q", 4, "attitude (w, x, y, z)"),
    ("gyro", 3, "the last gyro rates"),
    ("dvl_v", 3, "the last valid DVL velocity"),
    ("dvl_t", 1, "its time (NaN: none yet)"),
    ("xy", 2, "dead-reckoned north, east"),
    ("depth", 1, "the filtered depth at the last control tick"),
    ("distance", 1, "m travelled while driving"),
    ("v_body", 1, "the filtered forward speed at the last control tick"),
    ("fb_angle", N_FINS, "each fin's last encoder angle (robot order; NaN: none yet)"),
    ("fb_rate", N_FINS, "and rate"),
    ("cmd_angle", N_FINS, "each fin's last set-point angle: the loop writes them"),
    ("cmd_rate", N_FINS, "and profile velocity"),
    ("targets", 8, "the allocation's (f_x, f_y) per logical fin, the mode's order"),
    # the schedule
    ("n_control", 1, "control ticks done (the next one is at count * period)"),
    ("n_state", 1, "state ticks done"),
    ("n_power", 1, "power ticks done"),
    ("n_status", 1, "status ticks done"),
    ("p_control", 1, "control period, s"),
    ("p_state", 1, "state period, s"),
    ("p_power", 1, "power period, s"),
    ("p_status", 1, "status period, s"),
    ("phase", 1, "where the step goes on (PH_*)"),
    ("cursor", 1, "the reading being taken"),
    ("fin_k", 1, "the next fin of an encoder reading to feed (-1: the reading is not begun)"),
    ("nrows", 1, "readings of the event (the robot's, in rows)"),
    ("t_next", 1, "the next event's time (when waiting for it or for its readings)"),
    ("due", 1, "the ticks due at this event (DUE_* bits)"),
    ("rows_pending", 1, "1: the step waits for the robot's readings of t_next"),
    ("t_now", 1, "the time a stroke end was seen at (with stroke_row)"),
    ("stroke_row", 1, "the paper fin whose executor saw a stroke end"),
    ("err", 1, "for which fin or field it went wrong"),
    ("err_code", 1, "what went wrong (ERR_*)"),
    ("out_n", 1, "rows in the outbox"),
    # the loop's inputs (written before each call)
    ("t_end", 1, "run to here"),
    ("horizon", 1, "and no event later than this now (paced clock; inf headless)"),
    ("t_deliver", 1, "the earliest plan hand-over"),
    ("t_robot", 1, "when the robot's next reading is due"),
    ("flags", 1, "F_* bits"),
    ("sp_v", 1, "velocity setpoint in force"),
    ("sp_z", 1, "depth setpoint in force"),
    ("sp_r", 1, "yaw rate setpoint in force"),
    # parameters
    ("w_th", 1, "the executors' rate threshold"),
    ("min_time", 1, "and shortest stroke"),
    ("k_drag", 1, "the power estimate's drag coefficient"),
    ("inertia", 1, "fin inertia"),
    ("tau", 1, "and filter time constant"),
])
C_T, C_Q, C_GYRO, C_DVL_V, C_DVL_T, C_XY, C_DEPTH, C_DISTANCE, C_V_BODY = (
    STATE.at(f) for f in ("t", "q", "gyro", "dvl_v", "dvl_t", "xy", "depth", "distance", "v_body"))
C_FB_ANGLE, C_FB_RATE, C_CMD_ANGLE, C_CMD_RATE, C_TARGETS = (
    STATE.at(f) for f in ("fb_angle", "fb_rate", "cmd_angle", "cmd_rate", "targets"))
C_N_CONTROL, C_N_STATE, C_N_POWER, C_N_STATUS, C_P_CONTROL, C_P_STATE, C_P_POWER, C_P_STATUS = (
    STATE.at(f) for f in ("n_control", "n_state", "n_power", "n_status", "p_control", "p_state", "p_power",
                          "p_status"))
C_PHASE, C_CURSOR, C_FIN_K, C_NROWS, C_T_NEXT, C_DUE, C_ROWS_PENDING, C_T_NOW, C_STROKE_ROW = (
    STATE.at(f) for f in ("phase", "cursor", "fin_k", "nrows", "t_next", "due", "rows_pending", "t_now",
                          "stroke_row"))
C_ERR, C_ERR_CODE, C_OUT_N, C_T_END, C_HORIZON, C_T_DELIVER, C_T_ROBOT, C_FLAGS = (
    STATE.at(f) for f in ("err", "err_code", "out_n", "t_end", "horizon", "t_deliver", "t_robot", "flags"))
C_SP_V, C_SP_Z, C_SP_R, C_W_TH, C_MIN_TIME, C_K_DRAG, C_INERTIA, C_TAU = (
    STATE.at(f) for f in ("sp_v", "sp_z", "sp_r", "w_th", "min_time", "k_drag", "inertia", "tau"))
NC = STATE.size

# flags (C_FLAGS): what the loop wants to be called for, and the mode
F_HANDOVER = 1  # a mode hand-over waits for fins to go idle: check after the readings
F_REQUESTS = 2  # a logical fin has no plan requested yet: call at the control ticks
F_BODY_COMMAND = 4  # the telemetry takes the body command, the state, the power, readings
F_STATE = 8
F_POWER = 16
F_IMU = 32
F_DEPTH = 64
F_DVL = 128
F_EKF = 256  # the attitude comes from the loop's EKF (Python), not the IMU
F_DRIVING = 512  # the fins are driven (armed): distance and energy count
F_SYNC = 1024  # the rear pair is one logical fin
F_COMMANDS = 2048  # commands wait: return at the next event's start
F_STOP = 4096  # stop at the next event's start

# ticks (C_DUE)
DUE_CONTROL, DUE_STATE, DUE_POWER, DUE_STATUS, DUE_DELIVER = 1, 2, 4, 8, 16

# phases: how far the event is (the step goes on with what comes next)
PH_IDLE = 0.0  # between events
PH_SAMPLED = 1.0  # the readings of C_T_NEXT are asked for (or in): plan hand-overs next
PH_READINGS = 2.0  # the readings are being taken
PH_HANDOVER = 3.0  # the readings are taken and the hand-over checked: the control tick next
PH_CONTROL = 4.0  # the control tick is done: the state tick next
PH_STATE = 5.0  # the state tick is done: the power tick next
PH_POWER = 6.0  # the power tick is done: the status tick next
PH_FINAL_WAIT = 8.0  # the readings up to C_T_END are asked for
PH_FINAL = 9.0  # they are in: take them, then the run is over

# what a step returns
END = 0  # the run reached C_T_END (or was stopped)
WAIT = 1  # the next event (C_T_NEXT) is beyond C_HORIZON
READINGS = 2  # the robot must reach C_T_NEXT and deliver its readings as rows
DELIVER = 3  # plans are due to be handed over at C_T
STROKE = 4  # the executor of paper fin C_STROKE_ROW saw a stroke end at C_T_NOW (``found``)
EKF = 5  # the IMU reading at C_CURSOR needs the loop's attitude EKF
HANDOVER = 6  # check the mode hand-over
CONTROL = 7  # a control tick ran: plan requests
STATUS = 8  # a status tick
OUTBOX = 9  # the outbox is full: publish it
COMMANDS = 10  # take the commands waiting, at the start of an event
ERROR = 11  # C_ERR_CODE says what (ERR_*), C_ERR for which fin or field
NEED_NOISE = 12  # (a robot running the core: new noise blocks)
DIVERGED = 13  # (a robot running the core: its physics diverged)

# errors
ERR_BODY = 1  # a reading the body-frame layer refused (C_ERR: allocation.BODY_* code)
ERR_POWER = 2  # an encoder sample not after its fin's last (C_ERR: robot fin)
ERR_BACKWARDS = 3  # an encoder sample older than its fin's last (C_ERR: robot fin)
ERR_KIND = 4  # a reading of no known kind

# --- the outbox: telemetry rows, each kind with its declared layout --------------------
# every row begins with its kind and its time; the readings' rows are robot.reading_rows'
O_KIND = 0
O_T = 1
OUT_ROWS = 64
# kinds besides the readings' (rr.IMU ... rr.FIN)
O_BODY_COMMAND = 10.0
O_STATE = 11.0
O_POWER = 12.0
_HEAD = [("kind", 1, "the row's kind (O_* or a reading's)"), ("t", 1, "time, s")]
BODY_COMMAND_ROW = Layout("the outbox's body-command row", _HEAD + [
    ("force_x", 1, "sum of the fins' f_x targets, N"),
    ("force_y", 1, "sum of the fins' f_y targets, N"),
    ("yaw_force", 1, "sum of s_lat f_x over the fins, N"),
    ("asked", 3, "the wrench asked (X, Z, N)"),
    ("applied", 3, "the wrench the allocation applied (X, Z, N)"),
    ("cut", 1, "the allocation's cut bits"),
    ("driving", 1, "1: the fins are driven"),
    ("references", 4, "speed, depth, heading and yaw rate references"),
    ("errors", 3, "speed, depth and heading errors"),
])
STATE_ROW = Layout("the outbox's state row", _HEAD + [
    ("position", 3, "dead-reckoned north, east and the depth, m"),
    ("orientation", 4, "attitude (w, x, y, z)"),
    ("velocity", 3, "body velocity, m/s"),
    ("rates", 3, "body rates, rad/s"),
    ("depth", 1, "depth, m"),
    ("fin_angle", N_FINS, "each fin's angle (robot order; NaN: none yet), rad"),
    ("fin_rate", N_FINS, "and rate, rad/s"),
    ("fin_set_angle", N_FINS, "each fin's set-point angle, rad"),
    ("fin_set_rate", N_FINS, "and profile velocity, rad/s"),
])
POWER_ROW = Layout("the outbox's power row", _HEAD + [
    ("power", N_FINS, "each fin's power, W"),
    ("energy", N_FINS, "each fin's energy while driving, J"),
    ("mean", N_FINS, "each fin's mean power (NaN: none yet), W"),
    ("distance", 1, "m travelled while driving"),
])
#: columns of an outbox row: the widest kind's
OUT_ROW = 40
assert max(BODY_COMMAND_ROW.size, STATE_ROW.size, POWER_ROW.size, rr.ROW) <= OUT_ROW
_BC_FX, _BC_FY, _BC_YAW, _BC_ASKED, _BC_APPLIED, _BC_CUT, _BC_DRIVING, _BC_REFS, _BC_ERRORS = (
    BODY_COMMAND_ROW.at(f) for f in BODY_COMMAND_ROW.fields[2:])
_S_POS, _S_Q, _S_V, _S_RATES, _S_DEPTH, _S_ANGLE, _S_RATE, _S_SET_ANGLE, _S_SET_RATE = (
    STATE_ROW.at(f) for f in STATE_ROW.fields[2:])
_P_POWER, _P_ENERGY, _P_MEAN, _P_DISTANCE = (POWER_ROW.at(f) for f in POWER_ROW.fields[2:])
#: rows of readings one event can hand the core at a time
ROWS = 16


@njit(cache=True)
def _room(s: np.ndarray, out: np.ndarray) -> bool:
    return s[C_OUT_N] < out.shape[0]


@njit(cache=True)
def _next_out(s: np.ndarray, out: np.ndarray) -> np.ndarray:
    """The next outbox row (the caller has checked that there is room)."""
    n = int(s[C_OUT_N])
    s[C_OUT_N] = n + 1
    return out[n]


@njit(cache=True)
def _error(s: np.ndarray, code: int, what: float) -> int:
    s[C_ERR_CODE] = code
    s[C_ERR] = what
    return ERROR


@njit(cache=True)
def _wanted(kind: float, flags: int) -> bool:
    """Whether the telemetry takes readings of ``kind``."""
    if kind == rr.IMU:
        return (flags & F_IMU) != 0
    if kind == rr.DEPTH:
        return (flags & F_DEPTH) != 0
    if kind == rr.DVL:
        return (flags & F_DVL) != 0
    return False


@njit(cache=True)
def _take_readings(s, body, watch, members, found, power, rows, out, t, fin_rows, r3) -> int:
    """The event's readings from ``C_CURSOR`` on, in order; -1 when all are taken, else
    what the step returns (it goes on at the same place when called again)."""
    flags = int(s[C_FLAGS])
    driving = (flags & F_DRIVING) != 0
    n = int(s[C_NROWS])
    while int(s[C_CURSOR]) < n:
        c = int(s[C_CURSOR])
        row = rows[c]
        kind = row[rr.KIND]
        t_r = row[rr.T]
        k = int(s[C_FIN_K])  # -1: not begun; the encoders' next fin; -2: the IMU's attitude is in
        if kind == rr.FINS or kind == rr.FIN:
            if kind == rr.FINS:
                angles = row[rr.FINS_ANGLE:rr.FINS_ANGLE + N_FINS]
                rates = row[rr.FINS_RATE:rr.FINS_RATE + N_FINS]
                fins = fin_rows[:N_FINS]
                if k < 0:
                    for i in range(N_FINS):
                        s[C_FB_ANGLE + i] = angles[i]
                        s[C_FB_RATE + i] = rates[i]
                    bad = power_update_all(power, t_r, angles, driving, s[C_K_DRAG], s[C_INERTIA], s[C_TAU])
                    if bad >= 0:
                        return _error(s, ERR_POWER, bad)
                    k = 0
            else:
                pf = int(row[rr.FIN_INDEX])
                angles = row[rr.FIN_ANGLE:rr.FIN_ANGLE + 1]
                rates = row[rr.FIN_RATE:rr.FIN_RATE + 1]
                fins = fin_rows[N_FINS:]
                fins[0] = ROBOT_TO_PAPER[pf]
                if k < 0:
                    s[C_FB_ANGLE + pf] = angles[0]
                    s[C_FB_RATE + pf] = rates[0]
                    if power_update(power, pf, t_r, angles[0], driving, s[C_K_DRAG], s[C_INERTIA],
                                    s[C_TAU]) == NOT_AFTER:
                        return _error(s, ERR_POWER, pf)
                    k = 0
            t_now = t if t >= t_r else t_r
            k = feedback_kernel(watch, members, fins, t_r, rates, angles, t_now, k, s[C_W_TH], s[C_MIN_TIME],
                                found)
            if k < 0:
                paper = fins[BACKWARDS - k]
                for pf in range(N_FINS):
                    if ROBOT_TO_PAPER[pf] == paper:
                        return _error(s, ERR_BACKWARDS, pf)
            if k < fins.shape[0]:  # an executor saw a stroke end: it acts before the next fin
                s[C_FIN_K] = k + 1
                s[C_T_NOW] = t_now
                s[C_STROKE_ROW] = fins[k]
                return STROKE
        else:
            keep = _wanted(kind, flags)
            if keep and not _room(s, out):
                return OUTBOX
            if kind == rr.IMU:
                if k != -2:
                    e = body_on_imu(body, row[rr.IMU_GYRO + 2], t_r)
                    if e != BODY_OK:
                        return _error(s, ERR_BODY, e)
                    for i in range(3):
                        s[C_GYRO + i] = row[rr.IMU_GYRO + i]
                    if (flags & F_EKF) != 0 or math.isnan(row[rr.IMU_Q]):
                        s[C_FIN_K] = -2.0
                        return EKF  # the loop sets C_Q, then calls again
                    for i in range(4):
                        s[C_Q + i] = row[rr.IMU_Q + i]
            elif kind == rr.DEPTH:
                e = body_on_depth(body, row[rr.DEPTH_M], t_r)
                if e != BODY_OK:
                    return _error(s, ERR_BODY, e)
            elif kind == rr.DVL:
                valid = row[rr.DVL_VALID] != 0.0
                e = body_on_dvl(body, valid, row[rr.DVL_V], t_r)
                if e != BODY_OK:
                    return _error(s, ERR_BODY, e)
                if valid:
                    vx, vy, vz = row[rr.DVL_V], row[rr.DVL_V + 1], row[rr.DVL_V + 2]
                    if not math.isnan(s[C_DVL_T]):
                        dt = min(max(t_r - s[C_DVL_T], 0.0), MAX_DEAD_RECKONING_GAP)
                        dead_reckon_into(s[C_XY:C_XY + 2], s[C_Q:C_Q + 4], row[rr.DVL_V:rr.DVL_V + 3], dt, r3)
                        if driving:
                            s[C_DISTANCE] += dt * math.hypot(vx, vy)
                    s[C_DVL_T] = t_r
                    s[C_DVL_V] = vx
                    s[C_DVL_V + 1] = vy
                    s[C_DVL_V + 2] = vz
            else:
                return _error(s, ERR_KIND, kind)
            if keep:
                o = _next_out(s, out)
                for j in range(rr.ROW):
                    o[j] = row[j]
        s[C_FIN_K] = -1.0
        s[C_CURSOR] = c + 1
    return -1


@njit(cache=True)
def set_targets(s: np.ndarray, body: np.ndarray, sync: bool) -> None:
    """The body layer's last allocation into the targets of the mode's logical fins."""
    for k in range(4):
        fx, fy = body_targets(body, k)
        s[C_TARGETS + 2 * k], s[C_TARGETS + 2 * k + 1] = fx, fy
    if sync:
        s[C_TARGETS + 6] = math.nan
        s[C_TARGETS + 7] = math.nan


@njit(cache=True)
def retarget(s: np.ndarray, body: np.ndarray, sync: bool) -> None:
    """A mode switch (sync or not): the body layer's demand allocated again for the new
    mode's fins, into their targets."""
    if body[B_LAYER] != 0.0:
        body_allocate(body, s[C_SP_V], sync)
    set_targets(s, body, sync)


@njit(cache=True)
def _control(s: np.ndarray, body: np.ndarray, t: float) -> int:
    """The control tick: the body-frame loops and the allocation (the mode's targets); -1
    when all is well."""
    body_set_heading(body, s[C_Q], s[C_Q + 1], s[C_Q + 2], s[C_Q + 3])
    sync = (int(s[C_FLAGS]) & F_SYNC) != 0
    status, v, z = body_update(body, t, s[C_SP_V], s[C_SP_Z], s[C_SP_R], sync)
    if status != BODY_OK:
        return _error(s, ERR_BODY, status)
    if not math.isnan(v):
        s[C_V_BODY] = v
    if not math.isnan(z):
        s[C_DEPTH] = z
    set_targets(s, body, sync)
    return -1


@njit(cache=True)
def _keep_body_command(s: np.ndarray, body: np.ndarray, out: np.ndarray, t: float) -> None:
    o = _next_out(s, out)
    o[O_KIND] = O_BODY_COMMAND
    o[O_T] = t
    fx_sum = fy_sum = yaw = 0.0
    for k in range(4):
        fx, fy = body_targets(body, k)
        fx_sum += fx
        fy_sum += fy
        yaw += PAPER_SIDES[k] * fx
    o[_BC_FX], o[_BC_FY], o[_BC_YAW] = fx_sum, fy_sum, yaw
    if body[B_LAYER] == 0.0:
        x, z, n = body_wrench(body)
        o[_BC_ASKED], o[_BC_ASKED + 1], o[_BC_ASKED + 2] = x, z, n
        o[_BC_APPLIED], o[_BC_APPLIED + 1], o[_BC_APPLIED + 2] = x, z, n
        o[_BC_CUT] = 0.0
    else:
        o[_BC_ASKED], o[_BC_ASKED + 1], o[_BC_ASKED + 2] = body[B_ASKED], body[B_ASKED + 1], body[B_ASKED + 2]
        for k in range(3):
            o[_BC_APPLIED + k] = body[B_APPLIED + k]
        o[_BC_CUT] = body[B_CUT]
    o[_BC_DRIVING] = 1.0 if (int(s[C_FLAGS]) & F_DRIVING) != 0 else 0.0
    v_ref, z_ref, psi_ref, r_ref = body_references(body, s[C_SP_V], s[C_SP_Z], s[C_SP_R])
    o[_BC_REFS], o[_BC_REFS + 1], o[_BC_REFS + 2], o[_BC_REFS + 3] = v_ref, z_ref, psi_ref, r_ref
    o[_BC_ERRORS] = s[C_V_BODY] - v_ref
    o[_BC_ERRORS + 1] = s[C_DEPTH] - z_ref
    psi = body[B_HEADING]
    o[_BC_ERRORS + 2] = (psi - psi_ref + math.pi) % (2.0 * math.pi) - math.pi


@njit(cache=True)
def _keep_state(s: np.ndarray, out: np.ndarray, t: float) -> None:
    o = _next_out(s, out)
    o[O_KIND] = O_STATE
    o[O_T] = t
    o[_S_POS] = s[C_XY]
    o[_S_POS + 1] = s[C_XY + 1]
    o[_S_POS + 2] = s[C_DEPTH]
    for i in range(4):
        o[_S_Q + i] = s[C_Q + i]
    for i in range(3):
        o[_S_V + i] = s[C_DVL_V + i]
        o[_S_RATES + i] = s[C_GYRO + i]
    o[_S_DEPTH] = s[C_DEPTH]
    for i in range(N_FINS):
        o[_S_ANGLE + i] = s[C_FB_ANGLE + i]
        o[_S_RATE + i] = s[C_FB_RATE + i]
        o[_S_SET_ANGLE + i] = s[C_CMD_ANGLE + i]
        o[_S_SET_RATE + i] = s[C_CMD_RATE + i]


@njit(cache=True)
def _keep_power(s: np.ndarray, power: np.ndarray, out: np.ndarray, t: float) -> None:
    o = _next_out(s, out)
    o[O_KIND] = O_POWER
    o[O_T] = t
    for i in range(N_FINS):
        o[_P_POWER + i] = power[i, P_LAST_FIN]
        o[_P_ENERGY + i] = power[i, P_ENERGY]
        d = power[i, P_DURATION]
        o[_P_MEAN + i] = power[i, P_ENERGY] / d if d > 0.0 else math.nan
    o[_P_DISTANCE] = s[C_DISTANCE]


@njit(cache=True)
def core_step(s: np.ndarray, body: np.ndarray, watch: np.ndarray, members: np.ndarray, found: np.ndarray,
              power: np.ndarray, rows: np.ndarray, out: np.ndarray, fin_rows: np.ndarray, r3: np.ndarray) -> int:
    """Run the loop's events from where the last step stopped until the loop (or the robot)
    has something to do; what that is (END, WAIT, READINGS, ...: module docstring).
    ``fin_rows`` (int64) holds the paper fin of each robot fin, and room for one more;
    ``r3`` (3 x 3) is scratch."""
    while True:
        phase = s[C_PHASE]
        flags = int(s[C_FLAGS])
        if phase == PH_IDLE:
            if (flags & F_STOP) != 0:
                return END
            if (flags & F_COMMANDS) != 0:
                return COMMANDS
            t_control = s[C_N_CONTROL] * s[C_P_CONTROL]
            t_state = s[C_N_STATE] * s[C_P_STATE]
            t_power = s[C_N_POWER] * s[C_P_POWER]
            t_status = s[C_N_STATUS] * s[C_P_STATUS]
            t_next = min(s[C_T_ROBOT], t_control, t_state, t_power, t_status)
            if s[C_T_DELIVER] < t_next:
                t_next = s[C_T_DELIVER]
            t_end = s[C_T_END]
            if t_next > t_end + EPS:
                if t_end > s[C_T]:  # the robot reaches t_end; nothing is due before then
                    s[C_T_NEXT] = t_end
                    s[C_PHASE] = PH_FINAL_WAIT
                    s[C_ROWS_PENDING] = 1.0
                    return READINGS
                return END
            if t_next > s[C_HORIZON]:
                s[C_T_NEXT] = t_next
                return WAIT
            s[C_T_NEXT] = t_next
            t = t_next if t_next > s[C_T] else s[C_T]
            lim = t + EPS
            due = 0
            if t_control <= lim:
                due |= DUE_CONTROL
            if t_state <= lim:
                due |= DUE_STATE
            if t_power <= lim:
                due |= DUE_POWER
            if t_status <= lim:
                due |= DUE_STATUS
            s[C_DUE] = due
            s[C_PHASE] = PH_SAMPLED
            s[C_ROWS_PENDING] = 1.0
            return READINGS
        if phase == PH_SAMPLED or phase == PH_FINAL_WAIT:
            t_next = s[C_T_NEXT]
            s[C_CURSOR] = 0.0
            s[C_FIN_K] = -1.0
            if phase == PH_FINAL_WAIT:
                s[C_T] = t_next
                s[C_PHASE] = PH_FINAL
                continue
            s[C_T] = t_next if t_next > s[C_T] else s[C_T]
            s[C_PHASE] = PH_READINGS
            if s[C_T_DELIVER] <= s[C_T] + EPS:
                return DELIVER
            continue
        t = s[C_T]
        if phase == PH_READINGS or phase == PH_FINAL:
            r = _take_readings(s, body, watch, members, found, power, rows, out, t, fin_rows, r3)
            if r >= 0:
                return r
            if phase == PH_FINAL:
                s[C_PHASE] = PH_IDLE
                return END
            s[C_PHASE] = PH_HANDOVER
            if (flags & F_HANDOVER) != 0:
                return HANDOVER
            continue
        due = int(s[C_DUE])
        if phase == PH_HANDOVER:  # the hand-over is checked: the control tick
            if (due & DUE_CONTROL) != 0:
                keep = (flags & F_BODY_COMMAND) != 0
                if keep and not _room(s, out):
                    return OUTBOX
                s[C_N_CONTROL] += 1.0
                r = _control(s, body, t)
                s[C_PHASE] = PH_CONTROL
                if r >= 0:
                    return r
                if keep:
                    _keep_body_command(s, body, out, t)
                if (flags & F_REQUESTS) != 0:
                    return CONTROL
            s[C_PHASE] = PH_CONTROL
            continue
        if phase == PH_CONTROL:  # the state tick
            if (due & DUE_STATE) != 0:
                if (flags & F_STATE) != 0:
                    if not _room(s, out):
                        return OUTBOX
                    _keep_state(s, out, t)
                s[C_N_STATE] += 1.0
            s[C_PHASE] = PH_STATE
            continue
        if phase == PH_STATE:  # the power tick
            if (due & DUE_POWER) != 0:
                if (flags & F_POWER) != 0:
                    if not _room(s, out):
                        return OUTBOX
                    _keep_power(s, power, out, t)
                s[C_N_POWER] += 1.0
            s[C_PHASE] = PH_POWER
            continue
        if phase == PH_POWER:  # the status tick
            s[C_PHASE] = PH_IDLE
            if (due & DUE_STATUS) != 0:
                s[C_N_STATUS] += 1.0
                return STATUS
            continue
        return _error(s, ERR_KIND, phase)


class LoopCore:
    """The arrays of one closed loop's core (:func:`core_step`), and its one step."""

    def __init__(self, body: np.ndarray, watch: np.ndarray, members: np.ndarray, found: np.ndarray,
                 power: np.ndarray, *, rates: tuple[float, float, float, float], w_th: float, min_time: float,
                 k_drag: float, inertia: float, tau: float) -> None:
        self.s = np.zeros(NC)
        self.body, self.watch, self.members, self.found, self.power = body, watch, members, found, power
        self.rows = np.zeros((ROWS, rr.ROW))
        self.out = np.zeros((OUT_ROWS, OUT_ROW))
        self.fin_rows = np.array([ROBOT_TO_PAPER[pf] for pf in range(N_FINS)] + [0], dtype=np.int64)
        self.r3 = np.zeros((3, 3))
        s = self.s
        s[C_Q] = 1.0
        s[C_DVL_T] = math.nan
        s[C_FB_ANGLE:C_FB_ANGLE + N_FINS] = math.nan
        for i, rate in enumerate(rates):
            s[C_P_CONTROL + i] = 1.0 / rate
        s[C_FIN_K] = -1.0
        s[C_T_END] = 0.0
        s[C_HORIZON] = math.inf
        s[C_T_DELIVER] = math.inf
        s[C_T_ROBOT] = math.inf
        s[C_W_TH], s[C_MIN_TIME] = w_th, min_time
        s[C_K_DRAG], s[C_INERTIA], s[C_TAU] = k_drag, inertia, tau

    def step(self) -> int:
        """:func:`core_step` on these arrays."""
        return core_step(self.s, self.body, self.watch, self.members, self.found, self.power, self.rows,
                         self.out, self.fin_rows, self.r3)

    def fin_angles(self) -> list[float]:
        """Each fin's last encoder angle (robot order; NaN: none yet)."""
        return self.s[C_FB_ANGLE:C_FB_ANGLE + N_FINS].tolist()

    def arrays(self) -> tuple[np.ndarray, ...]:
        """The arrays :func:`core_step` takes, in its order (for a robot running the core)."""
        return (self.s, self.body, self.watch, self.members, self.found, self.power, self.rows, self.out,
                self.fin_rows, self.r3)
