"""Plausibility of the sensors' readings: what a reading may show before the estimator takes it.

Every robot's IMU, DVL and depth readings pass :class:`Plausibility` before they leave the
robot for the closed loop: the drivers' robot (``device_robot_io.DeviceRobotIO``, on the
readings it hands the loop) and the in-process simulator (``sim_robot_io.SimRobotIO``, in
the compiled call that runs the loop's core on the plant, and in ``advance_to``). One
compiled check, :func:`check_row`, judges a reading as a row (``robot.reading_rows``); a
reading that fails is dropped (the loop, the estimator and the telemetry never see it),
counted, and reported as an Event ``implausible`` of its sensor's source (``imu``, ``dvl``,
``pressure``) with the count and the reason: at once when a burst of them begins, then
once a second while it lasts (:class:`DropCounter`); the failsafes label the sensor with them
(``reporting.READING_FAULTS``) and, since a dropped reading is not a valid one, a sensor
that keeps failing starts its failsafe after the rule's timeout.

The checks (:class:`PlausibilityConfig` holds every limit):

* range, from the sensor's data sheet and the robot's envelope: the depth within
  ``min_depth`` (above the surface) .. ``max_depth``; each axis of the specific force within
  the accelerometer's range and of the angular rate within the gyro's (MicroStrain 3DM-CX5:
  +-8 g and +-300 deg/s as delivered); an orientation quaternion of unit norm; the DVL's
  velocity within its range (Water Linked A50: 2 m/s);
* rate of change, against the sensor's last reading that passed: the depth (from the
  pressure, so that a surface zeroing is no jump) no faster than ``max_depth_rate`` plus
  ``depth_noise``; the attitude no faster than the gyro's range (on every axis at once)
  plus ``attitude_noise``. A reading long after the last one may differ by as much as the
  robot can move in between;
* agreement, where two sensors see the same: the depth from the pressure against the
  DVL's vertical velocity (its body-frame velocity turned to NED by the IMU's attitude),
  integrated: their difference, low-passed over ``agreement_window``, may drift by at most
  ``agreement_tolerance`` m/s. While it drifts faster, both the depth readings and the DVL
  reports are dropped (which of the two is wrong is not known). The comparison starts
  afresh after a second without a valid DVL report or a depth reading. Both are taken at
  the body's reference point (the robot description gives no sensor mounts): a mount
  offset changes the vertical distance between the sensors by less than the hull's length
  as the robot pitches, a passing difference the window spreads, not a drift.

A reading with a non-finite value is let through here: the arming gate refuses it and the
failsafes call it invalid (``backend/arming.py``); a DVL report without bottom lock is
missing data and passes too. The pressure driver judges the loop current itself
(:func:`loop_current_problem`: only the driver sees it).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
from numba import njit

from ucat_console.robot import reading_rows as rr
from ucat_console.robot.layout import Layout
from ucat_console.robot.readings import DepthReading, DvlVelocity, ImuReading, Reading
from ucat_console.robot.units import GRAVITY, LOOP_SPAN_MA, LOOP_ZERO_MA, RHO_FRESH
from ucat_console.telemetry.events import Event, EventSink
from ucat_console.typedconf import Config, param

log = logging.getLogger(__name__)

#: Event code of a dropped reading
CODE = "implausible"
#: s between two reports of one sensor's dropped readings while they go on
REPORT_INTERVAL = 1.0
#: s between the report that ended a burst and the one of a new burst (one after a reading passed)
BURST_GAP = 0.25
#: s without a valid DVL report (or a depth) after which the agreement starts afresh
AGREEMENT_GAP = 1.0


@dataclass(frozen=True)
class PlausibilityConfig(Config):
    """What a sensor reading may show before it reaches the estimator (every robot: the
    in-process simulator, the simulated rig, the robot)."""

    max_depth: float = param(
        60.0, lo=0.1, hi=1000.0, unit="m",
        doc="deepest plausible depth: the pool's depth or the robot's envelope (at least loop.max_depth)",
    )
    min_depth: float = param(
        -0.5, lo=-10.0, hi=0.0, unit="m", doc="shallowest plausible depth (negative: above the surface)",
    )
    max_depth_rate: float = param(
        1.0, lo=0.01, hi=100.0, unit="m/s",
        doc="fastest the depth can change from one reading to the next (twice the envelope's fastest speed)",
    )
    depth_noise: float = param(
        0.05, lo=0.0, hi=10.0, unit="m", doc="noise allowed on top of max_depth_rate between two depth readings",
    )
    accel_range: float = param(
        8.0, lo=1.0, hi=20.0, unit="g_n",
        doc="accelerometer range per axis (3DM-CX5: 8 g as delivered, up to 20 g as ordered)",
    )
    gyro_range: float = param(
        300.0, lo=10.0, hi=900.0, unit="deg/s",
        doc="gyro range per axis (3DM-CX5: 300 deg/s as delivered, up to 900 deg/s as ordered)",
    )
    quaternion_tolerance: float = param(
        0.01, lo=1e-6, hi=0.5, doc="largest difference of an orientation quaternion's norm from 1",
    )
    attitude_noise: float = param(
        0.05, lo=0.0, hi=3.2, unit="rad",
        doc="noise allowed on top of the gyro range between two orientation readings",
    )
    dvl_range: float = param(2.0, lo=0.1, hi=20.0, unit="m/s", doc="fastest velocity the DVL measures (A50: 2 m/s)")
    agreement_window: float = param(
        2.0, lo=0.1, hi=60.0, unit="s",
        doc="the depth rate and the DVL's vertical velocity are compared over about this long",
    )
    agreement_tolerance: float = param(
        0.2, lo=0.01, hi=10.0, unit="m/s", doc="how far the depth rate and the DVL's vertical velocity may differ",
    )


# --- the compiled check's arrays ---------------------------------------------------------
LIMITS = Layout("the plausibility limits", [
    ("max_depth", 1, "deepest depth, m"), ("min_depth", 1, "shallowest depth, m"),
    ("depth_rate", 1, "fastest depth change, m/s"), ("depth_noise", 1, "noise on a depth change, m"),
    ("accel", 1, "accelerometer range per axis, m/s^2"), ("gyro", 1, "gyro range per axis, rad/s"),
    ("q_tol", 1, "quaternion norm tolerance"), ("q_noise", 1, "noise on an attitude change, rad"),
    ("dvl", 1, "DVL velocity range, m/s"), ("window", 1, "agreement window, s"),
    ("agree", 1, "agreement tolerance, m/s"),
])
L_MAX_DEPTH, L_MIN_DEPTH, L_DEPTH_RATE, L_DEPTH_NOISE, L_ACCEL, L_GYRO, L_Q_TOL, L_Q_NOISE, L_DVL, L_WINDOW, \
    L_AGREE = (LIMITS.at(f) for f in LIMITS.fields)
#: the sensors, as the state counts them
IMU, DVL, DEPTH = 0, 1, 2
SENSORS = ("imu", "dvl", "depth")
#: each sensor's event source (the depth: its pressure transducer's)
SOURCES = ("imu", "dvl", "pressure")
STATE = Layout("the plausibility state", [
    ("depth_t", 1, "time of the last depth reading that passed the depth's own checks (NaN: none)"),
    ("depth_z", 1, "its depth from the pressure, m"),
    ("q_t", 1, "time of the last orientation that passed (NaN: none)"),
    ("q", 4, "that orientation, normalised (w, x, y, z)"),
    ("w_t", 1, "time of the last valid DVL report (NaN: none)"),
    ("w", 1, "its vertical velocity (NED, down), m/s"),
    ("w_sum", 1, "the DVL's vertical velocity integrated since the agreement began, m"),
    ("e_t", 1, "time of the last depth compared (NaN: the agreement starts afresh)"),
    ("e_ref", 1, "the depth less the DVL's integral, low-passed over the window, m"),
    ("apart", 1, "how fast the two drift apart, m/s (NaN: not compared)"),
    ("disagree", 1, "1: the last comparison found them apart"),
    ("dropped", 3, "readings dropped, per sensor"),
    ("code", 3, "the last one's reason (a code below), per sensor"),
    ("v1", 3, "the last one's offending value, per sensor"),
    ("v2", 3, "and a second figure (the axis, the time between readings), per sensor"),
    ("dropped_t", 3, "and its time, per sensor"),
    ("passed", 3, "readings that passed, per sensor"),
])
S_DEPTH_T, S_DEPTH_Z, S_Q_T, S_Q, S_W_T, S_W, S_W_SUM, S_E_T, S_E_REF, S_APART, S_DISAGREE, S_DROPPED, S_CODE, \
    S_V1, S_V2, S_DROPPED_T, S_PASSED = (STATE.at(f) for f in STATE.fields)

# reasons
OK, DEEP, ABOVE, DEPTH_JUMP, ACCEL, GYRO, Q_NORM, Q_JUMP, DVL_SPEED, APART = range(10)
_SQRT3 = math.sqrt(3.0)
_DEPTH_PER_PA = 1.0 / (RHO_FRESH * GRAVITY)


def limits_array(cfg: PlausibilityConfig) -> np.ndarray:
    """The limits of ``cfg`` as the compiled check takes them (SI units)."""
    lim = np.zeros(LIMITS.size)
    lim[L_MAX_DEPTH], lim[L_MIN_DEPTH] = cfg.max_depth, cfg.min_depth
    lim[L_DEPTH_RATE], lim[L_DEPTH_NOISE] = cfg.max_depth_rate, cfg.depth_noise
    lim[L_ACCEL], lim[L_GYRO] = cfg.accel_range * GRAVITY, math.radians(cfg.gyro_range)
    lim[L_Q_TOL], lim[L_Q_NOISE] = cfg.quaternion_tolerance, cfg.attitude_noise
    lim[L_DVL], lim[L_WINDOW], lim[L_AGREE] = cfg.dvl_range, cfg.agreement_window, cfg.agreement_tolerance
    return lim


def state_array() -> np.ndarray:
    """A fresh state: nothing seen, nothing dropped."""
    st = np.zeros(STATE.size)
    for col in (S_DEPTH_T, S_Q_T, S_W_T, S_E_T, S_APART):
        st[col] = math.nan
    return st


@njit(cache=True)
def _drop(st: np.ndarray, sensor: int, t: float, code: int, v1: float, v2: float) -> int:
    st[S_DROPPED + sensor] += 1.0
    st[S_DROPPED_T + sensor] = t
    st[S_CODE + sensor] = code
    st[S_V1 + sensor] = v1
    st[S_V2 + sensor] = v2
    return code


@njit(cache=True)
def _restart_agreement(st: np.ndarray) -> None:
    st[S_E_T] = math.nan
    st[S_APART] = math.nan
    st[S_DISAGREE] = 0.0


@njit(cache=True)
def _compare_depth(lim: np.ndarray, st: np.ndarray, z: float, t: float) -> bool:
    """The depth ``z`` (from the pressure) at ``t`` against the DVL's integrated vertical
    velocity; True when the two drift apart faster than the tolerance."""
    w_t = st[S_W_T]
    if math.isnan(w_t) or t - w_t > AGREEMENT_GAP:
        _restart_agreement(st)  # no DVL to compare with
        return False
    e = z - (st[S_W_SUM] + st[S_W] * (t - w_t))
    e_t = st[S_E_T]
    if math.isnan(e_t) or t - e_t > AGREEMENT_GAP:
        st[S_E_REF] = e
        st[S_E_T] = t
        st[S_APART] = 0.0
        st[S_DISAGREE] = 0.0
        return False
    window = lim[L_WINDOW]
    d = e - st[S_E_REF]  # a steady drift r settles at r * window
    st[S_E_REF] += d * (1.0 - math.exp(-max(t - e_t, 0.0) / window))
    st[S_E_T] = t
    st[S_APART] = d / window
    apart = abs(d) > lim[L_AGREE] * window
    st[S_DISAGREE] = 1.0 if apart else 0.0
    return apart


@njit(cache=True)
def _check_depth(lim: np.ndarray, st: np.ndarray, row: np.ndarray, t: float) -> int:
    d, p = row[rr.DEPTH_M], row[rr.DEPTH_PA]
    z = p * _DEPTH_PER_PA if math.isfinite(p) else d
    if not (math.isfinite(d) and math.isfinite(z) and math.isfinite(t)):
        return OK
    if d > lim[L_MAX_DEPTH]:
        return _drop(st, DEPTH, t, DEEP, d, 0.0)
    if d < lim[L_MIN_DEPTH]:
        return _drop(st, DEPTH, t, ABOVE, d, 0.0)
    t0 = st[S_DEPTH_T]
    if not math.isnan(t0):
        dt = max(t - t0, 0.0)
        dz = z - st[S_DEPTH_Z]
        if abs(dz) > lim[L_DEPTH_RATE] * dt + lim[L_DEPTH_NOISE]:
            return _drop(st, DEPTH, t, DEPTH_JUMP, dz, dt)
    st[S_DEPTH_T] = t
    st[S_DEPTH_Z] = z
    if _compare_depth(lim, st, z, t):
        return _drop(st, DEPTH, t, APART, st[S_APART], 0.0)
    return OK


@njit(cache=True)
def _check_imu(lim: np.ndarray, st: np.ndarray, row: np.ndarray, t: float) -> int:
    for i in range(3):
        if not (math.isfinite(row[rr.IMU_ACCEL + i]) and math.isfinite(row[rr.IMU_GYRO + i])):
            return OK  # the arming gate's
    for i in range(3):
        if abs(row[rr.IMU_ACCEL + i]) > lim[L_ACCEL]:
            return _drop(st, IMU, t, ACCEL, row[rr.IMU_ACCEL + i], i)
    for i in range(3):
        if abs(row[rr.IMU_GYRO + i]) > lim[L_GYRO]:
            return _drop(st, IMU, t, GYRO, row[rr.IMU_GYRO + i], i)
    w, x, y, z = row[rr.IMU_Q], row[rr.IMU_Q + 1], row[rr.IMU_Q + 2], row[rr.IMU_Q + 3]
    if not (math.isfinite(w) and math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
        return OK  # not streamed (NaN), or non-finite: the arming gate's
    n = math.sqrt(w * w + x * x + y * y + z * z)
    if abs(n - 1.0) > lim[L_Q_TOL]:
        return _drop(st, IMU, t, Q_NORM, n, 0.0)
    w, x, y, z = w / n, x / n, y / n, z / n
    t0 = st[S_Q_T]
    if not math.isnan(t0):
        dt = max(t - t0, 0.0)
        dot = abs(w * st[S_Q] + x * st[S_Q + 1] + y * st[S_Q + 2] + z * st[S_Q + 3])
        angle = 2.0 * math.acos(min(dot, 1.0))
        if angle > _SQRT3 * lim[L_GYRO] * dt + lim[L_Q_NOISE]:
            return _drop(st, IMU, t, Q_JUMP, angle, dt)
    st[S_Q_T] = t
    st[S_Q], st[S_Q + 1], st[S_Q + 2], st[S_Q + 3] = w, x, y, z
    return OK


@njit(cache=True)
def _check_dvl(lim: np.ndarray, st: np.ndarray, row: np.ndarray, t: float) -> int:
    vx, vy, vz = row[rr.DVL_V], row[rr.DVL_V + 1], row[rr.DVL_V + 2]
    if row[rr.DVL_VALID] == 0.0 or not (math.isfinite(vx) and math.isfinite(vy) and math.isfinite(vz)
                                         and math.isfinite(t)):
        return OK  # missing data, or the arming gate's
    speed = math.sqrt(vx * vx + vy * vy + vz * vz)
    if speed > lim[L_DVL]:
        return _drop(st, DVL, t, DVL_SPEED, speed, 0.0)
    # the vertical velocity: the body-frame velocity turned to NED by the last orientation
    if math.isnan(st[S_Q_T]):
        down = vz
    else:
        w, x, y, z = st[S_Q], st[S_Q + 1], st[S_Q + 2], st[S_Q + 3]
        down = 2.0 * (x * z - w * y) * vx + 2.0 * (y * z + w * x) * vy + (1.0 - 2.0 * (x * x + y * y)) * vz
    w_t = st[S_W_T]
    if math.isnan(w_t) or t - w_t > AGREEMENT_GAP:
        st[S_W_SUM] = 0.0
        _restart_agreement(st)
    else:
        st[S_W_SUM] += st[S_W] * max(t - w_t, 0.0)
    st[S_W_T] = t
    st[S_W] = down
    e_t = st[S_E_T]
    if math.isnan(e_t) or t - e_t > AGREEMENT_GAP:
        st[S_DISAGREE] = 0.0  # no depth to disagree with
    if st[S_DISAGREE] != 0.0:
        return _drop(st, DVL, t, APART, st[S_APART], 0.0)
    return OK


@njit(cache=True)
def check_row(lim: np.ndarray, st: np.ndarray, row: np.ndarray) -> int:
    """The reason the reading in ``row`` is implausible (``OK``: it is not); counts it
    in ``st`` when it is, and learns from it when it is not."""
    kind, t = row[rr.KIND], row[rr.T]
    if kind == rr.DEPTH:
        sensor, found = DEPTH, _check_depth(lim, st, row, t)
    elif kind == rr.IMU:
        sensor, found = IMU, _check_imu(lim, st, row, t)
    elif kind == rr.DVL:
        sensor, found = DVL, _check_dvl(lim, st, row, t)
    else:
        return OK
    if found == OK:
        st[S_PASSED + sensor] += 1.0
    return found


@njit(cache=True)
def filter_rows(lim: np.ndarray, st: np.ndarray, rows: np.ndarray, n: int) -> int:
    """Drop the implausible ones of the first ``n`` readings in ``rows`` (the others move up,
    in order); how many are left."""
    k = 0
    for i in range(n):
        if check_row(lim, st, rows[i]) == OK:
            if k != i:
                for j in range(rows.shape[1]):
                    rows[k, j] = rows[i, j]
            k += 1
    return k


# --- reasons and reports -----------------------------------------------------------------
def reason(code: int, v1: float, v2: float, cfg: PlausibilityConfig) -> str:
    """What a reading dropped for ``code`` showed, in words."""
    axis = "xyz"[int(v2)] if code in (ACCEL, GYRO) and 0 <= v2 < 3 else ""
    if code == DEEP:
        return f"depth {v1:.1f} m beyond the {cfg.max_depth:g} m limit"
    if code == ABOVE:
        return f"depth {v1:.2f} m, further above the surface than {cfg.min_depth:g} m"
    if code == DEPTH_JUMP:
        return (f"depth jumped {v1:+.2f} m in {v2:.3f} s (at most {cfg.max_depth_rate:g} m/s "
                f"and {cfg.depth_noise:g} m)")
    if code == ACCEL:
        return f"acceleration {v1 / GRAVITY:.4g} g along {axis}, beyond the accelerometer's {cfg.accel_range:g} g"
    if code == GYRO:
        return (f"angular rate {v1:.4g} rad/s ({math.degrees(v1):.0f} deg/s) about {axis}, beyond the gyro's "
                f"{cfg.gyro_range:g} deg/s")
    if code == Q_NORM:
        return f"orientation quaternion of norm {v1:.3g}, not 1"
    if code == Q_JUMP:
        return (f"orientation turned {math.degrees(v1):.1f} deg in {v2:.3f} s, faster than the gyro's "
                f"{cfg.gyro_range:g} deg/s")
    if code == DVL_SPEED:
        return f"velocity {v1:.2f} m/s, beyond the DVL's {cfg.dvl_range:g} m/s"
    if code == APART:
        return (f"depth rate and the DVL's vertical velocity {abs(v1):.2f} m/s apart "
                f"(at most {cfg.agreement_tolerance:g} m/s over {cfg.agreement_window:g} s)")
    return f"reason {code}"


def loop_current_problem(current_ma: float, depth_m: float) -> str:
    """Why a transducer's loop current (mA) is no measurement, "" when it is one.

    A 4-20 mA transducer's span is 4 mA (its lowest pressure, ``p_min``) to 20 mA (its
    highest): a current at or below 4 mA is at the bottom of the span or under it (NAMUR NE
    43's under-range saturation, 3.8-4 mA: any pressure at or below ``p_min`` reads so, and
    so does a transducer whose output is stuck at its floor), and a current above 20 mA is
    over the span (NE 43's saturation, 20-20.5 mA). Neither says what the pressure is.
    Outside 3.8-20.5 mA the loop is broken or shorted (the driver's ``broken_loop``)."""
    if current_ma <= LOOP_ZERO_MA:
        return (f"loop current {current_ma:.3f} mA at or below {LOOP_ZERO_MA:g} mA: the bottom of the "
                f"transducer's span or under it, no measurement")
    top = LOOP_ZERO_MA + LOOP_SPAN_MA
    if current_ma > top:
        return (f"loop current {current_ma:.3f} mA above {top:g} mA (depth {depth_m:.1f} m): beyond the "
                f"transducer's span, no measurement")
    return ""


class DropCounter:
    """Readings of one sensor dropped as implausible, reported (``emit(dropped, reason)``,
    the count since the last report and the latest reason) at once when a burst of them
    begins (a reading passed since the last report, which is at least :data:`BURST_GAP`
    s old), then every :data:`REPORT_INTERVAL` s while it lasts: the failsafes know why a
    sensor went quiet before its rule's timeout, and a sensor failing on and off does not
    flood the events."""

    def __init__(self, emit: Callable[[int, str], None]) -> None:
        self._emit = emit
        self._pending = 0
        self._reason = ""
        self._last = -math.inf
        self._passed = True

    def passed(self) -> None:
        """A reading passed: the next one dropped begins a burst."""
        self._passed = True

    def note(self, n: int, why: str, now: float) -> None:
        """``n`` more dropped at ``now``, the latest for ``why``."""
        self._pending += n
        self._reason = why
        self.flush(now)

    def flush(self, now: float) -> None:
        """Report what is pending when the interval since the last report has passed."""
        if self._pending and not now - self._last < (BURST_GAP if self._passed else REPORT_INTERVAL):
            n, self._pending = self._pending, 0
            self._last = now
            self._passed = False
            self._emit(n, self._reason)


def report_event(t: float, source: str, dropped: int, why: str, **data: object) -> Event:
    """The Event of ``dropped`` readings of ``source`` dropped as implausible."""
    noun = "reading" if dropped == 1 else "readings"
    return Event(t=t, source=source, code=CODE, message=f"{dropped} {noun} dropped as implausible: {why}",
                 level="error", data={"dropped": dropped, "reason": why, **data})


class Plausibility:
    """The checks of one robot's readings (module docstring), what they dropped, and its
    reports: Events to ``on_event``, each stamped with the time of the last reading it
    counts (so that a valid reading before it does not end it in the failsafes' eyes)."""

    def __init__(self, cfg: PlausibilityConfig | None = None, on_event: EventSink | None = None) -> None:
        self.cfg = cfg or PlausibilityConfig()
        self.limits = limits_array(self.cfg)
        self.state = state_array()
        self.on_event = on_event
        self._row = np.full(rr.ROW, math.nan)
        self._counted = [0, 0, 0]
        self._passed = [0, 0, 0]
        self._counters = [DropCounter(lambda n, why, s=s: self._report(s, n, why)) for s in range(3)]
        check_row(self.limits, state_array(), self._row)  # compiled (or loaded) now, not on a reading

    def dropped(self, sensor: str) -> int:
        """Readings of ``sensor`` (``imu``, ``dvl``, ``depth``) dropped so far."""
        return int(self.state[S_DROPPED + SENSORS.index(sensor)])

    def reason(self, sensor: str) -> str:
        """Why the last reading of ``sensor`` was dropped ("" when none was)."""
        s = SENSORS.index(sensor)
        st = self.state
        return reason(int(st[S_CODE + s]), st[S_V1 + s], st[S_V2 + s], self.cfg) if st[S_DROPPED + s] else ""

    def filter(self, readings: list[Reading]) -> list[Reading]:
        """``readings`` without the implausible ones (the same list when none is)."""
        out: list[Reading] | None = None
        row, lim, st = self._row, self.limits, self.state
        for i, r in enumerate(readings):
            tp = type(r)
            if tp is ImuReading or tp is DepthReading or tp is DvlVelocity:
                rr.to_row(r, row)
                if check_row(lim, st, row) != OK:
                    if out is None:
                        out = readings[:i]
                    continue
            if out is not None:
                out.append(r)
        return readings if out is None else out

    def report(self, now: float) -> None:
        """Report the readings dropped since the last report (at loop time ``now``)."""
        st = self.state
        for s, counter in enumerate(self._counters):
            passed = int(st[S_PASSED + s])
            if passed > self._passed[s]:
                self._passed[s] = passed
                counter.passed()
            n = int(st[S_DROPPED + s])
            if n > self._counted[s]:
                counter.note(n - self._counted[s], self.reason(SENSORS[s]), now)
                self._counted[s] = n
            else:
                counter.flush(now)

    def _report(self, sensor: int, dropped: int, why: str) -> None:
        source = SOURCES[sensor]
        event = report_event(float(self.state[S_DROPPED_T + sensor]), source, dropped, why)
        log.warning("%s: %s", source, event.message)
        if self.on_event is not None:
            try:
                self.on_event(event)
            except Exception:
                log.exception("%s: event sink failed on %s", source, CODE)
