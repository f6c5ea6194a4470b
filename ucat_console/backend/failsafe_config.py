"""The failsafes' configuration, ``[failsafe]``: one rule per failsafe and the thresholds they judge.

Each :class:`FailsafeRule` (:mod:`~ucat_console.backend.failsafe_rule`) says what the failsafe does when its cause has lasted ``timeout`` s
(hold, surface, disarm or warn) and what it does when the cause lasts on; :class:`FailsafeConfig`
holds every rule and the thresholds (depth and altitude limits, battery, estimate, the tracking
alarm's expected response), and the rules set for the registered sensors' failsafes
(``sensors``, ``[[failsafe.sensors]]``; :mod:`~ucat_console.backend.sensors`).
:mod:`~ucat_console.backend.safety` acts on it; docs/safety.md describes each failsafe.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from ucat_console.backend.loop.config import LoopConfig
from ucat_console.control.body_design import HEADING_FACTOR
from ucat_console.control.params import DESIGN_DELAY, DESIGN_FACTOR, BodyConfig
from ucat_console.backend.failsafe_rule import (
    ESCALATE_DOC,
    ESCALATIONS,
    FIXED_FAILSAFES,
    FailsafeRule,
)
from ucat_console.backend.sensors import sensor_failsafe, sensor_failsafe_names
from ucat_console.typedconf import Config, param

#: the body layer's defaults, the tracking failsafe's expected response's limits
_BODY = BodyConfig()

@dataclass(frozen=True)
class PilotGoneRule(FailsafeRule):
    """The pilot-gone failsafe: hold where the robot is, then, if no pilot has come back
    after 30 s, disarm (ArduSub's default GCS failsafe disarms after 5 s)."""

    escalate: str = param("disarm", choices=ESCALATIONS, doc=ESCALATE_DOC)


@dataclass(frozen=True)
class LoopWatchdogRule(FailsafeRule):
    """The control loop's watchdog (a thread of its own): when the loop has not stepped for
    ``timeout`` s it disarms, turning the drives off from its own thread. Only disarm or warn:
    a hold or a surfacing needs the loop that is stuck. The default, 2 s, is over eight times
    the loop's longest caught-up lag (``console.max_lag``, 0.25 s) and half as long again as
    the longest lag measured with the computer at twice its load goal (1.3 s, docs/safety.md);
    the drives hold their last set-point meanwhile."""

    action: str = param("disarm", choices=("disarm", "warn"),
                        doc="disarm: the drives off from the watchdog's thread; warn: show and record only")
    timeout: float = param(2.0, lo=0.05, hi=60.0, unit="s",
                           doc="how long the loop has not stepped before the watchdog acts")

    def _check(self) -> None:
        if self.escalate != "none":
            raise ValueError(f"escalate: the loop watchdog acts once (disarm or warn); got {self.escalate!r}, "
                             "allowed: none")


@dataclass(frozen=True)
class SensorRule(FailsafeRule):
    """A registered sensor's failsafe (``backend.sensors``) as set in the configuration: its
    name and the rule in full (a field left out takes :class:`FailsafeRule`'s default, not the
    sensor's)."""

    name: str = param("", choices=sensor_failsafe_names, doc="the sensor's failsafe (one registered)")

    def rule(self) -> FailsafeRule:
        """The rule without its name."""
        return FailsafeRule(self.action, self.timeout, self.escalate, self.escalate_after)


@dataclass(frozen=True)
class FailsafeConfig(Config):
    """Every failsafe; each is shown, recorded, and latched until its cause clears."""

    pilot_gone: PilotGoneRule = PilotGoneRule()
    imu: FailsafeRule = FailsafeRule("disarm", 1.0)
    dvl: FailsafeRule = FailsafeRule("hold", 2.0)
    depth: FailsafeRule = FailsafeRule("disarm", 1.0)
    motor: FailsafeRule = FailsafeRule("disarm", 0.0)
    planner_late: FailsafeRule = FailsafeRule("hold", 10.0)
    late_plans: int = param(
        10, lo=1, hi=100_000, doc="late plans within planner_late.timeout that trigger planner_late"
    )
    tracking: FailsafeRule = FailsafeRule("warn", 10.0)
    #: the recorder failed to write (a full disk): warn, or hold until the operator acts
    recording: FailsafeRule = FailsafeRule("warn", 0.0)
    loop_watchdog: LoopWatchdogRule = LoopWatchdogRule("disarm", 2.0)
    #: the robot deeper than max_depth: surface (a hold would keep it beyond the limit)
    depth_limit: FailsafeRule = FailsafeRule("surface", 1.0)
    max_depth: float = param(
        55.0, lo=0.1, hi=10_000.0, unit="m",
        doc="depth_limit: a measured depth deeper than this (the default: 10 % beyond the setpoints' envelope, "
        "loop.max_depth 50 m; set the pool's depth less a margin)",
    )
    #: the DVL's altitude below min_altitude: surface (a hold keeps the robot at the floor)
    altitude: FailsafeRule = FailsafeRule("surface", 1.0)
    min_altitude: float = param(
        0.5, lo=0.0, hi=100.0, unit="m",
        doc="altitude: the DVL's distance to the floor shorter than this (0: off); an invalid altitude "
        "(none, NaN, not above 0) is not counted",
    )
    #: the attitude estimate disagrees with the accelerometer, or the estimate stopped: hold
    #: (stop; the depth is the pressure sensor's, the heading and speed loops are the estimate's)
    estimate: FailsafeRule = FailsafeRule("hold", 2.0)
    estimate_innovation: float = param(
        0.2, lo=0.01, hi=3.15, unit="rad",
        doc="estimate: the angle between the accelerometer's gravity and the attitude estimate's larger "
        "than this (every reading taken at rest, |a| within 0.15 g of g0)",
    )
    #: the battery: warn first (a sagging pack, most of its energy used), then surface while it
    #: still drives the fins; 10 s, ArduSub's BATT_LOW_TIMER, so a stroke's sag does not trip it
    battery_low: FailsafeRule = FailsafeRule("warn", 10.0)
    battery_critical: FailsafeRule = FailsafeRule("surface", 10.0)
    battery_low_voltage: float = param(
        22.0, lo=0.0, hi=100.0, unit="V",
        doc="battery_low: the lowest drive's supply voltage below this (a 24 V pack, 7 Li-ion cells at 3.15 V)",
    )
    battery_critical_voltage: float = param(
        21.0, lo=0.0, hi=100.0, unit="V",
        doc="battery_critical: the lowest drive's supply voltage below this (7 cells at 3.0 V, their cut-off)",
    )
    battery_capacity: float = param(
        0.0, lo=0.0, hi=100_000.0, unit="Wh",
        doc="the energy the pack gives the four drives (0: the energy used is not judged); "
        "the drives' electrical input counts the fins only, not the computer and the sensors",
    )
    battery_low_reserve: float = param(
        0.3, lo=0.0, hi=1.0, doc="battery_low: less than this fraction of battery_capacity left",
    )
    battery_critical_reserve: float = param(
        0.15, lo=0.0, hi=1.0, doc="battery_critical: less than this fraction of battery_capacity left",
    )
    tracking_depth: float = param(
        0.2, lo=0.01, hi=100.0, unit="m",
        doc="tracking: depth further than this from its expected response (backend.tracking_alarm)",
    )
    tracking_speed: float = param(
        0.05, lo=0.005, hi=5.0, unit="m/s",
        doc="tracking: forward speed further than this from its expected response",
    )
    tracking_heading: float = param(
        0.35, lo=0.01, hi=3.15, unit="rad", doc="tracking: heading further than this from its expected response"
    )
    tracking_delay: float = param(
        DESIGN_DELAY, lo=0.01, hi=30.0, unit="s",
        doc="tracking: the fins' delay in the slowest expected response (the body layer's design delay, "
        "control.params.DESIGN_DELAY)",
    )
    tracking_bandwidth: float = param(
        round(1.0 / (DESIGN_FACTOR * DESIGN_DELAY), 4), lo=0.001, hi=10.0, unit="rad/s",
        doc="tracking: the speed and depth loops' closed-loop bandwidth in the slowest expected response "
        "(the designed 1 / (k tau), control.body_design)",
    )
    tracking_heading_bandwidth: float = param(
        round(1.0 / (HEADING_FACTOR * DESIGN_DELAY), 4), lo=0.001, hi=10.0, unit="rad/s",
        doc="tracking: the heading loop's closed-loop bandwidth in the slowest expected response "
        "(the designed 1 / (HEADING_FACTOR tau), control.body_design)",
    )
    tracking_max_acceleration: float = param(
        _BODY.max_acceleration, lo=0.001, hi=2.0, unit="m/s2",
        doc="tracking: the expected speed's fastest change (body.max_acceleration's default)",
    )
    tracking_max_dive_rate: float = param(
        _BODY.max_dive_rate, lo=0.001, hi=2.0, unit="m/s",
        doc="tracking: the expected depth's fastest change (body.max_dive_rate's default)",
    )
    tracking_max_yaw_rate: float = param(
        LoopConfig().max_yaw_rate, lo=0.001, hi=10.0, unit="rad/s",
        doc="tracking: the expected heading's fastest change (loop.max_yaw_rate's default)",
    )
    #: the registered sensors' failsafes set here (``[[failsafe.sensors]]``); the others keep the
    #: rule their registration names (``backend.sensors``; the leak detector's: surface at once)
    sensors: tuple[SensorRule, ...] = ()

    #: the failsafes this block has a field for (the registered sensors' are in ``sensors``)
    FIXED: ClassVar[tuple[str, ...]] = FIXED_FAILSAFES
    #: the rules whose default acts on the robot (the others warn by default)
    PROTECTIVE: ClassVar[tuple[str, ...]] = ("pilot_gone", "imu", "dvl", "depth", "motor", "planner_late",
                                              "loop_watchdog", "depth_limit", "altitude", "battery_critical", "estimate")

    def _check(self) -> None:
        names = [r.name for r in self.sensors]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise ValueError(f"sensors: {twice[0]!r} is set more than once")
        if self.battery_critical_voltage >= self.battery_low_voltage:
            raise ValueError(f"battery_critical_voltage: {self.battery_critical_voltage:g} V must be below "
                             f"battery_low_voltage {self.battery_low_voltage:g} V")
        if self.battery_critical_reserve >= self.battery_low_reserve:
            raise ValueError(f"battery_critical_reserve: {self.battery_critical_reserve:g} must be below "
                             f"battery_low_reserve {self.battery_low_reserve:g}")

    def rule(self, name: str) -> FailsafeRule:
        """The rule of failsafe ``name``: a field of this block, or a registered sensor's (set in
        ``sensors``, else its registration's default); ValueError naming the failsafes there are."""
        if name in self.FIXED:
            return getattr(self, name)
        default = sensor_failsafe(name)  # ValueError naming them
        set_here = next((r for r in self.sensors if r.name == name), None)
        return default.rule if set_here is None else set_here.rule()

    def warn_only(self) -> tuple[str, ...]:
        """The protective rules configured only to warn (the fixed ones of :attr:`PROTECTIVE`
        and the registered sensors' whose default acts): the console logs them at start and the
        Safety tab lists them, since such a rule no longer protects the robot."""
        protective = self.PROTECTIVE + tuple(n for n in sensor_failsafe_names()
                                             if sensor_failsafe(n).rule.action != "warn")
        return tuple(name for name in protective if self.rule(name).action == "warn")
