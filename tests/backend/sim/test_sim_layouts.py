"""The simulator's arrays have declared layouts: each tiles its row, the arrays the plant
makes are as wide as their layouts, and the fields hold what their names say."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ucat_console.backend.sim import fin_hydro, plant, plate, sensors, vehicle
from ucat_console.backend.sim.params import FinHydroConfig, PlantConfig, VehicleConfig
from ucat_console.backend.sim.plant import Plant
from ucat_console.robot.fins import N_FINS
from ucat_console.robot.layout import Layout
from ucat_console.robot.units import GRAVITY

LAYOUTS = [vehicle.STATE, vehicle.PARAMS, vehicle.WORK, plate.PLATE, fin_hydro.HYDRO, fin_hydro.SIGNS,
           plant.FIN_STATE, plant.COMMAND, plant.SERVO, plant.MATRICES, plant.COUNT, sensors.IMU_OUT,
           sensors.IMU_NOISE, sensors.DVL_NOISE, sensors.PRESSURE_NOISE, sensors.SUITE, sensors.OUTPUT]


@pytest.mark.parametrize("lay", LAYOUTS, ids=lambda lay: lay.name)
def test_each_table_tiles_its_row(lay: Layout) -> None:
    cols: list[int] = []
    for f in lay.fields:
        cols += list(range(lay.span(f).start, lay.span(f).stop))
        assert lay.doc[f]
    assert cols == list(range(lay.size))


def test_the_plants_arrays_are_as_wide_as_their_layouts() -> None:
    p = Plant()
    xv, xf, cmd, mats, pv, ph, signs, servo, steps = p.kernel_arrays()
    assert xv.shape == (vehicle.STATE.size,) and xf.shape == (N_FINS, plant.FIN_STATE.size)
    assert cmd.shape == (N_FINS, plant.COMMAND.size) and mats.shape == (plant.MATRICES.size, 6, 6)
    assert pv.shape == (vehicle.PARAMS.size,) and ph.shape == (fin_hydro.HYDRO.size,)
    assert signs.shape == (N_FINS, fin_hydro.SIGNS.size) and servo.shape == (plant.SERVO.size,)
    assert steps.shape == (plant.COUNT.size,)
    state, out, imu, p_noise, dvl, _ = p.sensors.kernel_arrays()
    assert state.shape == (sensors.SUITE.size,) and out.shape == (sensors.OUTPUT.size,)
    assert imu.shape[1] == sensors.IMU_NOISE.size and dvl.shape[1] == sensors.DVL_NOISE.size
    assert p_noise.shape[1] == sensors.PRESSURE_NOISE.size
    # the drive's constants fill the hydro vector's drive fields, in FinMotor.constants()'s order
    motor = PlantConfig().motor
    assert tuple(ph[fin_hydro.H_MOTOR:]) == motor.constants()
    assert ph[fin_hydro.HYDRO.at("gear_ratio")] == motor.gear_ratio
    assert ph[fin_hydro.HYDRO.at("quiescent_power")] == motor.quiescent_power


def test_the_fields_hold_what_their_names_say() -> None:
    cfg = PlantConfig(vehicle=VehicleConfig(buoyancy_ratio=1.1, current_ned=(0.1, 0.2, 0.0)),
                      hydro=FinHydroConfig(model="still_water"), dt=0.0005)
    p = Plant(cfg)
    p.reset(position_ned=(1.0, 2.0, 3.0), fin_angles=(0.1, 0.2, 0.3, 0.4))
    p.command_fin(2, 1.0, 4.0)
    p.set_body_wrench((0.0, 0.0, 0.0), (0.0, 0.0, 0.5))
    xv, xf, cmd, mats, pv, ph, signs, servo, steps = p.kernel_arrays()
    assert tuple(xv[vehicle.STATE.span("pos")]) == (1.0, 2.0, 3.0)
    assert tuple(xv[vehicle.STATE.span("quat")]) == (1.0, 0.0, 0.0, 0.0)
    assert pv[vehicle.P_B] == pytest.approx(1.1 * pv[vehicle.P_W]) and pv[vehicle.P_W] == cfg.vehicle.mass * GRAVITY
    assert tuple(pv[vehicle.PARAMS.span("current")]) == (0.1, 0.2, 0.0)
    assert pv[vehicle.PARAMS.span("tau_ext")][5] == 0.5
    assert tuple(xf[:, plant.F_THETA]) == (0.1, 0.2, 0.3, 0.4)
    assert cmd[2, plant.C_TARGET] == 1.0 and cmd[2, plant.C_PROFILE_VELOCITY] == 4.0
    assert servo[plant.S_DT] == 0.0005 and servo[plant.S_MAX_RATE] == cfg.servo.max_rate
    assert np.array_equal(mats[plant.M_INV], np.linalg.inv(mats[plant.M_RB] + mats[plant.M_A]))
    assert ph[fin_hydro.H_PLATE + plate.P_NULL] == 1.0
    assert ph[fin_hydro.H_COS_A] == math.cos(math.radians(cfg.fins.mounting_angle_deg))
    assert tuple(signs[0]) == (signs[0, fin_hydro.SG_LAT], signs[0, fin_hydro.SG_LONG], signs[0, fin_hydro.SG_Y])
    p.advance(0.01)
    assert steps[plant.K_STEPS] == 20 and p.time == pytest.approx(0.01)
    assert tuple(xf[:, plant.F_THETA]) == p.fin_angles() and xf[2, plant.F_ENERGY] > 0.0


def test_the_noise_blocks_are_scaled_per_field() -> None:
    cfg = PlantConfig()
    suite = Plant(cfg).sensors
    imu, p_noise, dvl = suite.noise()
    # a column's spread is its field's standard deviation (512 draws: within 25 %)
    icfg, dcfg = cfg.sensors.imu, cfg.sensors.dvl
    for field, std in (("accel", icfg.accel_noise_std), ("gyro", icfg.gyro_noise_std),
                       ("attitude", icfg.attitude_noise_std)):
        assert np.std(imu[:, sensors.IMU_NOISE.span(field)]) == pytest.approx(std, rel=0.25)
    assert np.std(dvl[:, sensors.D_VELOCITY]) == pytest.approx(dcfg.noise_std, rel=0.25)
    assert np.std(dvl[:, sensors.D_DROPOUT]) == pytest.approx(1.0, rel=0.25)
    assert np.std(p_noise[:, sensors.R_PRESSURE]) == pytest.approx(cfg.sensors.pressure.noise_std_pa, rel=0.25)
