"""The simulated U-CAT: four fin servos, fin hydrodynamics, the 6-DOF hull and its sensors.

:class:`Plant` is the imperative shell the closed loop and the device emulators drive; under
it, :func:`advance_steps` is the functional core: one compiled call runs many physics steps
(state arrays in, state arrays out, nothing allocated in the loop). Each step:

1. every fin servo moves one step along its profile (``servo``) and the fin's mean |rate|
   (its recorded Strouhal number) is updated;
2. each fin's force, shaft torque and power, and power into the hull follow from its angle,
   rate and acceleration and the flow past it (``plate``, ``fin_hydro.fin_flow``); its drive's
   motor current and the battery power it draws from the shaft's torque (``robot.motor``);
   its force adds its wrench (``fin_hydro``);
3. the hull takes one semi-implicit Euler step (``vehicle``).

The plant never reads the controller's parameters; it has its own (``params``).
"""

from __future__ import annotations

import logging
import math
import time as _time

import numpy as np
from numba import njit

from ucat_console.backend.sim.fin_hydro import (
    H_ETA_B,
    H_ETA_G,
    H_I_0,
    H_J_R,
    H_K_T,
    H_N_G,
    H_P_Q,
    H_PLATE,
    H_R_M,
    H_TAU,
    SG_LAT,
    SG_LONG,
    SG_Y,
    add_fin_wrench,
    fin_flow,
    fin_sign_table,
    fin_strouhal,
    hydro_params,
)
from ucat_console.backend.sim.params import PlantConfig, VehicleConfig
from ucat_console.backend.sim.plate import NP, fin_load
from ucat_console.backend.sim.sensors import SensorSuite, sample_rows, sense
from ucat_console.backend.sim.vehicle import (
    NU,
    NWORK,
    NX,
    POS,
    QUAT,
    body_current,
    initial_state,
    vehicle_matrices,
    vehicle_params,
    vehicle_step,
)
from ucat_console.robot import reading_rows as rr
from ucat_console.robot.fins import N_FINS
from ucat_console.robot.layout import Layout
from ucat_console.robot.motor import battery_power, motor_current
from ucat_console.robot.readings import Reading
from ucat_console.robot.rotations import euler_from_quaternion, quat_to_rot, quaternion_from_euler
from ucat_console.robot.servo import encoder_reading, servo_step

log = logging.getLogger(__name__)

# the declared layouts of the plant's own arrays; their columns as constants (module globals,
# which the compiled functions take as constants)
FIN_STATE = Layout("a fin's state row (xf, one per fin)", [
    ("theta", 1, "angle (rad)"),
    ("omega", 1, "rate (rad/s)"),
    ("rate_mean", 1, "filtered |rate| (Strouhal)"),
    ("fx", 1, "last fin-frame force f_x (N)"),
    ("fy", 1, "last fin-frame force f_y (N)"),
    ("st", 1, "last Strouhal number"),
    ("useful", 1, "last power the fin delivered to the hull (W)"),
    ("alpha", 1, "last angular acceleration (rad/s2)"),
    ("power", 1, "last true shaft power (W), no regeneration"),
    ("energy", 1, "shaft energy since reset (J)"),
    ("impulse_x", 1, "time integral of the fin-frame force f_x since reset (N s)"),
    ("impulse_y", 1, "and of f_y"),
    ("work", 1, "work the fin did on the hull since reset (J)"),
    ("current", 1, "last motor current of its drive (A)"),
    ("battery", 1, "last battery power of its drive (W)"),
    ("battery_energy", 1, "battery energy of its drive since reset (J)"),
])
(F_THETA, F_OMEGA, F_RATE_MEAN, F_FX, F_FY, F_ST, F_USEFUL, F_ALPHA, F_POWER, F_ENERGY, F_IMPULSE_X,
 F_IMPULSE_Y, F_WORK, F_CURRENT, F_BATTERY, F_BATTERY_ENERGY) = (FIN_STATE.at(f) for f in FIN_STATE.fields)
NF = FIN_STATE.size

COMMAND = Layout("a fin's command row (cmd, one per fin)", [
    ("target", 1, "profile-position target angle (rad)"),
    ("profile_velocity", 1, "profile velocity (rad/s)"),
])
C_TARGET, C_PROFILE_VELOCITY = (COMMAND.at(f) for f in COMMAND.fields)

