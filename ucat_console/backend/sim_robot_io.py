"""The in-process simulated U-CAT as a robot: :class:`SimRobotIO` (``robot.interface``).

Here the plant (``backend.sim``) and the closed loop's per-sample core (``control.loop_core``)
meet, as the emulators and the plant meet in ``sim_rig.py``: neither imports the other.
:func:`run_core_on_plant` runs the core with the plant as its robot in one compiled call:
whenever the core asks for the readings of an event, the plant's physics runs to it and its
sensors sample into the core's rows, with no Python in between, until the core has
something for the loop to do (``SimRobotIO.run_core``). The loop's trajectory is the same as
when it drives the plant through :meth:`SimRobotIO.advance_to`, one event at a time.

Telemetry. About every :data:`ELECTRICAL_PERIOD` of plant time the simulated drives'
electrical input becomes an ``ElectricalPower`` message handed to each sink added with
:meth:`SimRobotIO.add_telemetry_sink` as ``(channel, message)``, as the device robot hands the
EPOS2s' (the supervisor publishes it on ``power/electrical``): each drive's battery power is
its mean since the last message, from the plant's drive model (``robot.motor``) integrated
at every physics step, and its current the motor current at the message's time. A message is
handed on at the robot's next step, after the loop has published the readings of the step
that made it, so that the stream stays in time order (the plant runs ahead of the readings
the loop has taken). (A real
drive's figure is made from its averaged current, ``drive_power``; the simulator knows the
battery's exact view.)

The plant's readings pass the plausibility checks (``devices.plausibility``) on either
path, in the compiled call too: an implausible one never reaches the core, and is reported
as an Event ``implausible`` (loop time) to ``on_event``. The plant's sensors keep their
readings plausible (noise included); a subclass that changes the readings runs through
:meth:`SimRobotIO.advance_to`, and the checks.
"""

from __future__ import annotations

import math
from typing import Any, Callable

from numba import njit

from ucat_console.backend.devices.plausibility import Plausibility, PlausibilityConfig, filter_rows
from ucat_console.backend.sim.params import PlantConfig
from ucat_console.backend.sim.plant import Plant, sample_plant
from ucat_console.backend.sim.sensors import S_DVL_ROW, S_IMU_ROW, S_NEXT, S_P_ROW
from ucat_console.control.loop_core import C_NROWS, C_ROWS_PENDING, C_T_NEXT, C_T_ROBOT, READINGS, LoopCore, core_step
from ucat_console.robot.fins import N_FINS
from ucat_console.robot.interface import RobotIO, RobotTruth
from ucat_console.robot.readings import Reading
from ucat_console.telemetry.channels import POWER_ELECTRICAL
from ucat_console.telemetry.events import EventSink
from ucat_console.telemetry.messages import ElectricalPower

#: how often the simulated drives' electrical input is reported (s of plant time), each
#: message the mean over its period; the EPOS2s report every ``Epos2Config.electrical_period_ms``
#: (20 ms), the simulated drives every 0.1 s
ELECTRICAL_PERIOD = 0.1
#: what :func:`run_core_on_plant` returns besides the core's own statuses
NEED_NOISE = -1  # a noise block is used up: new blocks, then call again
DIVERGED = -2  # the plant's state is no longer finite


@njit(cache=True)
def run_core_on_plant(s, body, watch, members, found, power, rows, outbox, fin_rows, r3,
                      xv, xf, cmd, mats, pv, ph, signs, servo, steps,
                      sf, out, imu_noise, p_noise, dvl_noise, _sensor_rows, plim, pst) -> int:
    """``control.loop_core.core_step`` (its arrays first) with the plant (``Plant.kernel_arrays``,
    ``SensorSuite.kernel_arrays``) as its robot, its readings through the plausibility
    checks (``plim``, ``pst``: ``Plausibility.limits``, ``.state``); what the core returns
    for the loop, or NEED_NOISE, or DIVERGED. After NEED_NOISE the core goes on where it was."""
    while True:
        if s[C_ROWS_PENDING] != 0.0:
            if (sf[S_IMU_ROW] >= imu_noise.shape[0] or sf[S_P_ROW] >= p_noise.shape[0]
                    or sf[S_DVL_ROW] >= dvl_noise.shape[0]):
                return NEED_NOISE
            n = sample_plant(xv, xf, cmd, mats, pv, ph, signs, servo, steps, s[C_T_NEXT], sf, out, imu_noise,
                             p_noise, dvl_noise, rows)
            if n < 0:
                return DIVERGED
            s[C_NROWS] = filter_rows(plim, pst, rows, n)
            s[C_ROWS_PENDING] = 0.0
        s[C_T_ROBOT] = sf[S_NEXT]
        st = core_step(s, body, watch, members, found, power, rows, outbox, fin_rows, r3)
        if st != READINGS:
            return st


