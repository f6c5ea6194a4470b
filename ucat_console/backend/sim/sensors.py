"""Sensor models of the simulated U-CAT: DVL, pressure transducer, IMU and fin encoders.

Each sensor samples the plant's true state at its own rate and returns the reading types the
robot delivers (``robot/readings.py``). Noise comes from numpy Generators seeded
from one seed (one independent stream per sensor), so a run is repeatable and a change in
one sensor's sampling does not shift another's noise.

* DVL (A50): bottom-track velocity over ground in the body frame, white noise per axis. The
  altitude is the vertical distance to a flat bottom; outside the valid altitude range, or
  on a random dropout, the report has ``valid=False`` and NaN velocities (missing data,
  never zeros).
* Pressure (Gems 3101P behind an ADC): gauge pressure rho g z plus noise, turned into the
  4-20 mA loop current (saturating at 3.8 and 20.5 mA, NAMUR NE 43), quantised by the ADC,
  and converted back to pressure and depth (the conversions of ``robot/units.py``, which the
  pressure driver uses too). A current pinned at either limit measures nothing (the robot
  more than 0.2/16 of the span above the surface, 0.32 m for the default 250 kPa, or deeper
  than 16.5/16 of it): no reading then, as the pressure driver hands on none (its
  ``loop_current_problem``).
* IMU (3DM-CX5): gyro = body rate + constant bias + noise; accel in m/s^2 = the specific
  force a - g in the body frame (level and at rest: (0, 0, -g0)) plus the bias and noise,
  which are given in standard gravities g0 as the sensor's data sheet gives them; attitude
  = the true quaternion turned by a small random rotation, with its ZYX Euler angles.
* Encoders: fin angle and rate quantised as the EPOS2 reports them (``robot.servo``), at the
  feedback (PDO) rate.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numba.extending import register_jitable

from ucat_console.backend.sim.params import PressureModelConfig, SensorsConfig, ServoConfig
from ucat_console.backend.sim.vehicle import NU, NU_DOT, POS, QUAT
from ucat_console.robot.fins import N_FINS
from ucat_console.robot.layout import Layout
from ucat_console.robot import reading_rows as rr
from ucat_console.robot.readings import Reading
from ucat_console.robot.rotations import quat_mul, quat_to_euler
from ucat_console.robot.units import (
    GRAVITY,
    LOOP_MAX_MA,
    LOOP_MIN_MA,
    current_to_pressure,
    depth_to_pressure,
    pressure_to_current,
    pressure_to_depth,
)


@register_jitable
def loop_current(gauge_pa: float, span_pa: float) -> float:
    """Loop current (mA) of the transducer at a gauge pressure, saturating at the NE 43 limits."""
    i = pressure_to_current(gauge_pa, 0.0, span_pa)
    return min(max(i, LOOP_MIN_MA), LOOP_MAX_MA)


@register_jitable
def adc_current(current_ma: float, adc_bits: int, full_scale_ma: float) -> float:
    """The current the ADC reports: a whole code of ``adc_bits`` over 0..full scale."""
    full = (1 << adc_bits) - 1
    code = min(max(round(current_ma / full_scale_ma * full), 0), full)
    return code * full_scale_ma / full


def current_from_pressure(gauge_pa: float, cfg: PressureModelConfig) -> float:
    """Loop current (mA) of the transducer at a gauge pressure, saturating at the NE 43 limits."""
    return loop_current(gauge_pa, cfg.span_pa)


def adc_quantise(current_ma: float, cfg: PressureModelConfig) -> float:
    """The current the ADC reports: a whole code of ``adc_bits`` over 0..full scale."""
    return adc_current(current_ma, cfg.adc_bits, cfg.adc_full_scale_ma)


#: the IMU model's output, and a row of its noise block (scaled standard normals)
IMU_OUT = Layout("the IMU model's output", [
    ("accel", 3, "specific force, body frame (m/s2)"), ("gyro", 3, "body rates (rad/s)"),
    ("q", 4, "attitude w, x, y, z"), ("euler", 3, "its roll, pitch, yaw (rad)"),
])
I_ACCEL, I_GYRO, I_Q, I_EULER = (IMU_OUT.at(f) for f in IMU_OUT.fields)
NI = IMU_OUT.size
IMU_NOISE = Layout("a row of the IMU's noise block", [
    ("accel", 3, "accelerometer noise (g_n)"), ("gyro", 3, "gyro noise (rad/s)"),
    ("attitude", 3, "attitude noise, a small rotation vector (rad)"),
])
N_ACCEL, N_GYRO, N_ATTITUDE = (IMU_NOISE.at(f) for f in IMU_NOISE.fields)
DVL_NOISE = Layout("a row of the DVL's noise block", [
    ("velocity", 3, "velocity noise per axis (m/s)"),
    ("dropout", 1, "a standard normal: decides dropouts"),
])
D_VELOCITY, D_DROPOUT = (DVL_NOISE.at(f) for f in DVL_NOISE.fields)
PRESSURE_NOISE = Layout("a row of the pressure sensor's noise block", [("pressure", 1, "transducer noise (Pa)")])
R_PRESSURE = PRESSURE_NOISE.at("pressure")


@njit(cache=True)
def imu_kernel(
    xv: np.ndarray, noise: np.ndarray, gyro_bias: np.ndarray, accel_bias: np.ndarray, out: np.ndarray
) -> None:
    """IMU outputs from the true state into ``out`` (:data:`IMU_OUT`); ``noise`` is this
    sample's row of the noise block (:data:`IMU_NOISE`)."""
    w, x, y, z = xv[QUAT], xv[QUAT + 1], xv[QUAT + 2], xv[QUAT + 3]
    # NED down axis in body coordinates (third row of R)
    g0x = 2.0 * (x * z - w * y)
    g0y = 2.0 * (y * z + w * x)
    g0z = 1.0 - 2.0 * (x * x + y * y)
    u, v, ww = xv[NU], xv[NU + 1], xv[NU + 2]
    p, q, r = xv[NU + 3], xv[NU + 4], xv[NU + 5]
    ax = xv[NU_DOT] + (q * ww - r * v)
    ay = xv[NU_DOT + 1] + (r * u - p * ww)
    az = xv[NU_DOT + 2] + (p * v - q * u)
    # in standard gravities (the bias and noise are), then in m/s^2
    out[I_ACCEL] = (ax / GRAVITY - g0x + accel_bias[0] + noise[N_ACCEL]) * GRAVITY
    out[I_ACCEL + 1] = (ay / GRAVITY - g0y + accel_bias[1] + noise[N_ACCEL + 1]) * GRAVITY
    out[I_ACCEL + 2] = (az / GRAVITY - g0z + accel_bias[2] + noise[N_ACCEL + 2]) * GRAVITY
    out[I_GYRO] = p + gyro_bias[0] + noise[N_GYRO]
    out[I_GYRO + 1] = q + gyro_bias[1] + noise[N_GYRO + 1]
    out[I_GYRO + 2] = r + gyro_bias[2] + noise[N_GYRO + 2]
    # attitude: q (x) exp(n / 2)
    nx, ny, nz = noise[N_ATTITUDE], noise[N_ATTITUDE + 1], noise[N_ATTITUDE + 2]
    a = math.sqrt(nx * nx + ny * ny + nz * nz)
    if a > 1e-15:
        c = math.cos(0.5 * a)
        s = math.sin(0.5 * a) / a
    else:
        c = 1.0
        s = 0.5
    dw, dx, dy, dz = c, s * nx, s * ny, s * nz
    qw, qx, qy, qz = quat_mul(w, x, y, z, dw, dx, dy, dz)
    norm = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
    qw, qx, qy, qz = qw / norm, qx / norm, qy / norm, qz / norm
    out[I_Q] = qw
    out[I_Q + 1] = qx
    out[I_Q + 2] = qy
    out[I_Q + 3] = qz
    out[I_EULER], out[I_EULER + 1], out[I_EULER + 2] = quat_to_euler(qw, qx, qy, qz)


