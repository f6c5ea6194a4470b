"""Parameters of the simulated U-CAT (plant.md): the plant's own, never read by the controller.

One frozen dataclass per block, nested under :class:`PlantConfig`. Defaults come from the
TalTech eeUVsim U-CAT model (plant.md table; the numbers in ``robot/hull.py``) unless a field's
doc says otherwise.

Frames, fin order and fin planes are the robot's (``ucat_console.robot``: ``fins`` for the
order and signs, ``geometry`` for the fin planes, ``rotations`` for the attitude
quaternion): world NED, body FRD (Fossen), attitude the unit quaternion (w, x, y, z)
rotating body vectors into NED, fins in the robot's order. The sensor models' blocks are
named ``*ModelConfig``: the drivers' configuration of the same devices is another thing
(``backend/devices``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ucat_console.robot import geometry as G
from ucat_console.robot import hull as H
from ucat_console.robot.geometry import Geometry
from ucat_console.robot.motor import FinMotor
from ucat_console.robot.servo import FIN_ACCELERATION, FIN_MAX_RATE
from ucat_console.robot.units import RHO_FRESH, RHO_TABLE_I, DriveUnits
from ucat_console.typedconf import Config, param, require_below

#: Names of the fin coefficient sets (see :class:`FinHydroConfig`).
COEFFICIENT_SETS = ("paper", "eeuvsim", "custom")
#: the plant's fin models: the plate in the flow, and the still-water null plant
FIN_MODELS = ("plate", "still_water")


def _check_vec3(name: str, value: tuple[float, ...]) -> None:
    if len(value) != 3 or not all(
        isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value
    ):
        raise ValueError(f"{name}: expected three finite numbers, got {value!r}")


@dataclass(frozen=True)
class VehicleConfig(Config):
    """Rigid body and hull hydrodynamics (Fossen), plant.md 'Vehicle'.

    Inertias are about the centre of gravity (the CAD values); the dynamics move them to the
    body origin (the centre of buoyancy) with the parallel-axis theorem. Added-mass and
    damping coefficients use Fossen's signs (negative: resistive). The centre of gravity is
    given in the FRD body frame, z down: eeUVsim lists (0, 0, -0.1) m with restoring terms
    of the opposite sign to Fossen's, i.e. its CG lies 0.1 m *below* the CB; here that is
    (0, 0, +0.1).
    """

    mass: float = param(H.MASS, lo=0.0, hi=500.0, lo_open=True, unit="kg", doc="dry mass (paper Table II)")
    ixx: float = param(H.IXX, lo=0.0, hi=100.0, lo_open=True, unit="kg m2", doc="roll inertia about the CG")
    iyy: float = param(H.IYY, lo=0.0, hi=100.0, lo_open=True, unit="kg m2", doc="pitch inertia about the CG")
    izz: float = param(H.IZZ, lo=0.0, hi=100.0, lo_open=True, unit="kg m2", doc="yaw inertia about the CG")
    x_udot: float = param(H.X_UDOT, lo=-1000.0, hi=0.0, unit="kg", doc="added mass X_u'")
    y_vdot: float = param(H.Y_VDOT, lo=-1000.0, hi=0.0, unit="kg", doc="added mass Y_v'")
    z_wdot: float = param(H.Z_WDOT, lo=-1000.0, hi=0.0, unit="kg", doc="added mass Z_w'")
    k_pdot: float = param(H.K_PDOT, lo=-100.0, hi=0.0, unit="kg m2", doc="added inertia K_p'")
    m_qdot: float = param(H.M_QDOT, lo=-100.0, hi=0.0, unit="kg m2", doc="added inertia M_q'")
    n_rdot: float = param(H.N_RDOT, lo=-100.0, hi=0.0, unit="kg m2", doc="added inertia N_r'")
    x_u: float = param(H.X_U, lo=-1000.0, hi=0.0, unit="N s/m", doc="linear surge damping X_u")
    y_v: float = param(H.Y_V, lo=-1000.0, hi=0.0, unit="N s/m", doc="linear sway damping Y_v")
    z_w: float = param(H.Z_W, lo=-1000.0, hi=0.0, unit="N s/m", doc="linear heave damping Z_w")
    k_p: float = param(0.0, lo=-100.0, hi=0.0, unit="N m s", doc="linear roll damping K_p")
    m_q: float = param(0.0, lo=-100.0, hi=0.0, unit="N m s", doc="linear pitch damping M_q")
    n_r: float = param(H.N_R, lo=-100.0, hi=0.0, unit="N m s", doc="linear yaw damping N_r")
    x_uu: float = param(H.X_UU, lo=-1000.0, hi=0.0, unit="N s2/m2", doc="quadratic surge damping X_uu")
    y_vv: float = param(H.Y_VV, lo=-1000.0, hi=0.0, unit="N s2/m2", doc="quadratic sway damping Y_vv")
    z_ww: float = param(H.Z_WW, lo=-1000.0, hi=0.0, unit="N s2/m2", doc="quadratic heave damping Z_ww")
    k_pp: float = param(H.K_PP, lo=-100.0, hi=0.0, unit="N m s2", doc="quadratic roll damping K_pp")
    m_qq: float = param(H.M_QQ, lo=-100.0, hi=0.0, unit="N m s2", doc="quadratic pitch damping M_qq")
    n_rr: float = param(H.N_RR, lo=-100.0, hi=0.0, unit="N m s2", doc="quadratic yaw damping N_rr")
    cg: tuple[float, float, float] = param(H.CG, unit="m", doc="centre of gravity, body FRD")
    cb: tuple[float, float, float] = param(H.CB, unit="m", doc="centre of buoyancy, body FRD")
    buoyancy_ratio: float = param(
        1.0, lo=0.5, hi=1.5, doc="buoyancy / weight (1.0: neutral, the default)"
    )
    current_ned: tuple[float, float, float] = param(
        (0.0, 0.0, 0.0), unit="m/s", doc="constant water current, world NED"
    )
    disturbance_ned: tuple[float, float, float] = param(
        (0.0, 0.0, 0.0), unit="N", doc="constant disturbance force at the body origin, world NED"
    )
    hull_size: tuple[float, float, float] = param(
        G.HULL_SIZE, unit="m", doc="hull box length, width, height (3-D view only)"
    )

    def _check(self) -> None:
        for name in ("cg", "cb", "current_ned", "disturbance_ned", "hull_size"):
            _check_vec3(name, getattr(self, name))
        if min(self.hull_size) <= 0.0:
            raise ValueError(f"hull_size: sizes must be positive, got {self.hull_size!r}")


@dataclass(frozen=True)
class FinGeometryConfig(Config):
    """Where the fins' forces act (eeUVsim ``finDynamics``): mounting angle and moment arms.

    Roll and pitch moments come from each fin's vertical force times the roll/pitch arm,
    the yaw moment from its horizontal in-plane force times the yaw arm (the perpendicular
    distance of that force's line of action from the body origin).
    """

    mounting_angle_deg: float = param(
        G.MOUNTING_ANGLE_DEG, lo=0.0, hi=89.0, unit="deg", doc="fin plane's horizontal axis from the body x axis"
    )
    arm_roll: float = param(G.ARM_ROLL, lo=0.0, hi=2.0, unit="m", doc="roll moment arm of the vertical force")
    arm_pitch: float = param(G.ARM_PITCH, lo=0.0, hi=2.0, unit="m", doc="pitch moment arm of the vertical force")
    arm_yaw: float = param(G.ARM_YAW, lo=0.0, hi=2.0, unit="m", doc="yaw moment arm of the horizontal force")
    fin_inertia: float = param(
        H.FIN_INERTIA, lo=0.0, hi=1.0, unit="kg m2", doc="fin inertia about its axis (true shaft power)"
    )


@dataclass(frozen=True)
class FinCoefficients(Config):
    """A fin's still-water model, of the controller's quasi-steady form: a stroke at rate w
    makes drag ``rho C_D A v^2 / 2`` and lift ``rho C_L A v^2 / 2`` at ``v = r_c |w|``. The
    plant's plate is calibrated to it (``backend/sim/plate.py``): at zero speed it makes this
    model's mean force, and in a stream what its physics gives."""

    rho: float = param(RHO_TABLE_I, lo=1.0, hi=2000.0, lo_open=True, unit="kg/m3", doc="water density")
    c_d: float = param(0.70, lo=0.0, hi=20.0, lo_open=True, doc="drag coefficient C_D (the plate's normal force)")
    c_l: float = param(0.25, lo=0.0, hi=20.0, doc="lift coefficient C_L")
    area: float = param(G.FIN_AREA, lo=0.0, hi=1.0, lo_open=True, unit="m2", doc="fin planform area A_f")
    r_c: float = param(G.FIN_R_C, lo=0.0, hi=2.0, lo_open=True, unit="m", doc="radius of gyration r_c")
    fin_length: float = param(G.FIN_LENGTH, lo=0.0, hi=2.0, lo_open=True, unit="m", doc="fin length L_f (Strouhal)")

    def scaled(self, factor: float) -> FinCoefficients:
        """The same fin with ``factor`` times the coefficients: ``factor`` times the thrust per
        w^2, paid with ``factor`` times the shaft's load (E6's plant family)."""
        return self.replace(c_d=self.c_d * factor, c_l=self.c_l * factor)


#: The paper's coefficients (its Table I), identified on the U-CAT's fin in still water: the
#: default plant's calibration, and the controller's model.
PAPER_COEFFICIENTS = FinCoefficients()
#: eeUVsim's lift/drag values (model-mismatch case). A_f and r_c are not part of that set;
#: the paper's values are kept so only the coefficients, the length and rho differ.
EEUVSIM_COEFFICIENTS = FinCoefficients(rho=997.0, c_d=3.2, c_l=1.65, fin_length=0.18)

_PRESETS = {
    "paper": PAPER_COEFFICIENTS,
    "eeuvsim": EEUVSIM_COEFFICIENTS,
}


@dataclass(frozen=True)
class FinHydroConfig(Config):
    """The fins in the water (plant.md; docs/fin-plant.md): a plate hinged at its leading
    edge whose forces conserve energy (:mod:`ucat_console.backend.sim.plate`), calibrated to a
    still-water coefficient set.

    ``plate`` is the plant: its forces from the fin's motion through the water the hull moves
    through. ``still_water`` is the null plant of the experiments: the same plate as if the
    hull stood still, the work its force does on the hull paid through the shaft, so that how
    a force is made (the stroke's frequency, its Strouhal number) costs nothing more or less
    at any speed.
    """

    model: str = param("plate", choices=FIN_MODELS, doc="plate: the fin in the flow; still_water: the null plant")
    coefficients: str = param("paper", choices=COEFFICIENT_SETS,
                              doc="the still-water model the plate is calibrated to")
    custom: FinCoefficients = FinCoefficients()
    c_d0: float = param(
        0.05, lo=0.0, hi=2.0,
        doc="the plate's profile drag C_D0 (flow along it); part of its normal force C_D",
    )
    lift_ratio: float = param(
        0.6, lo=0.0, hi=2.0,
        doc="the plate's largest lift over its normal force, C_Lmax / C_N (Wang et al. 2004: 1.2 / 2.0)",
    )
    added_mass: float = param(
        1.0, lo=0.0, hi=2.0, doc="share of the plate's strip-theory added inertia on the shaft"
    )
    strips: int = param(8, lo=1, hi=64, doc="blade-element strips along the plate")
    v_floor: float = param(0.05, lo=0.001, hi=5.0, unit="m/s",
                           doc="speed floor of each fin's recorded Strouhal number (the plant never reads it)")
    tau_rate: float = param(
        0.3, lo=0.001, hi=10.0, unit="s", doc="time constant of each fin's mean |rate| for its recorded Strouhal number"
    )

    def _check(self) -> None:
        c = self.resolved()
        if self.c_d0 > c.c_d:
            raise ValueError(f"c_d0: the profile drag {self.c_d0} exceeds the plate's normal force C_D {c.c_d}")

    def resolved(self) -> FinCoefficients:
        """The coefficient set in use."""
        return self.custom if self.coefficients == "custom" else _PRESETS[self.coefficients]


@dataclass(frozen=True)
class ServoConfig(Config):
    """Fin servos in profile-position mode, as an EPOS2 runs them."""

    acceleration: float = param(
        FIN_ACCELERATION, lo=0.0, hi=10000.0, lo_open=True, unit="rad/s2", doc="profile acceleration = deceleration"
    )
    max_rate: float = param(FIN_MAX_RATE, lo=0.0, hi=200.0, lo_open=True, unit="rad/s", doc="maximum fin rate")
    units: DriveUnits = DriveUnits()  # encoder and gearhead (robot.units: the one default)
    feedback_rate: float = param(100.0, lo=1.0, hi=1000.0, unit="Hz", doc="encoder feedback (PDO) rate")


@dataclass(frozen=True)
class DvlModelConfig(Config):
    """Water Linked DVL A50: bottom-track velocity in the body frame."""

    rate: float = param(8.0, lo=2.0, hi=15.0, unit="Hz", doc="velocity report rate")
    noise_std: float = param(0.005, lo=0.0, hi=1.0, unit="m/s", doc="velocity noise per axis")
    dropout_probability: float = param(0.01, lo=0.0, hi=1.0, doc="chance a report is invalid in range")
    altitude_min: float = param(0.05, lo=0.0, hi=100.0, unit="m", doc="shortest valid altitude")
    altitude_max: float = param(50.0, lo=0.0, hi=1000.0, unit="m", doc="longest valid altitude")
    bottom_depth: float = param(
        10.0, lo=0.0, hi=10000.0, unit="m", doc="depth of the flat bottom (the paper's pool: 1.65)"
    )

    def _check(self) -> None:
        require_below(self, "altitude_min", "altitude_max")


@dataclass(frozen=True)
class PressureModelConfig(Config):
    """Gems 3101P 4-20 mA transducer read by an ADC (gauge pressure, zero at the surface)."""

    rate: float = param(20.0, lo=1.0, hi=1000.0, unit="Hz", doc="ADC reading rate")
    water_density: float = param(RHO_FRESH, lo=900.0, hi=1100.0, unit="kg/m3", doc="true water density")
    span_pa: float = param(250_000.0, lo=1000.0, hi=1e8, unit="Pa", doc="gauge pressure at 20 mA")
    noise_std_pa: float = param(20.0, lo=0.0, hi=1e5, unit="Pa", doc="transducer noise")
    adc_bits: int = param(16, lo=4, hi=32, doc="ADC resolution")
    adc_full_scale_ma: float = param(25.0, lo=20.0, hi=100.0, unit="mA", doc="ADC full-scale current")


@dataclass(frozen=True)
class ImuModelConfig(Config):
    """Microstrain 3DM-CX5: gyro, accelerometer and attitude (the accelerometer's noise and
    bias in standard gravities, g_n, as its data sheet gives them)."""

    rate: float = param(100.0, lo=1.0, hi=1000.0, unit="Hz", doc="sample rate")
    gyro_noise_std: float = param(0.001, lo=0.0, hi=1.0, unit="rad/s", doc="gyro white noise")
    gyro_bias_std: float = param(0.0005, lo=0.0, hi=1.0, unit="rad/s", doc="spread of the constant gyro bias")
    accel_noise_std: float = param(0.001, lo=0.0, hi=1.0, unit="g_n", doc="accelerometer white noise")
    accel_bias_std: float = param(0.002, lo=0.0, hi=1.0, unit="g_n", doc="spread of the constant accel bias")
    attitude_noise_std: float = param(0.002, lo=0.0, hi=1.0, unit="rad", doc="attitude noise per axis")


@dataclass(frozen=True)
class SensorsConfig(Config):
    dvl: DvlModelConfig = DvlModelConfig()
    pressure: PressureModelConfig = PressureModelConfig()
    imu: ImuModelConfig = ImuModelConfig()


@dataclass(frozen=True)
class PlantConfig(Config):
    """The simulated U-CAT."""

    vehicle: VehicleConfig = VehicleConfig()
    fins: FinGeometryConfig = FinGeometryConfig()
    hydro: FinHydroConfig = FinHydroConfig()
    servo: ServoConfig = ServoConfig()
    motor: FinMotor = FinMotor()  # each fin drive's motor, gearhead and bridge (robot.motor)
    sensors: SensorsConfig = SensorsConfig()
    dt: float = param(0.001, lo=1e-5, hi=0.001, unit="s", doc="physics time step (1 kHz or finer)")
    seed: int = param(0, lo=0, hi=2**63 - 1, doc="seed of the sensor noise")

    @property
    def geometry(self) -> Geometry:
        """The robot geometry this plant simulates (what the 3-D view draws)."""
        f = self.fins
        return Geometry(
            hull_size=self.vehicle.hull_size, fin_length=self.hydro.resolved().fin_length,
            mounting_angle_deg=f.mounting_angle_deg, arm_roll=f.arm_roll, arm_pitch=f.arm_pitch,
            arm_yaw=f.arm_yaw,
        )

