"""What the fixed status bar shows: armed state, mode, pilot, recording, failsafes, a light for
each sensor, the drives, the planner, the control, the recording, and the vehicle (one light
for the loop watchdog, the depth limits, the battery, the registered auxiliary sensors (the
leak detector first), the estimate and the fins' pace), and the battery's figure.

:func:`bar_state` builds it from the console's snapshot
(:class:`~ucat_console.backend.supervisor.ConsoleState`, ``Supervisor.state()``) for one page
(the pilot reads "you"); the
page's script (:mod:`ucat_console.ui.page_script`) draws it. Lights are ``ok`` (green),
``warn`` (amber), ``bad`` (red) or ``off`` (grey: not on this robot), each with the reason
shown on hover.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ucat_console.backend.loop.modes import MODES
from ucat_console.backend.supervisor.console_state import ConsoleState, SafetyView

#: the lights, in the bar's order: sensor or part -> label
LIGHTS = {"imu": "IMU", "dvl": "DVL", "depth": "Depth", "drives": "Drives", "planner": "Planner",
          "control": "Control", "recording": "Recording", "loop_watchdog": "Loop",
          "limits": "Limits", "battery": "Battery",
          "estimate": "Estimate", "fins": "Fins", "vehicle": "Vehicle"}
ACTIONS = {"hold": "stops and holds its depth", "surface": "stops and rises to the surface",
           "disarm": "turns its motors off", "warn": "goes on (warn only)"}


@dataclass(frozen=True)
class Light:
    name: str
    state: str  # ok, warn, bad, off
    why: str

    def as_dict(self) -> dict[str, str]:
        return {"name": self.name, "state": self.state, "why": self.why}


def lights(st: ConsoleState, loading: str = "") -> list[Light]:
    """Each light's state and reason from the console's failsafes and readings."""
    safety = st.safety
    active = safety.active_states()
    out: list[Light] = []
    for s in safety.sensors:
        sensor, quiet, what = s.name, s.quiet, s.what
        rule = safety.rule(sensor)
        if sensor in active:
            out.append(Light(LIGHTS[sensor], "bad", f"failsafe {sensor}: {active[sensor].cause}"))
        elif quiet > 0.5 * rule.timeout or what:
            what = what or "no reading"
            out.append(Light(LIGHTS[sensor], "warn", f"{what} for {quiet:.1f} s (failsafe after {rule.timeout:g} s)"))
        else:
            out.append(Light(LIGHTS[sensor], "ok", f"valid reading {quiet:.2f} s ago"))
    if not st.has_drives:
        out.append(Light(LIGHTS["drives"], "off", "simulated fins: no motor drives"))
    elif "motor" in active:
        out.append(Light(LIGHTS["drives"], "bad", active["motor"].cause))
    else:
        faults = safety.motor_faults
        out.append(Light(LIGHTS["drives"], "warn" if faults else "ok",
                         ("reported: " + ", ".join(faults)) if faults else
                         ("powered" if st.armed else "off until armed")))
    late = safety.recent_late_plans
    if loading:
        out.append(Light(LIGHTS["planner"], "warn", loading))
    elif "planner_late" in active:
        out.append(Light(LIGHTS["planner"], "bad", active["planner_late"].cause))
    elif late:
        out.append(Light(LIGHTS["planner"], "warn",
                         f"{late} late plans in the last {safety.rule('planner_late').timeout:g} s"))
    else:
        overruns = st.plan_overruns
        out.append(Light(LIGHTS["planner"], "ok", "plans in time" + (
            f" ({overruns} plans since the start were ready after their hand-over deadline; "
            "a fin then starts its stroke a little later)" if overruns else "")))
    out.append(control_light(safety, active))
    out.append(recording_light(st))
    out.append(vehicle_light(vehicle_parts(st)))
    return out


def vehicle_parts(st: ConsoleState) -> list[Light]:
    """The parts of the Vehicle light: the loop watchdog, the depth limits, the battery, the
    registered auxiliary sensors (:func:`sensor_lights`), the estimate and the fins' pace,
    each its state and reason."""
    safety = st.safety
    now = st.t
    active = safety.active_states()
    parts: list[Light] = []
    rule = safety.rule("loop_watchdog")
    parts.append(failsafes_light(active, "loop_watchdog", ("loop_watchdog",), "ok",
                               f"stepping (watchdog after {rule.timeout:g} s: {rule.action})"))
    depth, alt = safety.depth, safety.altitude
    cfg = safety.config
    parts.append(failsafes_light(active, "limits", ("depth_limit", "altitude"), "ok", "; ".join([
        (f"depth {depth[1]:.2f} m" if depth else "no depth yet") + f" (limit {cfg.max_depth:g} m)",
        (f"altitude {alt[1]:.2f} m" if alt else "no altitude") + f" (minimum {cfg.min_altitude:g} m)"])))
    volts = safety.volts
    parts.append(failsafes_light(active, "battery", ("battery_critical", "battery_low"),
                               "ok" if volts is not None else "off", battery_text(safety, now)))
    parts += sensor_lights(st, active)
    innovation, t_state = safety.innovation, safety.estimate_t
    parts.append(failsafes_light(active, "estimate", ("estimate",), "ok", (
        f"attitude {innovation[1]:.3f} rad off the accelerometer's gravity" if innovation else
        "no attitude check at rest yet") + (f"; state {max(0.0, now - t_state):.2f} s old" if t_state is not None
                                            else "; no state estimate yet")))
    parts.append(fins_light(safety))
    return parts


def fins_light(safety: SafetyView) -> Light:
    """The fins' pace and force: amber while a fin is reported slow (its executed cycles take
    longer than their plans: a weak, lagging or stuck drive; the loop's ``fin_slow`` event) or
    the fins make more than the fin model's force (the loop's ``fin_force_scale``: the body
    layer asks them for less until they are identified), with what was reported."""
    off = [*safety.slow_fins, *([safety.fin_scale] if safety.fin_scale else [])]
    if off:
        return Light(LIGHTS["fins"], "warn", "; ".join(off))
    return Light(LIGHTS["fins"], "ok", "every fin keeps its plans' pace")


#: how bad each state is, for the light that stands for several
_WORST = {"off": 0, "ok": 1, "warn": 2, "bad": 3}


def vehicle_light(parts: list[Light]) -> Light:
    """One light for the loop watchdog, the depth limits, the battery, the auxiliary sensors, the
    estimate and the fins' pace (a bar of 1280 px keeps DISARM on screen): the worst of them,
    and each one's reason, the ones not green first."""
    worst = max(parts, key=lambda x: _WORST[x.state]).state
    ranked = sorted(parts, key=lambda x: -_WORST[x.state])
    return Light(LIGHTS["vehicle"], worst, "; ".join(f"{x.name}: {x.why}" for x in ranked))