# which sensor (schedule index), and its bit in a sample mask
IMU, PRESSURE, DVL, FINS = 0, 1, 2, 3
N_SENSORS = 4
#: the suite's numbers, one array for the compiled sampler (``state``), and their columns as
#: constants
SUITE = Layout("the sensor suite's state", [
    ("t0", N_SENSORS, "per sensor (IMU, PRESSURE, DVL, FINS): its first sample time (s)"),
    ("period", N_SENSORS, "its period (s)"),
    ("k", N_SENSORS, "samples it has taken"),
    ("next", 1, "the earliest due time (s)"),
    ("gyro_bias", 3, "the IMU's constant gyro bias (rad/s)"),
    ("accel_bias", 3, "its constant accelerometer bias (g_n)"),
    ("counts", 1, "the encoders' resolution: quadcounts per rad"),
    ("rate_step", 1, "and their rate quantum (rad/s)"),
    ("imu_row", 1, "the next row of the IMU noise block"),
    ("p_row", 1, "the next row of the pressure noise block"),
    ("dvl_row", 1, "the next row of the DVL's"),
    ("rho", 1, "the pressure model: water density (kg/m3)"),
    ("span", 1, "its span (Pa)"),
    ("adc_bits", 1, "its ADC bits"),
    ("adc_fs", 1, "and full scale (mA)"),
    ("dvl_std", 1, "the DVL model: velocity noise (m/s)"),
    ("dropout", 1, "dropout probability"),
    ("alt_min", 1, "shortest valid altitude (m)"),
    ("alt_max", 1, "longest valid altitude (m)"),
    ("bottom", 1, "depth of the flat bottom (m)"),
])
(S_T0, S_PERIOD, S_K, S_NEXT, S_GYRO_BIAS, S_ACCEL_BIAS, S_COUNTS, S_RATE_STEP, S_IMU_ROW, S_P_ROW, S_DVL_ROW,
 S_RHO, S_SPAN, S_ADC_BITS, S_ADC_FS, S_DVL_STD, S_DROPOUT, S_ALT_MIN, S_ALT_MAX, S_BOTTOM) = (
    SUITE.at(f) for f in SUITE.fields)
