"""Sensor models: rates, noise statistics, dropouts, conversions, determinism."""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest

from ucat_console.backend.sim.params import (
    DvlModelConfig,
    ImuModelConfig,
    PlantConfig,
    PressureModelConfig,
    SensorsConfig,
    ServoConfig,
)
from ucat_console.backend.sim.plant import Plant
from ucat_console.backend.sim.sensors import (
    SensorSuite,
    adc_quantise,
    current_from_pressure,
)
from ucat_console.backend.sim.vehicle import initial_state
from ucat_console.robot.readings import DepthReading, DvlVelocity, FinFeedbacks, ImuReading
from ucat_console.robot.rotations import quaternion_from_euler

G0 = 9.80665
ZERO4 = np.zeros(4)


def _collect(suite: SensorSuite, xv: np.ndarray, seconds: float, step: float = 0.001) -> list:
    out = []
    for k in range(round(seconds / step)):
        out.extend(suite.sample(k * step, xv, ZERO4, ZERO4))
    return out


def test_rates_over_two_seconds() -> None:
    p = Plant()
    p.reset(position_ned=(0.0, 0.0, 1.0))
    readings = []
    for _ in range(2000):
        readings.extend(p.sample_sensors())
        p.advance(0.001)
    counts = Counter(type(r) for r in readings)
    assert counts[ImuReading] == 200  # 100 Hz
    assert counts[DvlVelocity] == 16  # 8 Hz
    assert counts[DepthReading] == 40  # 20 Hz
    assert counts[FinFeedbacks] == 200  # 100 Hz, every fin
    assert all(r.position_rad.shape == (4,) for r in readings if isinstance(r, FinFeedbacks))
    imu_t = np.array([r.t for r in readings if isinstance(r, ImuReading)])
    assert np.diff(imu_t) == pytest.approx(0.01)


def test_next_sensor_time_lands_on_samples() -> None:
    cfg = PlantConfig(sensors=SensorsConfig(dvl=DvlModelConfig(rate=15.0)))
    p = Plant(cfg)
    dvl_t = []
    while p.time < 1.0:
        p.advance_to(p.next_sensor_time())
        dvl_t += [r.t for r in p.sample_sensors() if isinstance(r, DvlVelocity)]
    assert len(dvl_t) == 16  # 0, 1/15, ..., 15/15
    # 1 kHz physics: each DVL sample comes at the first step at or after its due time
    assert all(0.0 <= t - k / 15.0 < 0.001 + 1e-9 for k, t in enumerate(dvl_t))


def test_noise_statistics_at_rest() -> None:
    cfg = SensorsConfig(
        imu=ImuModelConfig(gyro_noise_std=0.01, accel_noise_std=0.02, attitude_noise_std=0.005),
        dvl=DvlModelConfig(rate=15.0, noise_std=0.01, dropout_probability=0.0),
        pressure=PressureModelConfig(rate=100.0, noise_std_pa=50.0),
    )
    suite = SensorSuite(cfg, ServoConfig(), seed=3)
    xv = initial_state((0.0, 0.0, 2.0))
    readings = _collect(suite, xv, 40.0, step=0.01 / 3)
    imu = [r for r in readings if isinstance(r, ImuReading)]
    dvl = [r for r in readings if isinstance(r, DvlVelocity)]
    dep = [r for r in readings if isinstance(r, DepthReading)]
    assert len(imu) == 4000 and len(dvl) == 600 and len(dep) == 4000
    gyro = np.array([r.gyro for r in imu])
    accel = np.array([r.accel for r in imu]) / 9.80665  # in standard gravities, as the noise is given
    assert gyro.std(axis=0) == pytest.approx([0.01] * 3, rel=0.08)
    assert gyro.mean(axis=0) == pytest.approx(suite.gyro_bias, abs=4 * 0.01 / math.sqrt(4000))
    assert accel.std(axis=0) == pytest.approx([0.02] * 3, rel=0.08)
    # level and at rest the accelerometer reads (0, 0, -1) g plus its bias
    assert accel.mean(axis=0) == pytest.approx(np.array([0, 0, -1.0]) + suite.accel_bias, abs=0.002)
    v = np.array([(r.vx, r.vy, r.vz) for r in dvl])
    assert all(r.valid for r in dvl)
    assert v.std(axis=0) == pytest.approx([0.01] * 3, rel=0.15)
    assert np.abs(v.mean(axis=0)).max() < 4 * 0.01 / math.sqrt(600)
    d = np.array([r.depth_m for r in dep])
    sd = 50.0 / (997.0 * G0)  # Pa -> m
    assert d.std() == pytest.approx(sd, rel=0.08)
    assert d.mean() == pytest.approx(2.0, abs=4 * sd / math.sqrt(4000) + 1e-4)
    roll = np.array([r.euler[0] for r in imu])
    assert roll.std() == pytest.approx(0.005, rel=0.1)


