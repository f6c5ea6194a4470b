"""Body-frame layer: PIDs on velocity, depth and yaw rate, and the fin force allocation.

Control.md section 7, paper section IV.B/IV.D.

Fin indexing is the paper's: fins 0 and 1 are the front pair, 2 and 3 the rear pair;
0 and 2 are on the starboard side, 1 and 3 on the port side (``robot.fins.PAPER_SIDES``). The plant
and the drivers use the robot's order (``robot.fins``, which holds the one map between them).

Sign conventions. Forces are those of the fin model (control.md section 1): forward thrust
is ``f_x < 0``; ``f_y`` is the force in the fin's working plane perpendicular to x (vertical
on U-CAT), its sign towards depth set by ``BodyConfig.depth_sign``. Body frame x forward,
y starboard, z down, so a positive yaw rate is clockwise seen from above (a turn to
starboard); the gyro's z component is that rate.

* Velocity: ``F_x* = -PID_v(v_ref - v)`` (a positive velocity error asks for more forward
  thrust, i.e. a more negative f_x).
* Depth: ``F_y* = depth_sign * PID_z(z_ref - z)`` (depth positive down), realised on the
  front pair: ``f_y,0 = f_y,1 = F_y*/2``, rear ``f_y = 0``.
* Yaw: ``m = PID_r(r_ref - r)`` is a thrust differential in newtons (the paper's yaw limit
  is 0.5 N). It is applied to the front pair as ``f_x,0 += m/2`` (starboard) and
  ``f_x,1 -= m/2`` (port): for m > 0 the port fin pushes forward harder, the starboard fin
  less, giving a clockwise (starboard) yaw moment ``N = b m`` for fins at lateral distance
  ``b``, with no change of the total f_x.
* Axial: every fin gets ``F_x*/4``.

Sync mode: the rear pair is one logical actuator; :func:`allocate` then returns three
logical targets (front starboard, front port, rear pair) and the logical -> physical map.
A logical target is the force *each* of its physical fins must produce.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from math import isfinite

import numpy as np
from numba.extending import register_jitable

from ucat_console.control.argcheck import finite, in_range
from ucat_console.control.filters import MedianFilter, median_clear, median_push, median_size, median_value
from ucat_console.control.params import BodyConfig
from ucat_console.control.pid import EARLIER, NPID, Pid, pid_reset, pid_step
from ucat_console.robot.readings import DepthReading, DvlVelocity, ImuReading
from ucat_console.robot.fins import N_FINS

FRONT_STARBOARD, FRONT_PORT, REAR_STARBOARD, REAR_PORT = 0, 1, 2, 3

#: logical -> physical fins
INDEPENDENT_FINS: tuple[tuple[int, ...], ...] = ((0,), (1,), (2,), (3,))
SYNC_FINS: tuple[tuple[int, ...], ...] = (
    (FRONT_STARBOARD,),
    (FRONT_PORT,),
    (REAR_STARBOARD, REAR_PORT),
)


@dataclass(frozen=True)
class Allocation:
    """Per-logical-actuator force targets ``(f_x, f_y)`` (N) and the physical fins of each."""

    targets: tuple[tuple[float, float], ...]
    fins: tuple[tuple[int, ...], ...]

    @property
    def sync(self) -> bool:
        return len(self.targets) < N_FINS

    def per_fin(self) -> tuple[tuple[float, float], ...]:
        """The target of every physical fin, in paper order 0..3."""
        out: list[tuple[float, float]] = [(0.0, 0.0)] * N_FINS
        for target, fins in zip(self.targets, self.fins):
            for i in fins:
                out[i] = target
        return tuple(out)


@register_jitable
def fin_targets(fx: float, fy: float, m: float) -> tuple[float, float, float, float, float, float]:
    """The allocation's arithmetic (paper section IV.B): (f_x, f_y) of the front starboard
    fin, the front port fin and each rear fin, for F_x* ``fx``, F_y* ``fy`` and the yaw
    differential ``m`` (see the module docstring). The one definition: :func:`allocate`
    runs it as Python, the closed loop's compiled core compiled."""
    axial = 0.25 * fx
    return axial + 0.5 * m, 0.5 * fy, axial - 0.5 * m, 0.5 * fy, axial, 0.0