NS = SUITE.size
#: the sampler's output (``out``)
OUTPUT = Layout("the sampler's output", [
    ("imu", NI, "the IMU's (IMU_OUT)"),
    ("fin_pos", N_FINS, "each fin's encoder angle (rad)"),
    ("fin_vel", N_FINS, "and rate (rad/s); right after the angles (the fins' reading row takes both)"),
])
O_IMU, O_FIN_POS, O_FIN_VEL = (OUTPUT.at(f) for f in OUTPUT.fields)
NO = OUTPUT.size


@njit(cache=True)
def _take(sf: np.ndarray, i: int, t: float) -> bool:
    """Sensor ``i``'s schedule: True when a sample is due at ``t``, and move past ``t``
    (missed samples are skipped)."""
    t0, period, k = sf[S_T0 + i], sf[S_PERIOD + i], sf[S_K + i]
    if t + 1e-9 < t0 + k * period:
        return False
    sf[S_K + i] = max(k + 1.0, math.floor((t - t0) / period + 1e-9) + 1.0)
    return True


@njit(cache=True)
def sense(xv: np.ndarray, fin_theta: np.ndarray, fin_omega: np.ndarray, t: float, sf: np.ndarray,
          imu_noise: np.ndarray, out: np.ndarray) -> int:
    """Take the samples due at ``t``: the IMU's and the encoders' into ``out``; returns the
    mask of sensors sampled (bit ``1 << IMU`` ...: the caller makes the pressure and DVL
    readings, whose noise streams it draws)."""
    if t + 1e-9 < sf[S_NEXT]:
        return 0
    mask = 0
    if _take(sf, IMU, t):
        row = int(sf[S_IMU_ROW])
        imu_kernel(xv, imu_noise[row], sf[S_GYRO_BIAS:S_GYRO_BIAS + 3], sf[S_ACCEL_BIAS:S_ACCEL_BIAS + 3],
                   out[O_IMU:O_IMU + NI])
        sf[S_IMU_ROW] = row + 1
        mask |= 1 << IMU
    if _take(sf, PRESSURE, t):
        mask |= 1 << PRESSURE
    if _take(sf, DVL, t):
        mask |= 1 << DVL
    if _take(sf, FINS, t):
        k, q = sf[S_COUNTS], sf[S_RATE_STEP]
        for i in range(fin_theta.shape[0]):  # whole counts, whole rate steps (robot.servo.quantise)
            out[O_FIN_POS + i] = np.rint(fin_theta[i] * k) / k
            out[O_FIN_VEL + i] = np.rint(fin_omega[i] / q) * q
        mask |= 1 << FINS
    nxt = math.inf
    for i in range(N_SENSORS):
        due = sf[S_T0 + i] + sf[S_K + i] * sf[S_PERIOD + i]
        if due < nxt:
            nxt = due
    sf[S_NEXT] = nxt
    return mask