SERVO = Layout("the servos' constants (servo)", [
    ("acceleration", 1, "profile acceleration = deceleration (rad/s2)"),
    ("max_rate", 1, "maximum fin rate (rad/s)"),
    ("fin_inertia", 1, "fin inertia about its axis (kg m2)"),
    ("dt", 1, "physics time step (s)"),
])
S_ACCELERATION, S_MAX_RATE, S_FIN_INERTIA, S_DT = (SERVO.at(f) for f in SERVO.fields)

MATRICES = Layout("the hull's matrices (mats, each 6x6)", [
    ("m_rb", 1, "rigid-body inertia M_RB"), ("m_a", 1, "added mass M_A"), ("m_inv", 1, "(M_RB + M_A)^-1"),
])
M_RB, M_A, M_INV = (MATRICES.at(f) for f in MATRICES.fields)

COUNT = Layout("the plant's step count (steps)", [("steps", 1, "physics steps since the reset")])
K_STEPS = COUNT.at("steps")


@njit(cache=True)
def advance_steps(
    xv_in: np.ndarray,
    xf_in: np.ndarray,
    cmd: np.ndarray,
    mrb: np.ndarray,
    ma: np.ndarray,
    minv: np.ndarray,
    pv: np.ndarray,
    ph: np.ndarray,
    signs: np.ndarray,
    acceleration: float,
    max_rate: float,
    fin_inertia: float,
    dt: float,
    n_steps: int,
    xv_out: np.ndarray,
    xf_out: np.ndarray,
) -> bool:
    """Run ``n_steps`` physics steps from (xv_in, xf_in) into (xv_out, xf_out).

    The outputs may be the inputs themselves (the Plant steps in place). ``cmd`` holds each
    fin's target angle and profile velocity, held over the call. Returns False when the
    vehicle state is no longer finite.
    """
    for j in range(xv_in.shape[0]):
        xv_out[j] = xv_in[j]
    for i in range(xf_in.shape[0]):
        for j in range(xf_in.shape[1]):
            xf_out[i, j] = xf_in[i, j]
    r = np.empty((3, 3))
    work = np.empty(NWORK)
    tau = np.empty(6)
    nuc = np.empty(3)
    nu_r = np.empty(6)
    k_rate = dt / ph[H_TAU]
    pf = ph[H_PLATE:H_PLATE + NP]
    k_t, r_m, i_0, j_r = ph[H_K_T], ph[H_R_M], ph[H_I_0], ph[H_J_R]
    n_g, eta_g, eta_b, p_q = ph[H_N_G], ph[H_ETA_G], ph[H_ETA_B], ph[H_P_Q]
    for _ in range(n_steps):
        # 1. servos, mean |rate|
        for i in range(N_FINS):
            th, om, al = servo_step(
                xf_out[i, F_THETA], xf_out[i, F_OMEGA], cmd[i, C_TARGET], cmd[i, C_PROFILE_VELOCITY],
                acceleration, max_rate, dt,
            )
            xf_out[i, F_THETA] = th
            xf_out[i, F_OMEGA] = om
            xf_out[i, F_ALPHA] = al
            xf_out[i, F_RATE_MEAN] += (abs(om) - xf_out[i, F_RATE_MEAN]) * k_rate
        # 2. fin forces and powers -> body wrench
        quat_to_rot(xv_out[QUAT : QUAT + 4], r)
        body_current(r, pv, nuc)
        for j in range(6):
            nu_r[j] = xv_out[NU + j]
            tau[j] = 0.0
        for j in range(3):
            nu_r[j] -= nuc[j]
        for i in range(N_FINS):
            s_lat, s_long, s_y = signs[i, SG_LAT], signs[i, SG_LONG], signs[i, SG_Y]
            ux, uy = fin_flow(nu_r, s_lat, s_long, s_y, ph)
            om = xf_out[i, F_OMEGA]
            al = xf_out[i, F_ALPHA]
            fx, fy, torque, p, useful = fin_load(xf_out[i, F_THETA], om, al, ux, uy, fin_inertia, dt, pf)
            current = motor_current(torque, om, al, k_t, i_0, j_r, n_g, eta_g)
            battery = battery_power(current, om, k_t, r_m, n_g, eta_b, p_q)
            xf_out[i, F_CURRENT] = current
            xf_out[i, F_BATTERY] = battery
            xf_out[i, F_BATTERY_ENERGY] += battery * dt
            xf_out[i, F_FX] = fx
            xf_out[i, F_FY] = fy
            xf_out[i, F_POWER] = p
            xf_out[i, F_ENERGY] += p * dt
            xf_out[i, F_USEFUL] = useful
            xf_out[i, F_WORK] += useful * dt
            xf_out[i, F_IMPULSE_X] += fx * dt
            xf_out[i, F_IMPULSE_Y] += fy * dt
            xf_out[i, F_ST] = fin_strouhal(xf_out[i, F_RATE_MEAN], nu_r[0], ph)  # recorded; no force reads it
            add_fin_wrench(fx, fy, s_lat, s_long, s_y, ph, tau)
        # 3. hull
        vehicle_step(xv_out, tau, mrb, ma, minv, pv, dt, r, nuc, work)
    total = 0.0
    for j in range(xv_out.shape[0]):
        total += xv_out[j]
    return math.isfinite(total)