def allocate(fx_body: float, fy_body: float, yaw: float, *, sync: bool = False) -> Allocation:
    """Split the body demand into fin targets (paper eqs in section IV.B).

    ``fx_body`` is F_x* (N, forward < 0), ``fy_body`` is F_y* (N), ``yaw`` the front-pair
    thrust differential (N, > 0 turns to starboard). See the module docstring for signs.
    """
    fx, fy, m = float(fx_body), float(fy_body), float(yaw)
    if not (isfinite(fx) and isfinite(fy) and isfinite(m)):
        finite("fx_body", fx)
        finite("fy_body", fy)
        finite("yaw", m)
    sx, sy, px, py, rx, ry = fin_targets(fx, fy, m)
    front_s, front_p, rear = (sx, sy), (px, py), (rx, ry)
    if sync:
        return Allocation(targets=(front_s, front_p, rear), fins=SYNC_FINS)
    return Allocation(targets=(front_s, front_p, rear, rear), fins=INDEPENDENT_FINS)


#: the widest envelope: no configuration allows setpoints beyond these (m/s, m, rad/s)
MAX_VELOCITY, MAX_DEPTH, MAX_YAW_RATE = 5.0, 1000.0, 10.0


@dataclass(frozen=True)
class BodySetpoints:
    """Setpoints: forward velocity (m/s), depth (m, positive down), yaw rate (rad/s).

    Always inside the widest envelope; :meth:`within` checks a configured one (the one
    setpoint range check: the loop, the supervisor and the experiments all call it).
    """

    velocity: float = 0.0
    depth: float = 0.0
    yaw_rate: float = 0.0

    def __post_init__(self) -> None:
        self.within(MAX_VELOCITY, MAX_DEPTH, MAX_YAW_RATE)

    def within(self, max_velocity: float, max_depth: float, max_yaw_rate: float) -> BodySetpoints:
        """``self`` if |velocity| <= max_velocity, 0 <= depth <= max_depth and
        |yaw_rate| <= max_yaw_rate, else ValueError naming the value and the range."""
        in_range("velocity", self.velocity, -max_velocity, max_velocity, unit="m/s")
        in_range("depth", self.depth, 0.0, max_depth, unit="m")
        in_range("yaw_rate", self.yaw_rate, -max_yaw_rate, max_yaw_rate, unit="rad/s")
        return self


@dataclass(frozen=True)
class BodyStep:
    """Output of one body-frame step (published as ``telemetry.messages.BodyCommand``).

    ``fx``, ``fy``, ``yaw`` are F_x*, F_y* and the yaw differential (N); ``velocity``,
    ``depth`` are the median-filtered measurements and ``yaw_rate`` the last gyro rate (None
    before the first sample); ``*_updated`` tell whether that loop ran on a new sample in
    this step (False: its output is held).
    """

    t: float
    fx: float
    fy: float
    yaw: float
    allocation: Allocation
    velocity: float | None
    depth: float | None
    yaw_rate: float | None
    velocity_updated: bool
    depth_updated: bool
    yaw_updated: bool


# layout of the body-frame layer's numbers (one float array): what the readings left, the
# loops' outputs, then the three PIDs (``pid.PID_*`` rows) and the two median filters
B_DVL_MISSING = 0  # DVL reports without bottom lock since the reset
B_LAST_DVL_T = 1  # time of the last valid DVL report (NaN: none)
B_LAST_DEPTH_T = 2
B_LAST_IMU_T = 3
B_YAW_RATE = 4  # the last gyro rate (NaN: none)
B_NEW_V = 5  # 1.0: a sample the loop has not run on yet
B_NEW_Z = 6
B_NEW_R = 7
B_FX = 8  # the loops' last outputs (held while a loop has no new sample)
B_FY = 9
B_YAW = 10
B_DEPTH_SIGN = 11
B_WINDOW = 12  # the median filters' length
B_PIDS = 16  # velocity, depth, yaw rate: NPID numbers each
B_FILTERS = B_PIDS + 3 * NPID  # velocity filter, then depth filter
#: what the body functions return: all is well, or which input was not a finite number
BODY_OK, BAD_DVL_VX, BAD_DVL_T, BAD_DEPTH, BAD_DEPTH_T, BAD_GYRO, BAD_IMU_T, BAD_T, EARLIER_T = range(9)
#: the field each bad input is named by
BODY_FIELDS = {BAD_DVL_VX: "dvl.vx", BAD_DVL_T: "dvl.t", BAD_DEPTH: "depth.depth_m", BAD_DEPTH_T: "depth.t",
               BAD_GYRO: "imu.gyro[2]", BAD_IMU_T: "imu.t", BAD_T: "t"}