@njit(cache=True)
def sample_rows(mask: int, t: float, xv: np.ndarray, sf: np.ndarray, out: np.ndarray, p_noise: np.ndarray,
                dvl_noise: np.ndarray, rows: np.ndarray, first: int) -> int:
    """The readings of the sensors in ``mask`` (from :func:`sense` at ``t``) as rows
    (``robot.reading_rows``) from ``rows[first]`` on, in the order IMU, pressure, DVL,
    encoders; the pressure and DVL readings draw the next row of their noise blocks.
    Returns the row after the last one written."""
    k = first
    if mask & (1 << IMU):
        r = rows[k]
        r[rr.KIND] = rr.IMU
        r[rr.T] = t
        for i in range(NI):
            r[rr.IMU_ACCEL + i] = out[O_IMU + i]
        k += 1
    if mask & (1 << PRESSURE):
        i = int(sf[S_P_ROW])
        sf[S_P_ROW] = i + 1
        rho = sf[S_RHO]
        span = sf[S_SPAN]
        gauge = depth_to_pressure(xv[POS + 2], 0.0, rho)
        gauge += p_noise[i, R_PRESSURE]
        unclamped = pressure_to_current(gauge, 0.0, span)
        if LOOP_MIN_MA <= unclamped <= LOOP_MAX_MA:  # pinned at a limit: no measurement, no reading
            current = adc_current(loop_current(gauge, span), int(sf[S_ADC_BITS]), sf[S_ADC_FS])
            measured = current_to_pressure(current, 0.0, span)
            r = rows[k]
            r[rr.KIND] = rr.DEPTH
            r[rr.T] = t
            r[rr.DEPTH_M] = pressure_to_depth(measured, 0.0, rho)
            r[rr.DEPTH_PA] = measured
            k += 1
    if mask & (1 << DVL):
        i = int(sf[S_DVL_ROW])  # drawn every time: the stream ignores validity
        sf[S_DVL_ROW] = i + 1
        n = dvl_noise[i]
        drop = 0.5 * math.erfc(-n[D_DROPOUT] / math.sqrt(2.0)) < sf[S_DROPOUT]  # uniform via the normal CDF
        altitude = sf[S_BOTTOM] - xv[POS + 2]
        in_range = sf[S_ALT_MIN] <= altitude <= sf[S_ALT_MAX]
        r = rows[k]
        r[rr.KIND] = rr.DVL
        r[rr.T] = t
        if not in_range or drop:
            r[rr.DVL_V] = math.nan
            r[rr.DVL_V + 1] = math.nan
            r[rr.DVL_V + 2] = math.nan
            r[rr.DVL_VALID] = 0.0
            r[rr.DVL_ALTITUDE] = altitude if in_range else math.nan
            r[rr.DVL_FOM] = math.nan
        else:
            r[rr.DVL_V] = xv[NU] + n[D_VELOCITY]
            r[rr.DVL_V + 1] = xv[NU + 1] + n[D_VELOCITY + 1]
            r[rr.DVL_V + 2] = xv[NU + 2] + n[D_VELOCITY + 2]
            r[rr.DVL_VALID] = 1.0
            r[rr.DVL_ALTITUDE] = altitude
            r[rr.DVL_FOM] = sf[S_DVL_STD]
        k += 1
    if mask & (1 << FINS):
        r = rows[k]
        r[rr.KIND] = rr.FINS
        r[rr.T] = t
        for i in range(2 * N_FINS):
            r[rr.FINS_ANGLE + i] = out[O_FIN_POS + i]
        k += 1
    return k