class SimRobotIO(RobotIO):
    """The in-process simulated U-CAT (``backend.sim.Plant``), headless or paced.

    The plant starts level at ``depth`` (m) with heading ``yaw`` (rad), surging at
    ``velocity`` (m/s, body x; 0: at rest), all fins at rest at angle 0; ``seed`` restarts
    the sensor noise (default: the plant configuration's seed). ``plausibility`` limits
    the readings (module docstring); what they drop is reported to ``on_event``.
    """

    def __init__(
        self, cfg: PlantConfig | None = None, *, depth: float = 0.0, yaw: float = 0.0,
        velocity: float = 0.0, seed: int | None = None, plausibility: PlausibilityConfig | None = None,
        on_event: EventSink | None = None,
    ) -> None:
        if not math.isfinite(depth) or depth < 0.0:
            raise ValueError(f"depth: the start depth must be finite and >= 0 m, got {depth!r}")
        if not math.isfinite(velocity) or abs(velocity) > 5.0:
            raise ValueError(f"velocity: the start surge must be finite and within 5 m/s, got {velocity!r}")
        self.plant = Plant(cfg)
        self.plant.reset(
            position_ned=(0.0, 0.0, float(depth)), euler=(0.0, 0.0, float(yaw)),
            body_velocity=(float(velocity), 0.0, 0.0, 0.0, 0.0, 0.0), seed=seed,
        )
        #: the plausibility checks of the readings
        self.checks = Plausibility(plausibility, on_event)
        self._telemetry_sinks: tuple[Callable[[str, Any], None], ...] = ()
        self._last_electrical: tuple[float, tuple[float, ...]] | None = None  # (time, battery energy)
        self._electrical_due: ElectricalPower | None = None  # made at the last step, handed on at the next
        self._weak: dict[int, float] = {}  # weak drives: fin -> the share of the speed asked it runs at

    @property
    def runs_core(self) -> bool:  # type: ignore[override]
        """The plant's physics and sensors run with the loop's core in compiled code; not
        for a subclass that changes the readings (its :meth:`advance_to` is the robot)."""
        return type(self).advance_to is SimRobotIO.advance_to

    def command_fin(self, fin: int, target_rad: float, profile_velocity_rad_s: float) -> None:
        factor = self._weak.get(fin)
        if factor is not None:  # a weak drive: a share of the speed asked, of the servo's maximum at most
            profile_velocity_rad_s = factor * min(profile_velocity_rad_s, self.plant.cfg.servo.max_rate)
        self.plant.command_fin(fin, target_rad, profile_velocity_rad_s)

    def weaken_fin(self, fin: int, factor: float) -> None:
        """Fin ``fin``'s drive runs from its next command on at ``factor`` (0 < factor <= 1) of
        the speed it is asked for (and of the servos' maximum rate): a weak or worn drive. It
        may happen while the robot runs (every command passes here); 1 makes it whole again."""
        if isinstance(fin, bool) or not isinstance(fin, int) or not 0 <= fin < N_FINS:
            raise ValueError(f"fin: {fin!r} is not a plant fin index 0..{N_FINS - 1}")
        if isinstance(factor, bool) or not (isinstance(factor, (int, float)) and 0.0 < factor <= 1.0):
            raise ValueError(f"factor: a weak drive runs at a share in (0, 1] of its speed, got {factor!r}")
        if factor == 1.0:
            self._weak.pop(fin, None)
        else:
            self._weak[fin] = float(factor)

    def add_telemetry_sink(self, sink: Callable[[str, Any], None]) -> Callable[[], None]:
        """``sink(channel, message)`` for the simulated drives' electrical input (module
        docstring); returns the function that removes it."""
        self._telemetry_sinks = self._telemetry_sinks + (sink,)

        def remove() -> None:
            self._telemetry_sinks = tuple(s for s in self._telemetry_sinks if s is not sink)

        return remove

    def _hand_on_electrical(self) -> None:
        """The message the last step made, if any, to every sink."""
        msg, self._electrical_due = self._electrical_due, None
        if msg is not None:
            for sink in self._telemetry_sinks:
                sink(POWER_ELECTRICAL, msg)

    def _report_electrical(self) -> None:
        """The drives' electrical input since the last message, when one is due (handed on
        at the next step)."""
        p = self.plant
        if not self._telemetry_sinks:
            return
        t, energy = p.time, p.fin_battery_energy()
        last = self._last_electrical
        if last is None or t < last[0]:  # the first, or the plant was reset
            self._last_electrical = (t, energy)
            return
        span = t - last[0]
        if span + 1e-9 < ELECTRICAL_PERIOD:
            return
        self._last_electrical = (t, energy)
        per_fin = tuple((e - e0) / span for e, e0 in zip(energy, last[1]))
        volts = (p.cfg.motor.supply_voltage,) * len(per_fin)
        self._electrical_due = ElectricalPower(t, p.fin_currents(), volts, per_fin, math.fsum(per_fin))  # type: ignore[arg-type]

    def run_core(self, core: LoopCore) -> int:
        plant = self.plant
        sensors = plant.sensors
        arrays = core.arrays() + plant.kernel_arrays()
        checks = self.checks
        self._hand_on_electrical()
        while True:
            st = run_core_on_plant(*arrays, *sensors.kernel_arrays(), checks.limits, checks.state)
            if st != NEED_NOISE:
                break
        plant.synced()
        checks.report(plant.time)
        if st == DIVERGED:
            raise plant.diverged()
        self._report_electrical()
        return st

    def next_reading_time(self) -> float:
        return self.plant.next_sensor_time()

    def advance_to(self, t: float) -> list[Reading]:
        self._hand_on_electrical()
        readings = self.checks.filter(self.plant.advance_and_sample(t))
        self.checks.report(t)
        self._report_electrical()
        return readings

    def truth(self) -> RobotTruth:
        p = self.plant
        pos, q = p.pose()
        return RobotTruth(
            t=p.time,
            position=pos,
            orientation=q,
            euler=p.euler(),
            velocity=p.body_velocity(),
            fin_angles=p.fin_angles(),
            fin_rates=p.fin_rates(),
            fin_strouhal=p.fin_strouhal(),
            fin_energy=p.fin_energy(),
            fin_impulse=p.fin_impulse(),
            fin_battery_energy=p.fin_battery_energy(),
        )