def failsafes_light(active: dict[str, Any], light: str, names: tuple[str, ...], state: str, why: str) -> Light:
    """The light of failsafes of their own: red with their causes while one is active (amber
    when all of those only warn), else ``state`` and ``why``; ``light`` is one of
    :data:`LIGHTS` or a sensor's label."""
    label = LIGHTS.get(light, light)
    on = [active[n] for n in names if n in active]
    if on:
        return Light(label, "warn" if all(s.action == "warn" for s in on) else "bad",
                     "; ".join(f"failsafe {s.name}: {s.cause}" for s in on))
    return Light(label, state, why)


def sensor_lights(st: ConsoleState, active: dict[str, Any]) -> list[Light]:
    """Each registered auxiliary sensor's light (``backend.sensors``, in the snapshot): red
    while its failsafe is active, else what its entry's ``light`` made of its latest reading;
    grey on a robot without it."""
    return [failsafes_light(active, s.label, (s.failsafe,) if s.failsafe else (), s.state, s.why)
            for s in st.sensor_lights]


def battery_text(safety: SafetyView, now: float) -> str:
    """The bar's battery figure: the lowest drive supply voltage and the energy drawn."""
    volts, used = safety.volts, safety.energy_used
    cap = safety.config.battery_capacity
    energy = f"{used:.1f} of {cap:g} Wh used" if cap > 0 else f"{used:.1f} Wh used"
    if volts is None:
        return f"no supply voltage from the drives; {energy}"
    return f"{volts[1]:.1f} V" + (f" ({now - volts[0]:.0f} s ago)" if now - volts[0] > 2.0 else "") + f"; {energy}"


