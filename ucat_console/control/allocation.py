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

from dataclasses import dataclass
from math import isfinite

from ucat_console.control.argcheck import finite, in_range
from ucat_console.control.filters import MedianFilter
from ucat_console.control.params import BodyConfig
from ucat_console.control.pid import Pid
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


def allocate(fx_body: float, fy_body: float, yaw: float, *, sync: bool = False) -> Allocation:
    """Split the body demand into fin targets (paper eqs in section IV.B).

    ``fx_body`` is F_x* (N, forward < 0), ``fy_body`` is F_y* (N), ``yaw`` the front-pair
    thrust differential (N, > 0 turns to starboard). See the module docstring for signs.
    """
    fx, fy, m = float(fx_body), float(fy_body), float(yaw)
    if not (isfinite(fx) and isfinite(fy) and isfinite(m)):  # inline: this runs at the control rate
        finite("fx_body", fx)
        finite("fy_body", fy)
        finite("yaw", m)
    axial = 0.25 * fx
    front_s = (axial + 0.5 * m, 0.5 * fy)
    front_p = (axial - 0.5 * m, 0.5 * fy)
    rear = (axial, 0.0)
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


class BodyController:
    """The three body-frame PIDs with their input filters; readings in, fin targets out.

    Feed readings with :meth:`on_dvl`, :meth:`on_depth`, :meth:`on_imu` as they arrive and
    call :meth:`update` at the control rate. A loop runs only on a new sample; otherwise its
    last output is held. A DVL report with ``valid=False`` is missing data: it is counted
    and never enters the filter as a zero velocity.
    """

    def __init__(self, cfg: BodyConfig) -> None:
        self.cfg = cfg
        self.velocity_pid = Pid(cfg.velocity)
        self.depth_pid = Pid(cfg.depth)
        self.yaw_pid = Pid(cfg.yaw_rate)
        self.velocity_filter = MedianFilter(cfg.median_window)
        self.depth_filter = MedianFilter(cfg.median_window)
        self.reset()

    def reset(self) -> None:
        for pid in (self.velocity_pid, self.depth_pid, self.yaw_pid):
            pid.reset()
        self.velocity_filter.reset()
        self.depth_filter.reset()
        self.dvl_missing = 0
        self.last_dvl_t: float | None = None
        self.last_depth_t: float | None = None
        self.last_imu_t: float | None = None
        self._yaw_rate: float | None = None
        self._new_v = self._new_z = self._new_r = False
        self._fx = self._fy = self._yaw = 0.0

    @property
    def sensors_reported(self) -> bool:
        """A depth and a DVL report (with or without bottom lock) have arrived since the
        reset: the loops have seen what the robot can measure, and a speed still missing is
        the DVL's reported fault, not the start-up's."""
        return self.last_depth_t is not None and (self.last_dvl_t is not None or self.dvl_missing > 0)

    # the readings' checks are inline: these run on every sample
    def on_dvl(self, reading: DvlVelocity) -> None:
        if not reading.valid:
            self.dvl_missing += 1
            return
        v, t = reading.vx, reading.t
        if not (isfinite(v) and isfinite(t)):
            finite("dvl.vx", v)
            finite("dvl.t", t)
        self.velocity_filter.push(v)
        self.last_dvl_t = t
        self._new_v = True

    def on_depth(self, reading: DepthReading) -> None:
        z, t = reading.depth_m, reading.t
        if not (isfinite(z) and isfinite(t)):
            finite("depth.depth_m", z)
            finite("depth.t", t)
        self.depth_filter.push(z)
        self.last_depth_t = t
        self._new_z = True

    def on_imu(self, reading: ImuReading) -> None:
        r, t = reading.gyro[2], reading.t
        if not (isfinite(r) and isfinite(t)):
            finite("imu.gyro[2]", r)
            finite("imu.t", t)
        self._yaw_rate = r
        self.last_imu_t = t
        self._new_r = True

    def update(self, t: float, setpoints: BodySetpoints, *, sync: bool = False) -> BodyStep:
        """One control step at time ``t`` (s): run the loops that have new data, allocate."""
        t = finite("t", t)
        v = self.velocity_filter.value
        z = self.depth_filter.value
        r = self._yaw_rate
        new_v, new_z, new_r = self._new_v, self._new_z, self._new_r
        if new_v and v is not None:
            self._fx = -self.velocity_pid.update((setpoints.velocity, v), t)
        if new_z and z is not None:
            self._fy = self.cfg.depth_sign * self.depth_pid.update((setpoints.depth, z), t)
        if new_r and r is not None:
            self._yaw = self.yaw_pid.update((setpoints.yaw_rate, r), t)
        self._new_v = self._new_z = self._new_r = False
        return BodyStep(
            t=t,
            fx=self._fx,
            fy=self._fy,
            yaw=self._yaw,
            allocation=allocate(self._fx, self._fy, self._yaw, sync=sync),
            velocity=v,
            depth=z,
            yaw_rate=r,
            velocity_updated=new_v,
            depth_updated=new_z,
            yaw_updated=new_r,
        )
