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
  pressure driver uses too).
* IMU (3DM-CX5): gyro = body rate + constant bias + noise; accel in g = specific force
  (a - g) / g0 in the body frame (level and at rest: (0, 0, -1)) + bias + noise; attitude
  = the true quaternion turned by a small random rotation, with its ZYX Euler angles.
* Encoders: fin angle and rate quantised as the EPOS2 reports them (``robot.servo``), at the
  feedback (PDO) rate.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ucat_console.backend.sim.params import PressureModelConfig, SensorsConfig, ServoConfig
from ucat_console.backend.sim.vehicle import NU, NU_DOT, POS, QUAT
from ucat_console.robot.fins import N_FINS
from ucat_console.robot.readings import DepthReading, DvlVelocity, FinFeedbacks, ImuReading, Reading
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


def current_from_pressure(gauge_pa: float, cfg: PressureModelConfig) -> float:
    """Loop current (mA) of the transducer at a gauge pressure, saturating at the NE 43 limits."""
    i = pressure_to_current(gauge_pa, 0.0, cfg.span_pa)
    return min(max(i, LOOP_MIN_MA), LOOP_MAX_MA)


def adc_quantise(current_ma: float, cfg: PressureModelConfig) -> float:
    """The current the ADC reports: a whole code of ``adc_bits`` over 0..full scale."""
    full = (1 << cfg.adc_bits) - 1
    code = min(max(round(current_ma / cfg.adc_full_scale_ma * full), 0), full)
    return code * cfg.adc_full_scale_ma / full


@njit(cache=True)
def imu_kernel(
    xv: np.ndarray, noise: np.ndarray, gyro_bias: np.ndarray, accel_bias: np.ndarray, out: np.ndarray
) -> None:
    """IMU outputs from the true state into ``out`` (13): accel in g (3), gyro (3), q (4), euler (3).

    ``noise`` (9) holds the scaled accel, gyro and attitude noise of this sample.
    """
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
    out[0] = ax / GRAVITY - g0x + accel_bias[0] + noise[0]
    out[1] = ay / GRAVITY - g0y + accel_bias[1] + noise[1]
    out[2] = az / GRAVITY - g0z + accel_bias[2] + noise[2]
    out[3] = p + gyro_bias[0] + noise[3]
    out[4] = q + gyro_bias[1] + noise[4]
    out[5] = r + gyro_bias[2] + noise[5]
    # attitude: q (x) exp(n / 2)
    nx, ny, nz = noise[6], noise[7], noise[8]
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
    out[6] = qw
    out[7] = qx
    out[8] = qy
    out[9] = qz
    out[10], out[11], out[12] = quat_to_euler(qw, qx, qy, qz)


# which sensor (schedule index), and its bit in a sample mask
IMU, PRESSURE, DVL, FINS = 0, 1, 2, 3
# the suite's numbers, one array for the compiled sampler: per sensor its schedule (first
# sample time, period, samples taken), the earliest due time, the IMU's biases, the
# encoders' resolution, and the next row of the IMU noise block
S_T0 = 0
S_PERIOD = 4
S_K = 8
S_NEXT = 12
S_GYRO_BIAS = 13
S_ACCEL_BIAS = 16
S_COUNTS = 19
S_RATE_STEP = 20
S_IMU_ROW = 21
NS = 22
# the sampler's output: the IMU (accel 3, gyro 3, q 4, euler 3), then fin angles and rates
O_IMU = 0
O_FIN_POS = 13
O_FIN_VEL = 17
NO = 21


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
                   out[O_IMU:O_IMU + 13])
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
    for i in range(4):
        due = sf[S_T0 + i] + sf[S_K + i] * sf[S_PERIOD + i]
        if due < nxt:
            nxt = due
    sf[S_NEXT] = nxt
    return mask


class _Noise:
    """Rows of scaled standard normals drawn from one Generator in blocks, used in order."""

    def __init__(self, rng: np.random.Generator, scale: list[float], block: int = 512) -> None:
        self._rng = rng
        self._scale = np.asarray(scale, dtype=float)
        self._block = block
        self._i = block
        self.buf = np.empty((0, len(scale)))

    def refill(self) -> None:
        self.buf = self._rng.standard_normal((self._block, len(self._scale))) * self._scale
        self._i = 0

    def next_list(self) -> list[float]:
        if self._i >= self._block:
            self.refill()
        row = self.buf[self._i].tolist()
        self._i += 1
        return row