def _scale(layout: Layout, **std: float) -> list[float]:
    """The scale of each column of a noise block: each field's standard deviation."""
    out = [0.0] * layout.size
    for f in layout.fields:
        out[layout.span(f)] = [std[f]] * layout.width(f)
    return out


class _Noise:
    """Rows of scaled standard normals drawn from one Generator in blocks, used in order;
    the next row to use is ``state[row]`` (compiled code takes the rows)."""

    def __init__(self, rng: np.random.Generator, scale: list[float], state: np.ndarray, row: int,
                 block: int = 512) -> None:
        self._rng = rng
        self._scale = np.asarray(scale, dtype=float)
        self._block = block
        self._state = state
        self._row = row
        self.refill()

    def refill(self) -> None:
        self.buf = self._rng.standard_normal((self._block, len(self._scale))) * self._scale
        self._state[self._row] = 0.0

    def rows(self) -> np.ndarray:
        """The block holding the next row (a new block once one is used up)."""
        if self._state[self._row] >= self._block:
            self.refill()
        return self.buf


class SensorSuite:
    """All sensors of the plant; :meth:`sample` returns the readings due at a time.

    The sensors are compiled (:func:`sense`, :func:`sample_rows`): the plant calls them in
    the same compiled call as its physics, and writes the readings as rows
    (``robot.reading_rows``) that compiled code reads as they are; :meth:`readings` makes
    reading objects of them."""

    def __init__(self, cfg: SensorsConfig, servo: ServoConfig, seed: int) -> None:
        self._cfg = cfg
        self._servo = servo
        self.state = np.zeros(NS)
        self.out = np.zeros(NO)
        self.rows = np.zeros((4, rr.ROW))
        self.reset(seed)

    def reset(self, seed: int, t0: float = 0.0) -> None:
        """New noise streams and biases from ``seed``; the first samples are due at ``t0``."""
        imu_ss, dvl_ss, p_ss = np.random.SeedSequence(seed).spawn(3)
        rng_imu = np.random.default_rng(imu_ss)
        icfg = self._cfg.imu
        sf = self.state
        sf[SUITE.span("gyro_bias")] = rng_imu.normal(0.0, icfg.gyro_bias_std, SUITE.width("gyro_bias"))
        sf[SUITE.span("accel_bias")] = rng_imu.normal(0.0, icfg.accel_bias_std, SUITE.width("accel_bias"))
        self._imu_noise = _Noise(rng_imu, _scale(IMU_NOISE, accel=icfg.accel_noise_std, gyro=icfg.gyro_noise_std,
                                                 attitude=icfg.attitude_noise_std), sf, S_IMU_ROW)
        dcfg = self._cfg.dvl
        # the dropout column stays a standard normal
        self._dvl_noise = _Noise(np.random.default_rng(dvl_ss), _scale(DVL_NOISE, velocity=dcfg.noise_std, dropout=1.0),
                                 sf, S_DVL_ROW)
        pcfg = self._cfg.pressure
        self._p_noise = _Noise(np.random.default_rng(p_ss), _scale(PRESSURE_NOISE, pressure=pcfg.noise_std_pa),
                               sf, S_P_ROW)
        rates = (icfg.rate, pcfg.rate, dcfg.rate, self._servo.feedback_rate)
        for i, rate in enumerate(rates):
            sf[S_T0 + i] = t0
            sf[S_PERIOD + i] = 1.0 / rate
            sf[S_K + i] = 0.0
        sf[S_NEXT] = t0
        sf[S_COUNTS] = self._servo.units.quadcounts_per_rad
        sf[S_RATE_STEP] = self._servo.units.rate_quantum
        sf[S_RHO], sf[S_SPAN] = pcfg.water_density, pcfg.span_pa
        sf[S_ADC_BITS], sf[S_ADC_FS] = pcfg.adc_bits, pcfg.adc_full_scale_ma
        sf[S_DVL_STD], sf[S_DROPOUT] = dcfg.noise_std, dcfg.dropout_probability
        sf[S_ALT_MIN], sf[S_ALT_MAX], sf[S_BOTTOM] = dcfg.altitude_min, dcfg.altitude_max, dcfg.bottom_depth
        self._last_t = -math.inf

    @property
    def gyro_bias(self) -> np.ndarray:
        return self.state[SUITE.span("gyro_bias")].copy()

    @property
    def accel_bias(self) -> np.ndarray:
        return self.state[SUITE.span("accel_bias")].copy()

    def next_due(self) -> float:
        """Earliest time at which some sensor has a sample due."""
        return float(self.state[S_NEXT])

    def noise(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The IMU's, the pressure sensor's and the DVL's noise blocks for the next compiled
        sample (a new block for each one used up)."""
        return self._imu_noise.rows(), self._p_noise.rows(), self._dvl_noise.rows()

    def imu_noise(self) -> np.ndarray:
        """The IMU's noise block for the next compiled sample."""
        return self._imu_noise.rows()

    def kernel_arrays(self) -> tuple[np.ndarray, ...]:
        """The arrays compiled sampling takes (``plant.sample_plant`` after ``t``): the state,
        the IMU's outputs, the noise blocks (new ones for those used up), the rows."""
        imu, p, dvl = self.noise()
        return self.state, self.out, imu, p, dvl, self.rows

    def noise_used_up(self) -> bool:
        """Whether a noise block has no row left (:meth:`kernel_arrays` gives new ones)."""
        sf = self.state
        return bool(sf[S_IMU_ROW] >= self._imu_noise.buf.shape[0] or sf[S_P_ROW] >= self._p_noise.buf.shape[0]
                    or sf[S_DVL_ROW] >= self._dvl_noise.buf.shape[0])

    def sample(
        self, t: float, xv: np.ndarray, fin_theta: np.ndarray, fin_omega: np.ndarray
    ) -> list[Reading]:
        """Readings due at time ``t`` from the true state (vehicle state ``xv``, fin angles/rates)."""
        if not math.isfinite(t):
            raise ValueError(f"t: sensor time must be finite, got {t!r}")
        if t < self._last_t:
            raise ValueError(f"t: sensor time went backwards ({t} < {self._last_t})")
        self._last_t = t
        mask = sense(xv, fin_theta, fin_omega, t, self.state, self.imu_noise(), self.out)
        return self.readings(mask, t, xv) if mask else []

    def readings(self, mask: int, t: float, xv: np.ndarray) -> list[Reading]:
        """The readings of the sensors in ``mask`` (from :func:`sense` at ``t``), in the order
        IMU, pressure, DVL, encoders."""
        self._last_t = t
        _, p_noise, dvl_noise = self.noise()
        n = sample_rows(mask, t, xv, self.state, self.out, p_noise, dvl_noise, self.rows, 0)
        return [rr.from_row(self.rows[k]) for k in range(n)]