def body_size(window: int) -> int:
    return B_FILTERS + 2 * median_size(window)


@register_jitable
def body_reset(b: np.ndarray) -> None:
    """Forget every reading and output (the gains stay)."""
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
def body_sensors_reported(b: np.ndarray) -> bool:
    return not math.isnan(b[B_LAST_DEPTH_T]) and (not math.isnan(b[B_LAST_DVL_T]) or b[B_DVL_MISSING] > 0.0)


@register_jitable
def body_update(b: np.ndarray, t: float, sp_v: float, sp_z: float, sp_r: float) -> tuple[int, float, float]:
    """One control step at ``t``: each loop that has a new sample runs (else its output is
    held). Returns (BODY_OK or what was wrong, the filtered velocity, the filtered depth:
    NaN before a sample); the outputs are ``b[B_FX]``, ``b[B_FY]``, ``b[B_YAW]``."""
    if not math.isfinite(t):
        return BAD_T, math.nan, math.nan
    w = int(b[B_WINDOW])
    v = median_value(b, B_FILTERS, w)
    z = median_value(b, B_FILTERS + median_size(w), w)
    r = b[B_YAW_RATE]
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
    b[B_NEW_V] = 0.0
    b[B_NEW_Z] = 0.0
    b[B_NEW_R] = 0.0
    return status, v, z


def _none(x: float) -> float | None:
    return None if math.isnan(x) else float(x)


class BodyController:
    """The three body-frame PIDs with their input filters; readings in, fin targets out.

    Feed readings with :meth:`on_dvl`, :meth:`on_depth`, :meth:`on_imu` as they arrive and
    call :meth:`update` at the control rate. A loop runs only on a new sample; otherwise its
    last output is held. A DVL report with ``valid=False`` is missing data: it is counted
    and never enters the filter as a zero velocity.

    Its numbers are one array, :attr:`state` (layout ``B_*``), that the ``body_*`` functions
    work on: this class runs them as Python, the closed loop's compiled core runs the same
    functions compiled on the loop's controller's array.
    """

    def __init__(self, cfg: BodyConfig) -> None:
        self.cfg = cfg
        w = cfg.median_window
        self.state = np.zeros(body_size(w))
        self.state[B_WINDOW] = w
        self.state[B_DEPTH_SIGN] = cfg.depth_sign
        self.velocity_pid = Pid(cfg.velocity, self.state[B_PIDS:B_PIDS + NPID])
        self.depth_pid = Pid(cfg.depth, self.state[B_PIDS + NPID:B_PIDS + 2 * NPID])
        self.yaw_pid = Pid(cfg.yaw_rate, self.state[B_PIDS + 2 * NPID:B_PIDS + 3 * NPID])
        self.velocity_filter = MedianFilter(w, self.state, B_FILTERS)
        self.depth_filter = MedianFilter(w, self.state, B_FILTERS + median_size(w))
        self.reset()

    def reset(self) -> None:
        body_reset(self.state)

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

    def update(self, t: float, setpoints: BodySetpoints, *, sync: bool = False) -> BodyStep:
        """One control step at time ``t`` (s): run the loops that have new data, allocate."""
        t = finite("t", t)
        b = self.state
        new_v, new_z, new_r = bool(b[B_NEW_V]), bool(b[B_NEW_Z]), bool(b[B_NEW_R])
        status, v, z = body_update(b, t, setpoints.velocity, setpoints.depth, setpoints.yaw_rate)
        if status == EARLIER_T:
            raise ValueError(f"t: {t!r} is earlier than the last update of a body-frame loop")
        fx, fy, yaw = float(b[B_FX]), float(b[B_FY]), float(b[B_YAW])
        return BodyStep(
            t=t,
            fx=fx,
            fy=fy,
            yaw=yaw,
            allocation=allocate(fx, fy, yaw, sync=sync),
            velocity=_none(v),
            depth=_none(z),
            yaw_rate=_none(b[B_YAW_RATE]),
            velocity_updated=new_v,
            depth_updated=new_z,
            yaw_updated=new_r,
        )