def recording_light(st: ConsoleState) -> Light:
    """Whether what the robot does is recorded: red when the recorder failed to write."""
    failed = st.recording.failed
    if failed:
        return Light(LIGHTS["recording"], "bad", f"recording FAILED: {failed}; Start recording again once "
                     "there is space, or Stop recording to acknowledge")
    sid = st.recording.session_id
    return Light(LIGHTS["recording"], "ok" if sid else "off", f"recording {sid}" if sid else "not recording")


def control_light(safety: SafetyView, active: dict[str, Any]) -> Light:
    """Whether the robot goes where it is sent: the tracking failsafe, the axes off their
    band, what the allocation cuts (the fins cannot give an axis what its loop asks)."""
    cut, off = safety.cut, safety.off_track
    if "tracking" in active:
        return Light(LIGHTS["control"], "bad", active["tracking"].cause + ("; cut: " + "; ".join(cut) if cut else ""))
    if off or cut:
        return Light(LIGHTS["control"], "warn", "; ".join(
            ([f"off its reference: {', '.join(off)}"] if off else []) + ([f"cut: {'; '.join(cut)}"] if cut else [])))
    return Light(LIGHTS["control"], "ok", "on its references; the fins give every axis what it asks")


def link_policy(st: ConsoleState) -> str:
    """What the robot does when the pilot's page is lost, as the banner says it."""
    rule = st.safety.config.pilot_gone
    then = (f", and {ACTIONS.get(rule.escalate, rule.escalate)} {rule.escalate_after:g} s later if no pilot "
            f"has taken control (then: {rule.escalate})" if rule.escalates else "")
    return (f"If this page was the pilot's, the robot {ACTIONS.get(rule.action, rule.action)} "
            f"{rule.timeout:g} s after the page's last answer (failsafe pilot_gone: {rule.action}){then}. "
            "The page reconnects by itself when the console is back; the token is needed again.")


def mode_label(mode: str) -> str:
    """The bar's short label of a mode (its registration's, ``backend.loop.modes``)."""
    return MODES[mode].short if mode in MODES else mode


#: the bar's label of each cost formulation (``mpc.formulation``), shown beside an MPC mode
FORMULATIONS = {"paper": "paper's cost", "closed_stroke": "closed-stroke cost"}


def formulation_label(st: ConsoleState) -> str:
    """The MPC's cost formulation as the bar shows it beside the mode ("" for a mode without the MPC)."""
    m = MODES.get(st.mode)
    if m is None or not m.mpc:
        return ""
    return FORMULATIONS.get(st.formulation, st.formulation)


def pilot_label(st: ConsoleState, client: int | None) -> str:
    p = st.access.pilot
    if p is None:
        return "none"
    if client is not None and p == client:
        return "you"
    name = st.access.pilot_name
    return f"{name} (client {p})" if name else f"client {p}"


def bar_state(st: ConsoleState, client: int | None, *, dark: bool, uuids: dict[str, str], loading: str = "",
              link_slow: bool = False, review: str = "", console: dict[str, str] | None = None) -> dict[str, Any]:
    """The bar's state for page ``client`` (JSON-ready); ``link_slow``: the page's link is
    slow and its telemetry thinned (:mod:`ucat_console.ui.link`); ``review``: the session
    the page plays in its Review tab ("" for none: no REVIEW badge); ``console``: this run
    of the console (``id``, ``started``), so that a page that comes back to another run says so."""
    return {
        "armed": bool(st.armed),
        "mode": mode_label(st.mode),
        "formulation": formulation_label(st),
        "pilot": pilot_label(st, client),
        "you_pilot": st.access.is_pilot(client),
        "recording": st.recording.session_id,
        "recording_failed": st.recording.failed,
        "failsafes": list(st.safety.active) + ([f"loop stopped: {st.fault}"] if st.fault else []),
        "lights": [x.as_dict() for x in lights(st, loading)],
        "battery": battery_text(st.safety, st.t),
        "link_policy": link_policy(st),
        "link_slow": bool(link_slow),
        "review": str(review),
        "dark": bool(dark),
        "console": dict(console or {}),
        **uuids,
    }