def test_accelerometer_sees_gravity_through_the_attitude() -> None:
    cfg = SensorsConfig(imu=ImuModelConfig(gyro_noise_std=0, gyro_bias_std=0, accel_noise_std=0, accel_bias_std=0, attitude_noise_std=0))
    suite = SensorSuite(cfg, ServoConfig(), seed=0)
    pitch, roll = 0.3, -0.2
    xv = initial_state((0.0, 0.0, 1.0), quaternion_from_euler(roll, pitch, 0.0), (0.0, 0.0, 0.0, 0.0, 0.0, 0.2))
    imu = [r for r in suite.sample(0.0, xv, ZERO4, ZERO4) if isinstance(r, ImuReading)][0]
    # specific force -g in body axes: g0 (sin p, -cos p sin r, -cos p cos r)
    expected = (math.sin(pitch), -math.cos(pitch) * math.sin(roll), -math.cos(pitch) * math.cos(roll))
    assert imu.accel == pytest.approx(tuple(9.80665 * e for e in expected), abs=1e-11)  # m/s^2
    assert imu.gyro == pytest.approx((0.0, 0.0, 0.2))
    assert imu.euler == pytest.approx((roll, pitch, 0.0), abs=1e-12)


def test_dvl_out_of_range_is_invalid_not_zero() -> None:
    cfg = SensorsConfig(dvl=DvlModelConfig(bottom_depth=1.0, dropout_probability=0.0))
    suite = SensorSuite(cfg, ServoConfig(), seed=0)
    xv = initial_state((0.0, 0.0, 2.0), body_velocity=(0.3, 0, 0, 0, 0, 0))  # below the bottom
    dvl = [r for r in _collect(suite, xv, 1.0) if isinstance(r, DvlVelocity)]
    assert len(dvl) == 8
    for r in dvl:
        assert r.valid is False
        assert math.isnan(r.vx) and math.isnan(r.vy) and math.isnan(r.vz)
        assert math.isnan(r.altitude)


def test_dvl_random_dropouts() -> None:
    cfg = SensorsConfig(dvl=DvlModelConfig(rate=15.0, dropout_probability=0.3))
    suite = SensorSuite(cfg, ServoConfig(), seed=11)
    xv = initial_state((0.0, 0.0, 1.0), body_velocity=(0.3, 0, 0, 0, 0, 0))
    dvl = [r for r in _collect(suite, xv, 100.0, step=1 / 15) if isinstance(r, DvlVelocity)]
    assert len(dvl) == 1500
    bad = [r for r in dvl if not r.valid]
    # binomial(1500, 0.3): mean 450, sd 17.7
    assert abs(len(bad) - 450) < 4 * 17.7
    assert all(math.isnan(r.vx) and r.altitude == pytest.approx(9.0) for r in bad)
    good = [r for r in dvl if r.valid]
    assert np.mean([r.vx for r in good]) == pytest.approx(0.3, abs=0.002)


def test_pressure_chain_current_saturation_and_adc() -> None:
    cfg = PressureModelConfig()  # span 250 kPa over 4-20 mA
    assert current_from_pressure(0.0, cfg) == pytest.approx(4.0)
    assert current_from_pressure(125_000.0, cfg) == pytest.approx(12.0)
    assert current_from_pressure(-1e5, cfg) == 3.8  # NE 43 saturation
    assert current_from_pressure(1e6, cfg) == 20.5
    step = 25.0 / (2**16 - 1)
    assert abs(adc_quantise(12.34567, cfg) - 12.34567) <= step / 2
    # noiseless chain: depth back to within one ADC step (in metres) of the truth
    quiet = SensorsConfig(pressure=PressureModelConfig(noise_std_pa=0.0))
    suite = SensorSuite(quiet, ServoConfig(), seed=0)
    dep = [r for r in suite.sample(0.0, initial_state((0.0, 0.0, 1.5)), ZERO4, ZERO4) if isinstance(r, DepthReading)][0]
    step_m = step / 16.0 * 250_000.0 / (997.0 * G0)
    assert abs(dep.depth_m - 1.5) <= step_m / 2 + 1e-12
    assert dep.pressure_pa == pytest.approx(997.0 * G0 * 1.5, abs=step / 16.0 * 250_000.0)


def test_sensor_time_must_not_go_backwards() -> None:
    suite = SensorSuite(SensorsConfig(), ServoConfig(), seed=0)
    xv = initial_state()
    suite.sample(1.0, xv, ZERO4, ZERO4)
    with pytest.raises(ValueError, match="backwards"):
        suite.sample(0.5, xv, ZERO4, ZERO4)
    with pytest.raises(ValueError, match="finite"):
        suite.sample(float("nan"), xv, ZERO4, ZERO4)