class SensorSuite:
    """All sensors of the plant; :meth:`sample` returns the readings due at a time.

    The IMU and the encoders, sampled at 100 Hz, are the compiled :func:`sense` (the plant
    calls it in the same compiled call as its physics); the pressure sensor and the DVL,
    at 20 and 8 Hz, are made here from its mask."""

    def __init__(self, cfg: SensorsConfig, servo: ServoConfig, seed: int) -> None:
        self._cfg = cfg
        self._servo = servo
        self.state = np.zeros(NS)
        self.out = np.zeros(NO)
        self.reset(seed)

    def reset(self, seed: int, t0: float = 0.0) -> None:
        """New noise streams and biases from ``seed``; the first samples are due at ``t0``."""
        imu_ss, dvl_ss, p_ss = np.random.SeedSequence(seed).spawn(3)
        rng_imu = np.random.default_rng(imu_ss)
        icfg = self._cfg.imu
        sf = self.state
        sf[S_GYRO_BIAS:S_GYRO_BIAS + 3] = rng_imu.normal(0.0, icfg.gyro_bias_std, 3)
        sf[S_ACCEL_BIAS:S_ACCEL_BIAS + 3] = rng_imu.normal(0.0, icfg.accel_bias_std, 3)
        self._imu_noise = _Noise(
            rng_imu, [icfg.accel_noise_std] * 3 + [icfg.gyro_noise_std] * 3 + [icfg.attitude_noise_std] * 3
        )
        self._imu_noise.refill()
        sf[S_IMU_ROW] = 0.0
        dcfg = self._cfg.dvl
        # the fourth column stays a standard normal: it decides dropouts
        self._dvl_noise = _Noise(np.random.default_rng(dvl_ss), [dcfg.noise_std] * 3 + [1.0])
        self._p_noise = _Noise(np.random.default_rng(p_ss), [self._cfg.pressure.noise_std_pa])
        rates = (icfg.rate, self._cfg.pressure.rate, self._cfg.dvl.rate, self._servo.feedback_rate)
        for i, rate in enumerate(rates):
            sf[S_T0 + i] = t0
            sf[S_PERIOD + i] = 1.0 / rate
            sf[S_K + i] = 0.0
        sf[S_NEXT] = t0
        sf[S_COUNTS] = self._servo.units.quadcounts_per_rad
        sf[S_RATE_STEP] = self._servo.units.rate_quantum
        self._last_t = -math.inf

    @property
    def gyro_bias(self) -> np.ndarray:
        return self.state[S_GYRO_BIAS:S_GYRO_BIAS + 3].copy()

    @property
    def accel_bias(self) -> np.ndarray:
        return self.state[S_ACCEL_BIAS:S_ACCEL_BIAS + 3].copy()

    def next_due(self) -> float:
        """Earliest time at which some sensor has a sample due."""
        return float(self.state[S_NEXT])

    def imu_noise(self) -> np.ndarray:
        """The IMU's noise block for the next compiled sample (a new block once one is used up)."""
        if self.state[S_IMU_ROW] >= self._imu_noise.buf.shape[0]:
            self._imu_noise.refill()
            self.state[S_IMU_ROW] = 0.0
        return self._imu_noise.buf

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
        out: list[Reading] = []
        o = self.out
        if mask & (1 << IMU):
            v = o[O_IMU:O_IMU + 13].tolist()
            out.append(ImuReading(t, (v[0], v[1], v[2]), (v[3], v[4], v[5]), (v[6], v[7], v[8], v[9]),
                                  (v[10], v[11], v[12])))
        if mask & (1 << PRESSURE):
            out.append(self._depth_reading(t, xv))
        if mask & (1 << DVL):
            out.append(self._dvl_reading(t, xv))
        if mask & (1 << FINS):
            fb = o[O_FIN_POS:O_FIN_VEL + N_FINS].copy()
            fb.flags.writeable = False
            out.append(FinFeedbacks(t, fb[:N_FINS], fb[N_FINS:]))
        return out

    def _depth_reading(self, t: float, xv: np.ndarray) -> DepthReading:
        c = self._cfg.pressure
        gauge = depth_to_pressure(float(xv[POS + 2]), 0.0, c.water_density)
        gauge += self._p_noise.next_list()[0]
        measured = current_to_pressure(adc_quantise(current_from_pressure(gauge, c), c), 0.0, c.span_pa)
        return DepthReading(
            t=t, depth_m=pressure_to_depth(measured, 0.0, c.water_density), pressure_pa=measured
        )

    def _dvl_reading(self, t: float, xv: np.ndarray) -> DvlVelocity:
        c = self._cfg.dvl
        n = self._dvl_noise.next_list()  # drawn every time: the stream ignores validity
        drop = 0.5 * math.erfc(-n[3] / math.sqrt(2.0)) < c.dropout_probability  # uniform via the normal CDF
        altitude = c.bottom_depth - float(xv[POS + 2])
        in_range = c.altitude_min <= altitude <= c.altitude_max
        if not in_range or drop:
            return DvlVelocity(
                t=t,
                vx=math.nan,
                vy=math.nan,
                vz=math.nan,
                valid=False,
                altitude=altitude if in_range else math.nan,
                fom=math.nan,
            )
        return DvlVelocity(
            t=t,
            vx=float(xv[NU]) + n[0],
            vy=float(xv[NU + 1]) + n[1],
            vz=float(xv[NU + 2]) + n[2],
            valid=True,
            altitude=altitude,
            fom=c.noise_std,
        )