@njit(cache=True)
def advance_and_sense(xv: np.ndarray, xf: np.ndarray, cmd: np.ndarray, mats: np.ndarray, pv: np.ndarray,
                      ph: np.ndarray, signs: np.ndarray, servo: np.ndarray, n_steps: int, t: float,
                      sf: np.ndarray, imu_noise: np.ndarray, out: np.ndarray) -> int:
    """:func:`advance_steps` in place for ``n_steps`` (to time ``t``), then the sensors'
    samples due at ``t`` (``sensors.sense``): one compiled call per event of the loop.
    ``mats`` holds M_RB, M_A and M^-1, ``servo`` the acceleration, maximum rate, fin inertia
    and time step. Returns the sensors' mask, or -1 when the state is no longer finite."""
    if n_steps > 0:
        ok = advance_steps(xv, xf, cmd, mats[M_RB], mats[M_A], mats[M_INV], pv, ph, signs, servo[S_ACCELERATION],
                           servo[S_MAX_RATE], servo[S_FIN_INERTIA], servo[S_DT], n_steps, xv, xf)
        if not ok:
            return -1
    return sense(xv, xf[:, F_THETA], xf[:, F_OMEGA], t, sf, imu_noise, out)


@njit(cache=True)
def sample_plant(xv: np.ndarray, xf: np.ndarray, cmd: np.ndarray, mats: np.ndarray, pv: np.ndarray, ph: np.ndarray,
                 signs: np.ndarray, servo: np.ndarray, steps: np.ndarray, t: float, sf: np.ndarray, out: np.ndarray,
                 imu_noise: np.ndarray, p_noise: np.ndarray, dvl_noise: np.ndarray, rows: np.ndarray) -> int:
    """Whole physics steps up to the first step at or after ``t`` (``steps`` counts
    them), then the readings due there as rows (``robot.reading_rows``) into ``rows``: their
    number, or -1 when the state is no longer finite. The noise blocks must each have a row
    left (:meth:`SensorSuite.noise`)."""
    dt = servo[S_DT]
    n = max(0, math.ceil((t - steps[K_STEPS] * dt) / dt - 1e-6))
    t_after = (steps[K_STEPS] + n) * dt
    mask = advance_and_sense(xv, xf, cmd, mats, pv, ph, signs, servo, n, t_after, sf, imu_noise, out)
    steps[K_STEPS] += n
    if mask < 0:
        return -1
    if mask == 0:
        return 0
    return sample_rows(mask, t_after, xv, sf, out, p_noise, dvl_noise, rows, 0)


def _finite(name: str, values: tuple[float, ...] | list[float], n: int) -> tuple[float, ...]:
    try:
        out = tuple(float(v) for v in values)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected {n} numbers, got {values!r}") from None
    if len(out) != n or not all(math.isfinite(v) for v in out):
        raise ValueError(f"{name}: expected {n} finite numbers, got {values!r}")
    return out