def _trace(seed: int) -> list:
    p = Plant(PlantConfig(seed=seed))
    p.reset(position_ned=(0.0, 0.0, 1.0))
    out = []
    for k in range(300):
        if k % 50 == 0:
            for i in range(4):
                p.command_fin(i, 0.5 if k % 100 == 0 else -0.5, 4.0)
        out.extend(p.sample_sensors())
        p.advance(0.005)
    return out


def _same(a: list, b: list) -> bool:
    def key(r: object) -> tuple:
        return tuple(str(v.tolist() if isinstance(v, np.ndarray) else v)  # str(nan) == str(nan)
                     for v in vars(r).values())

    return len(a) == len(b) and all(type(x) is type(y) and key(x) == key(y) for x, y in zip(a, b))


def test_deterministic_for_a_seed() -> None:
    a, b, c = _trace(5), _trace(5), _trace(6)
    assert _same(a, b)
    assert not _same(a, c)
    fins = [r for r in a if isinstance(r, FinFeedbacks)]
    assert any((r.velocity_rad_s != 0.0).any() for r in fins)


def test_the_compiled_encoders_report_what_robot_servo_quantise_says() -> None:
    """The sampler's encoders against the Python quantiser (halves rounded to even too)."""
    from ucat_console.robot.servo import quantise

    servo = ServoConfig()
    suite = SensorSuite(SensorsConfig(), servo, seed=0)
    k, q = servo.units.quadcounts_per_rad, servo.units.rate_quantum
    rng = np.random.default_rng(3)
    xv = initial_state()
    for n in range(300):
        theta = rng.normal(0.0, 3.0, 4)
        omega = rng.normal(0.0, 5.0, 4)
        if n % 3 == 0:  # exactly half a count / half a rate step
            theta[0] = (round(theta[0] * k) + 0.5) / k
            omega[1] = (round(omega[1] / q) + 0.5) * q
        fb = [r for r in suite.sample(n * 0.01, xv, theta, omega) if isinstance(r, FinFeedbacks)][0]
        for i in range(4):
            assert (fb.position_rad[i], fb.velocity_rad_s[i]) == quantise(theta[i], omega[i], k, q)


def test_the_compiled_pressure_and_dvl_readings_are_the_reference_ones() -> None:
    """The sensor rows the plant writes in compiled code (``sample_rows``) against the
    Python readings the simulator made before: the same depth, pressure, velocities,
    validity and altitude from the same true state and noise rows, over depths that take
    the DVL out of its range and with dropouts."""
    from control.reference_kernels import reference_depth, reference_dvl
    from ucat_console.backend.sim import sensors as S
    from ucat_console.robot import reading_rows as rr

    cfg = SensorsConfig(dvl=DvlModelConfig(dropout_probability=0.2, bottom_depth=3.0, altitude_max=2.5))
    suite = SensorSuite(cfg, ServoConfig(), seed=4)
    rng = np.random.default_rng(2)
    pc, dc = cfg.pressure, cfg.dvl
    mask = (1 << S.PRESSURE) | (1 << S.DVL)
    checked_invalid = 0
    for k in range(300):
        xv = initial_state((0.0, 0.0, float(rng.uniform(0.0, 2.9))), body_velocity=tuple(rng.normal(0, 0.3, 6)))
        _, p_noise, dvl_noise = suite.noise()
        ip, idv = int(suite.state[S.S_P_ROW]), int(suite.state[S.S_DVL_ROW])
        n_p, n_dvl = float(p_noise[ip, 0]), tuple(dvl_noise[idv].tolist())
        n = S.sample_rows(mask, 0.01 * k, xv, suite.state, suite.out, p_noise, dvl_noise, suite.rows, 0)
        assert n == 2
        depth, row = float(xv[2]), suite.rows
        assert (row[0, rr.DEPTH_M], row[0, rr.DEPTH_PA]) == reference_depth(
            depth, n_p, pc.water_density, pc.span_pa, pc.adc_bits, pc.adc_full_scale_ma)
        vx, vy, vz, valid, alt = reference_dvl(tuple(xv[7:10].tolist()), depth, n_dvl, dc.dropout_probability,
                                               dc.bottom_depth, dc.altitude_min, dc.altitude_max)
        got = row[1, rr.DVL_V:rr.DVL_V + 3].tolist() + [bool(row[1, rr.DVL_VALID]), row[1, rr.DVL_ALTITUDE]]
        np.testing.assert_array_equal(np.array(got[:3] + got[4:], dtype=float), np.array([vx, vy, vz, alt]))
        assert got[3] == valid
        checked_invalid += not valid
    assert 30 < checked_invalid < 270  # both kinds were compared
