"""The arming gate: a :class:`RobotIO` wrapper through which fin commands pass only when armed.

The closed loop keeps running while the motors are disarmed (the estimator, the plots and
the failsafes need the readings), so the gate sits between it and the robot:

* disarmed: fin commands are dropped; on disarming, a robot with drives stops them on
  their quick-stop ramp and turns their power stages off (they are powered again on
  arming, :meth:`RobotIO.enable_drives`); the simulator's fins are each sent one set-point
  at their last measured angle (the servo decelerates and stops there). Either way a fin
  never keeps swimming towards an old target;
* armed: commands pass unchanged;
* each set-point a fin is actually sent (a command passed on, a stop) is kept in
  :attr:`ArmingGate.sent` and reported to the one :meth:`ArmingGate.report_sent` names
  (the closed loop, which publishes it in its fin states);
* readings with non-finite values are dropped before they reach the loop (they would stop
  it) and reported through ``on_invalid(sensor, description)``; the failsafes then see
  the sensor as silent.

A robot that runs the loop's core itself (the simulator, ``RobotIO.run_core``) runs it
through the gate too: its readings never leave compiled code, and they cannot be
non-finite (they are sampled from a state its physics keep finite: a diverging state is an
error of the robot), so the gate's part there is the commands and the stop set-points.

:meth:`ArmingGate.disarm` may be called from any thread and stops commands at once; the
stop set-points go out from the loop's thread (the next command or
:meth:`ArmingGate.flush`), because the robot is driven by that thread only.
"""

from __future__ import annotations

import logging
import math
import threading
from typing import Any, Callable

import numpy as np

from ucat_console.robot.fins import N_FINS
from ucat_console.robot.readings import DepthReading, DvlVelocity, FinFeedback, FinFeedbacks, ImuReading
from ucat_console.robot.interface import RobotIO, RobotTruth
from ucat_console.robot.readings import Reading

log = logging.getLogger(__name__)

#: profile velocity of the stop set-point sent on disarming (rad/s)
STOP_RATE = 2.0


def _finite(*values: float) -> bool:
    return all(math.isfinite(v) for v in values)


def reading_finite(r: Reading) -> tuple[str, bool]:
    """(sensor name, whether every value the loop uses is finite)."""
    if isinstance(r, FinFeedbacks):
        return "fin", math.isfinite(r.t) and bool(np.isfinite(r.position_rad).all() and np.isfinite(r.velocity_rad_s).all())
    if isinstance(r, FinFeedback):
        return "fin", _finite(r.position_rad, r.velocity_rad_s, r.t)
    if isinstance(r, ImuReading):
        ok = _finite(r.t, *r.gyro, *r.accel) and (r.quaternion is None or _finite(*r.quaternion))
        return "imu", ok
    if isinstance(r, DvlVelocity):
        # an invalid report may carry NaN velocities: the loop skips it by its flag
        return "dvl", _finite(r.t) and (not r.valid or _finite(r.vx, r.vy, r.vz))
    if isinstance(r, DepthReading):
        return "depth", _finite(r.t, r.depth_m)
    return type(r).__name__, True


class ArmingGate(RobotIO):
    """Wraps a robot; see the module docstring."""

    def __init__(self, inner: RobotIO, on_invalid: Callable[[str, str], None] | None = None) -> None:
        self.inner = inner
        self._on_invalid = on_invalid
        self._armed = False
        self._stop_pending = False
        self._lock = threading.Lock()
        self.measured: list[float] = [math.nan] * N_FINS
        #: the last set-point each fin was actually sent (angle, rate)
        self.sent: list[tuple[float, float]] = [(0.0, 0.0)] * N_FINS
        self._report: Callable[[int, float, float], None] | None = None
        self.dropped_commands = 0
        self.dropped_readings = 0

    @property
    def armed(self) -> bool:
        return self._armed

    def arm(self) -> None:
        with self._lock:
            self._armed = True
            self._stop_pending = False

    def disarm(self) -> None:
        """No command passes from now on; the fins are stopped from the loop's thread."""
        with self._lock:
            if self._armed:
                self._stop_pending = True
            self._armed = False

    def flush(self) -> None:
        """Send the stop set-points owed since a disarm (call from the loop's thread)."""
        with self._lock:
            pending, self._stop_pending = self._stop_pending, False
        if not pending:
            return
        if self.inner.has_drives:
            if self.inner.stop_drives():
                log.info("fin drives stopped on their quick-stop ramp, power stages off")
            else:
                log.error("a fin drive did not confirm its stop (see its events)")
            return
        for fin in range(N_FINS):
            angle = self.measured[fin]
            if math.isnan(angle):
                angle = self.sent[fin][0]
            self._send(fin, angle, STOP_RATE)
        log.info("fins stopped at their measured angles")

    def _send(self, fin: int, target_rad: float, profile_velocity_rad_s: float) -> None:
        self.inner.command_fin(fin, target_rad, profile_velocity_rad_s)
        self.sent[fin] = (target_rad, profile_velocity_rad_s)
        if self._report is not None:
            self._report(fin, target_rad, profile_velocity_rad_s)

    # ------------------------------------------------------------------ RobotIO
    def command_fin(self, fin: int, target_rad: float, profile_velocity_rad_s: float) -> None:
        if self._stop_pending:
            self.flush()
        if not self._armed:
            self.dropped_commands += 1
            return
        self._send(fin, target_rad, profile_velocity_rad_s)

    def report_sent(self, report: Callable[[int, float, float], None]) -> bool:
        """Each set-point a fin is sent from now on, passed on or a stop, goes to ``report``
        too (the module docstring)."""
        self._report = report
        return True

    @property
    def has_drives(self) -> bool:  # type: ignore[override]
        return self.inner.has_drives

    @property
    def runs_core(self) -> bool:  # type: ignore[override]
        return self.inner.runs_core

    def run_core(self, core: Any) -> int:
        if self._stop_pending:
            self.flush()
        st = self.inner.run_core(core)
        self.measured = core.fin_angles()
        return st

    def enable_drives(self) -> bool:
        return self.inner.enable_drives()

    def stop_drives(self) -> bool:
        return self.inner.stop_drives()

    def reset_drive_faults(self) -> bool:
        return self.inner.reset_drive_faults()

    def zero_depth(self) -> float:
        return self.inner.zero_depth()

    def next_reading_time(self) -> float:
        return self.inner.next_reading_time()

    def resync(self, t: float) -> None:
        self.inner.resync(t)

    def advance_to(self, t: float) -> list[Reading]:
        if self._stop_pending:
            self.flush()
        readings = self.inner.advance_to(t)
        out = readings
        for i, r in enumerate(readings):
            sensor, ok = reading_finite(r)
            if not ok:
                out = [x for x in readings if reading_finite(x)[1]]
                for x in readings[i:]:
                    s, good = reading_finite(x)
                    if not good:
                        self.dropped_readings += 1
                        log.warning("%s reading refused: non-finite values in %r", s, x)
                        if self._on_invalid is not None:
                            self._on_invalid(s, "non-finite values")
                break
        for r in out:
            tp = type(r)
            if tp is FinFeedbacks:
                self.measured = r.position_rad.tolist()
            elif tp is FinFeedback:
                self.measured[r.fin] = r.position_rad
        return out

    def truth(self) -> RobotTruth | None:
        return self.inner.truth()

    def close(self) -> None:
        self.inner.close()