class Plant:
    """The simulated U-CAT (plant.md). Deterministic for a given configuration and seed."""

    def __init__(self, cfg: PlantConfig | None = None) -> None:
        self._cfg = cfg if cfg is not None else PlantConfig()
        c = self._cfg
        self._mrb, self._ma, self._minv = vehicle_matrices(c.vehicle)
        self._mats = np.empty((MATRICES.size, 6, 6))
        self._mats[M_RB], self._mats[M_A], self._mats[M_INV] = self._mrb, self._ma, self._minv
        self._tau_ext = (0.0,) * 6
        self._pv = vehicle_params(c.vehicle, self._tau_ext)
        self._ph = hydro_params(c.hydro, c.fins, c.motor)
        self._signs = fin_sign_table()
        self._acc = float(c.servo.acceleration)
        self._max_rate = float(c.servo.max_rate)
        self._fin_inertia = float(c.fins.fin_inertia)
        self._servo_consts = np.empty(SERVO.size)
        self._servo_consts[S_ACCELERATION], self._servo_consts[S_MAX_RATE] = self._acc, self._max_rate
        self._servo_consts[S_FIN_INERTIA], self._servo_consts[S_DT] = self._fin_inertia, float(c.dt)
        self._sensors = SensorSuite(c.sensors, c.servo, c.seed)
        self._xv = np.zeros(NX)
        self._xf = np.zeros((N_FINS, NF))
        self._cmd = np.zeros((N_FINS, 2))
        self._step_count = np.zeros(COUNT.size, dtype=np.int64)  # physics steps since the reset
        self._t_goal = 0.0
        self.reset()

    # ------------------------------------------------------------------ setup
    @property
    def cfg(self) -> PlantConfig:
        return self._cfg

    @property
    def _steps(self) -> int:
        return int(self._step_count[K_STEPS])

    @property
    def time(self) -> float:
        """Simulated time (s) since the last reset: a whole number of physics steps."""
        return self._steps * self._cfg.dt

    def reset(
        self,
        position_ned: tuple[float, float, float] = (0.0, 0.0, 0.0),
        euler: tuple[float, float, float] = (0.0, 0.0, 0.0),
        quaternion: tuple[float, float, float, float] | None = None,
        body_velocity: tuple[float, ...] = (0.0,) * 6,
        fin_angles: tuple[float, ...] = (0.0,) * N_FINS,
        seed: int | None = None,
    ) -> None:
        """Start again at time 0: pose, body velocity, fins at rest holding ``fin_angles``.

        The sensor noise restarts from ``seed`` (default: the configured seed); the extra body
        wrench of :meth:`set_body_wrench` is kept.
        """
        if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int) or seed < 0):
            raise ValueError(f"seed: expected a non-negative integer, got {seed!r}")
        if quaternion is None:
            r, p, y = _finite("euler", euler, 3)
            quaternion = quaternion_from_euler(r, p, y)
        self._xv[:] = initial_state(position_ned, quaternion, body_velocity)
        angles = _finite("fin_angles", fin_angles, N_FINS)
        self._xf[:, :] = 0.0
        self._xf[:, F_THETA] = angles
        self._cmd[:, C_TARGET] = angles
        self._cmd[:, C_PROFILE_VELOCITY] = self._cfg.servo.max_rate
        self._step_count[K_STEPS] = 0
        self._t_goal = 0.0
        self._sensors.reset(self._cfg.seed if seed is None else seed)

    # --------------------------------------------------------------- commands
    def command_fin(self, i: int, target_rad: float, profile_velocity_rad_s: float) -> None:
        """New profile-position set-point for fin ``i`` (acts at once, as 'change set immediately')."""
        if not isinstance(i, (int, np.integer)) or not 0 <= i < N_FINS:
            raise ValueError(f"fin: {i!r} is not a plant fin index 0..3")
        if not math.isfinite(target_rad):
            raise ValueError(f"target_rad: fin {i} target must be finite, got {target_rad!r}")
        if not math.isfinite(profile_velocity_rad_s) or profile_velocity_rad_s <= 0.0:
            raise ValueError(
                f"profile_velocity_rad_s: fin {i} needs a positive finite profile velocity, "
                f"got {profile_velocity_rad_s!r}"
            )
        v = min(profile_velocity_rad_s, self._cfg.servo.max_rate)
        if v < profile_velocity_rad_s:
            log.debug("fin %d: profile velocity %.3f clipped to %.3f rad/s", i, profile_velocity_rad_s, v)
        self._cmd[i, C_TARGET] = target_rad
        self._cmd[i, C_PROFILE_VELOCITY] = v

    def set_body_wrench(
        self, force: tuple[float, float, float] = (0.0, 0.0, 0.0), moment: tuple[float, float, float] = (0.0, 0.0, 0.0)
    ) -> None:
        """A constant extra wrench at the body origin, body frame (tests and experiments)."""
        self._tau_ext = _finite("force", force, 3) + _finite("moment", moment, 3)
        self._pv = vehicle_params(self._cfg.vehicle, self._tau_ext)

    def change_vehicle(self, vehicle: VehicleConfig) -> None:
        """The hull becomes ``vehicle`` from the next step on (a robot that changes while it
        runs: added drag, added mass, a current); the state and the fins are kept. The arrays
        a compiled caller holds (:meth:`kernel_arrays`) are updated in place."""
        if not isinstance(vehicle, VehicleConfig):
            raise ValueError(f"vehicle: expected a VehicleConfig, got {type(vehicle).__name__}")
        mrb, ma, minv = vehicle_matrices(vehicle)
        pv = vehicle_params(vehicle, self._tau_ext)
        self._cfg = self._cfg.replace(vehicle=vehicle)
        self._mrb[...], self._ma[...], self._minv[...] = mrb, ma, minv
        self._mats[M_RB], self._mats[M_A], self._mats[M_INV] = mrb, ma, minv
        self._pv[...] = pv

    # ---------------------------------------------------------------- stepping
    def advance(self, duration_s: float) -> None:
        """Run the physics for ``duration_s``: whole steps, the remainder carries over to the
        next call, so the simulated time is the sum of the durations rounded down to a step."""
        if not math.isfinite(duration_s) or duration_s < 0.0:
            raise ValueError(f"duration_s: expected a finite non-negative duration, got {duration_s!r}")
        self._t_goal += duration_s
        self._run(math.floor((self._t_goal - self.time) / self._cfg.dt + 1e-6))

    def advance_to(self, t: float) -> None:
        """Run whole steps up to the first step at or after time ``t`` (e.g. the next sensor time)."""
        if not math.isfinite(t):
            raise ValueError(f"t: expected a finite time, got {t!r}")
        self._run(math.ceil((t - self.time) / self._cfg.dt - 1e-6))
        self._t_goal = self.time

    def _run(self, n: int) -> None:
        if n <= 0:
            return
        dt = self._cfg.dt
        ok = advance_steps(
            self._xv, self._xf, self._cmd, self._mrb, self._ma, self._minv, self._pv, self._ph,
            self._signs, self._acc, self._max_rate, self._fin_inertia, dt, n, self._xv, self._xf,
        )
        self._step_count[K_STEPS] += n
        if not ok:
            raise FloatingPointError(f"plant state diverged at t={self.time:.3f} s: {self._xv!r}")

    def advance_and_sample(self, t: float) -> list[Reading]:
        """:meth:`advance_to` ``t``, then :meth:`sample_sensors`, in one compiled call."""
        if not math.isfinite(t):
            raise ValueError(f"t: expected a finite time, got {t!r}")
        s = self._sensors
        imu, p, dvl = s.noise()
        n = sample_plant(self._xv, self._xf, self._cmd, self._mats, self._pv, self._ph, self._signs,
                         self._servo_consts, self._step_count, t, s.state, s.out, imu, p, dvl, s.rows)
        self._t_goal = self.time
        if n < 0:
            raise self.diverged()
        return [rr.from_row(s.rows[k]) for k in range(n)]

    def kernel_arrays(self) -> tuple[np.ndarray, ...]:
        """The arrays :func:`sample_plant` takes before ``t`` (vehicle and fin state, fin
        commands, matrices, parameters, servo constants, the step count), for compiled
        callers that advance and sample the plant themselves; the sensors' are
        :meth:`SensorSuite.kernel_arrays`."""
        return (self._xv, self._xf, self._cmd, self._mats, self._pv, self._ph, self._signs,
                self._servo_consts, self._step_count)

    @property
    def sensors(self) -> SensorSuite:
        return self._sensors

    def diverged(self) -> FloatingPointError:
        """The error of a state that is no longer finite."""
        return FloatingPointError(f"plant state diverged at t={self.time:.3f} s: {self._xv!r}")

    def synced(self) -> None:
        """After a compiled caller advanced the plant (:meth:`kernel_arrays`)."""
        self._t_goal = self.time

    # ----------------------------------------------------------------- sensors
    def sample_sensors(self, t: float | None = None) -> list[Reading]:
        """Readings due at ``t`` (default: plant time), sampled from the present state."""
        return self._sensors.sample(
            self.time if t is None else t, self._xv, self._xf[:, F_THETA], self._xf[:, F_OMEGA]
        )

    def next_sensor_time(self) -> float:
        """When the next sensor sample is due (advance to it for exact sensor rates)."""
        return self._sensors.next_due()

    def fin_feedback(self, i: int) -> tuple[float, float]:
        """Fin ``i``'s encoder angle and rate, quantised as the EPOS2 reports them."""
        if not 0 <= i < N_FINS:
            raise ValueError(f"fin: {i!r} is not a plant fin index 0..3")
        return encoder_reading(float(self._xf[i, F_THETA]), float(self._xf[i, F_OMEGA]), self._cfg.servo.units)

    # -------------------------------------------------------------- true state
    def pose(self) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
        """(position NED, quaternion w,x,y,z body->NED) for the 3-D view."""
        p = self._xv[POS : POS + 3]
        q = self._xv[QUAT : QUAT + 4]
        return (float(p[0]), float(p[1]), float(p[2])), (float(q[0]), float(q[1]), float(q[2]), float(q[3]))

    def euler(self) -> tuple[float, float, float]:
        """Roll, pitch, yaw (rad, ZYX)."""
        return euler_from_quaternion(self._xv[QUAT : QUAT + 4])

    def body_velocity(self) -> tuple[float, float, float, float, float, float]:
        """(u, v, w, p, q, r) over ground, body frame."""
        v = self._xv[NU : NU + 6]
        return tuple(float(x) for x in v)  # type: ignore[return-value]

    def depth(self) -> float:
        return float(self._xv[POS + 2])

    def fin_angles(self) -> tuple[float, ...]:
        return tuple(float(x) for x in self._xf[:, F_THETA])

    def fin_rates(self) -> tuple[float, ...]:
        return tuple(float(x) for x in self._xf[:, F_OMEGA])

    def fin_strouhal(self) -> tuple[float, ...]:
        return tuple(float(x) for x in self._xf[:, F_ST])

    def fin_energy(self) -> tuple[float, ...]:
        """True shaft energy per fin since reset (J), no regeneration (``plate.fin_load``)."""
        return tuple(float(x) for x in self._xf[:, F_ENERGY])

    def fin_currents(self) -> tuple[float, ...]:
        """Each fin drive's motor current in the last step (A; ``robot.motor``)."""
        return tuple(float(x) for x in self._xf[:, F_CURRENT])

    def fin_battery_energy(self) -> tuple[float, ...]:
        """Battery energy each fin drive drew since reset (J; ``robot.motor``): never less than
        its shaft energy."""
        return tuple(float(x) for x in self._xf[:, F_BATTERY_ENERGY])

    def fin_work(self) -> tuple[float, ...]:
        """Work each fin did on the hull since reset (J): never more than its shaft energy
        over whole cycles."""
        return tuple(float(x) for x in self._xf[:, F_WORK])

    def fin_impulse(self) -> tuple[tuple[float, float], ...]:
        """Each fin's fin-frame force (f_x, f_y) integrated since the reset (N s): the
        true mean force over a span is the change of this over the span's length."""
        return tuple((float(x), float(y)) for x, y in self._xf[:, F_IMPULSE_X:F_IMPULSE_Y + 1])

    def state_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """Copies of the vehicle and fin state arrays (layouts in ``vehicle`` and here)."""
        return self._xv.copy(), self._xf.copy()


def measure_realtime_factor(seconds: float = 20.0, chunk_s: float = 0.01, sensors: bool = True) -> float:
    """Simulated seconds per wall-clock second of the plant alone, fins beating at 2 Hz.

    The plant is advanced in chunks of ``chunk_s`` (sampling the sensors after each chunk
    when ``sensors``), as a closed loop would drive it. Compilation is done before timing.
    """
    plant = Plant()
    plant.advance(0.01)
    plant.sample_sensors()
    plant.reset()
    n = max(1, round(seconds / chunk_s))
    half_period = 0.25
    sign = 1.0
    next_flip = 0.0
    start = _time.perf_counter()
    for _ in range(n):
        if plant.time >= next_flip:
            for i in range(N_FINS):
                plant.command_fin(i, 0.6 * sign, 6.0)
            sign = -sign
            next_flip += half_period
        plant.advance(chunk_s)
        if sensors:
            plant.sample_sensors()
    wall = _time.perf_counter() - start
    return plant.time / wall
