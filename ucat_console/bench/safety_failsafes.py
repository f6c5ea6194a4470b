"""``bench safety --parts failsafes``:

* **Failsafe triggers** (``failsafes``): the emulated rig (``sim-devices``, the drivers on the
  device emulators) armed at 1 m; each new failsafe's cause is brought about ``--failsafe-trials``
  times, each rule's timeout 1 s (the leak's 0 s, the loop watchdog's its default, 2 s): the loop's thread held
  (``loop_watchdog``; the action: every emulated drive out of operation enabled), a dive to
  2 m past a 1.3 m depth limit (``depth_limit``) and, on a second rig with its floor at
  2.5 m, past a 1.2 m minimum altitude (``altitude``; from the first reading beyond the
  limit on the stream), a drive's supply made to read 20 V (``battery_critical``), water at
  the emulated leak detector (``leak``), the accelerometer streaming a tilt the estimate
  lacks (``estimate``). Detection to action: from the cause (the injection, or the first
  reading beyond the limit) to the action in force (the surfacing or holding setpoints
  applied, the drives off), less the rule's timeout; the goal: 100 ms at the 99th percentile.

Figures depend on the machine and its load; they are for docs/performance.md, never test assertions.
"""

from __future__ import annotations

import logging
import statistics
import tempfile
import time
from typing import Any

from ucat_console.bench.safety_console import TOKEN, wait_until

log = logging.getLogger(__name__)

PILOT = 1


def _rig(tmp: str, bottom: float | None = None, **failsafe: Any) -> Any:
    """The emulated rig's console, running, the bench its pilot, no failsafe active."""
    from ucat_console.backend.supervisor import Supervisor
    from ucat_console.config import load_config

    cfg = load_config("sim-devices")
    plant = cfg.plant
    if bottom is not None:
        plant = plant.replace(sensors=plant.sensors.replace(dvl=plant.sensors.dvl.replace(bottom_depth=bottom)))
    cfg = cfg.replace(access=cfg.access.replace(token=TOKEN), console=cfg.console.replace(record_on_arm=False),
                      plant=plant, failsafe=cfg.failsafe.replace(**failsafe))
    sup = Supervisor(cfg, sessions_dir=tmp)
    sup.start()
    sup.client_connected(PILOT)
    sup.take_control(PILOT, TOKEN)
    wait_until(lambda: sup.loop.time > 1.0 and not sup.safety.active(), 120.0, "the rig running, no failsafe")
    return sup


def _readings(sup: Any, channel: str, beyond: Any) -> list[float]:
    """The wall times (monotonic) of the readings on ``channel`` beyond a limit, from now on."""
    times: list[float] = []
    sup.stream.subscribe(lambda c, m: times.append(time.monotonic()) if beyond(m) else None, [channel])
    return times


def _failsafe_trials(sup: Any, name: str, trials: int, inject: Any, clear: Any, acted: Any,
                     crossed: list[float] | None = None) -> tuple[float, list[float]]:
    """(the rule's timeout, detection to action in s beyond it of ``trials`` causes of ``name``)."""
    from ucat_console.backend.supervisor import CommandRefused

    timeout = sup.safety.rule(name).timeout
    out = []
    for trial in range(trials):
        wait_until(lambda: not sup.safety.active(), 120.0, f"no failsafe before {name} trial {trial + 1}")
        if not sup.armed:
            sup.arm(PILOT)
        while True:
            try:
                sup.set_setpoints(PILOT, velocity=0.1, depth=1.0)
                break
            except CommandRefused:  # a hold not cleared yet
                time.sleep(0.05)
        wait_until(lambda: abs(sup._last_body.depth - 1.0) < 0.1, 120.0, "the robot at 1 m")
        if crossed is not None:
            crossed.clear()
        t0 = time.monotonic()
        inject()
        t_act = wait_until(lambda: acted() and time.monotonic(), 120.0, f"the {name} failsafe's action")
        start = crossed[0] if crossed else t0
        out.append(t_act - start - timeout)
        log.info("%s trial %d: acted %.3f s after its cause (timeout %g s)", name, trial + 1, t_act - start, timeout)
        clear()
        wait_until(lambda: not sup.safety.is_active(name), 120.0, f"the {name} failsafe clearing")
    return timeout, out


def _percentile(xs: list[float], q: float) -> float:
    """The ``q`` quantile of sorted ``xs``, interpolated between neighbours."""
    k = (len(xs) - 1) * q
    lo = int(k)
    return xs[lo] + (xs[min(lo + 1, len(xs) - 1)] - xs[lo]) * (k - lo)


def failsafe_triggers(trials: int) -> dict[str, Any]:
    """Detection to action of the new failsafes on the emulated rig (module docstring)."""
    from ucat_console.backend.devices import cia402
    from ucat_console.backend.failsafe_config import FailsafeRule
    from ucat_console.telemetry import channels as ch

    rule = {"battery_low": FailsafeRule("warn", 1.0), "battery_critical": FailsafeRule("surface", 1.0),
            "estimate": FailsafeRule("hold", 1.0)}
    surfaced = (lambda sup: lambda: sup.setpoints.depth == 0.0)
    result: dict[str, tuple[float, list[float]]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        sup = _rig(tmp, max_depth=1.3, **rule)
        try:
            nodes = sup.rig.nodes.nodes.values()
            result["loop_watchdog"] = _failsafe_trials(
                sup, "loop_watchdog", trials, lambda: sup.stall_loop(PILOT, 30.0), sup._unstall.set,
                lambda: all(n.state != cia402.OPERATION_ENABLED for n in nodes))
            deep = _readings(sup, ch.DEPTH, lambda m: m.depth_m > 1.3)
            result["depth_limit"] = _failsafe_trials(
                sup, "depth_limit", trials, lambda: sup.set_setpoints(PILOT, depth=2.0), lambda: None,
                surfaced(sup), deep)
            result["battery_critical"] = _failsafe_trials(
                sup, "battery_critical", trials, lambda: sup.inject_fault(PILOT, "epos2", "low_voltage", fin=2),
                lambda: sup.clear_fault(PILOT, "epos2", "low_voltage"), surfaced(sup))
            result["leak"] = _failsafe_trials(
                sup, "leak", trials, lambda: sup.inject_leak(PILOT, True), lambda: sup.inject_leak(PILOT, False),
                surfaced(sup))
            result["estimate"] = _failsafe_trials(
                sup, "estimate", trials,
                lambda: sup.inject_fault(PILOT, "imu", "implausible", accel_g=(0.5, 0.0, -0.75 ** 0.5)),
                lambda: sup.clear_fault(PILOT, "imu", "implausible"), lambda: sup.setpoints.velocity == 0.0)
        finally:
            sup.stop()
        sup = _rig(tmp, bottom=2.5, min_altitude=1.2)
        try:
            low = _readings(sup, ch.DVL, lambda m: 0.0 < m.altitude < 1.2)
            result["altitude"] = _failsafe_trials(
                sup, "altitude", trials, lambda: sup.set_setpoints(PILOT, depth=2.0), lambda: None,
                surfaced(sup), low)
        finally:
            sup.stop()
    actions = {"loop_watchdog": "disarm (the drives off)", "depth_limit": "surface", "altitude": "surface",
               "battery_critical": "surface", "leak": "surface", "estimate": "hold"}
    out: dict[str, Any] = {"trials": trials, "goal_s": 0.1, "triggers": {}}
    for name, (timeout, xs) in result.items():
        xs = sorted(xs)
        out["triggers"][name] = {"action": actions[name], "timeout_s": timeout,
                                 "median_s": statistics.median(xs), "p99_s": _percentile(xs, 0.99),
                                 "max_s": xs[-1]}
    return out
