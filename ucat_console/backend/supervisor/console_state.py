"""The console as the page shows it: one immutable snapshot, :class:`ConsoleState`.

The page (``ui/``) renders the console from a snapshot and sends commands through the
supervisor's methods; it reads no part of the supervisor (its access control, failsafes,
recorder, loop). :meth:`Supervisor.state() <ucat_console.backend.supervisor.Supervisor.state>`
builds one with :func:`build_state`, the one place that reads the parts for the page.

A snapshot holds values only (frozen dataclasses, tuples, the frozen configuration blocks):
no live object, no lock, no callable, so a page may keep it, pass it around and read it
from any thread. It is built on each call, without a lock of its own (each part answers
under its own short lock, as for any reading), so a DISARM never waits for one; the page
builds one per refresh and renders every page from it. Its parts are read one after the
other: a change that lands while it is built may show in one part and not yet in another,
and shows in full in the next snapshot.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ucat_console.backend.access import Actor
from ucat_console.backend.failsafe_config import FailsafeConfig, FailsafeRule
from ucat_console.backend.review.effects import Effect
from ucat_console.backend.safety import SENSORS, FailsafeState
from ucat_console.control.allocation import BodySetpoints


@dataclass(frozen=True)
class AccessView:
    """Who flies and who watches."""

    pilot: Actor  # the pilot's client id (None: nobody flies)
    pilot_name: str  # the name the pilot's page chose ("" when none)
    pending: int | None  # the client waiting for the pilot's hand-over
    clients: int  # the pages connected (the pilot's among them)

    def is_pilot(self, client: int | None) -> bool:
        """Whether page ``client`` is the pilot's."""
        return client is not None and self.pilot is not None and client == self.pilot

    @property
    def viewers(self) -> int:
        """The pages connected that are not the pilot's."""
        return max(0, self.clients - (1 if self.pilot is not None else 0))


@dataclass(frozen=True)
class RecordingView:
    """The recording: its session ("" when not recording) and why it failed ("" when it did not)."""

    session_id: str
    failed: str

    @property
    def recording(self) -> bool:
        return bool(self.session_id)


@dataclass(frozen=True)
class SensorView:
    """One sensor's last valid reading: seconds since it, and what was reported since ("" nothing)."""

    name: str
    quiet: float
    what: str


@dataclass(frozen=True)
class SafetyView:
    """The failsafes and what the status bar's lights show of the robot's state."""

    config: FailsafeConfig  # the rules, as configured
    failsafes: tuple[FailsafeState, ...]  # every failsafe, in the configuration's order
    sensors: tuple[SensorView, ...]  # in :data:`~ucat_console.backend.safety.SENSORS` order
    motor_faults: tuple[str, ...]
    recent_late_plans: int
    depth: tuple[float, float] | None  # the last valid depth (time, m)
    altitude: tuple[float, float] | None  # the last valid DVL altitude (time, m)
    volts: tuple[float, float] | None  # the last lowest drive supply voltage (time, V)
    energy_used: float  # Wh the drives drew since the start
    innovation: tuple[float, float] | None  # the last attitude innovation at rest (time, rad)
    estimate_t: float | None  # the last body state's time
    slow_fins: tuple[str, ...]
    fin_scale: str  # the fins' force against the fin model's, while the body layer follows it ("": as the model)
    cut: tuple[str, ...]  # the axes the allocation cuts
    off_track: tuple[str, ...]  # the tracked axes off their band

    def rule(self, name: str) -> FailsafeRule:
        """Failsafe ``name``'s rule as configured (ValueError naming the failsafes for another)."""
        return self.config.rule(name)

    @property
    def active(self) -> tuple[str, ...]:
        """The failsafes active, in the configuration's order."""
        return tuple(s.name for s in self.failsafes if s.active)

    def active_states(self) -> dict[str, FailsafeState]:
        return {s.name: s for s in self.failsafes if s.active}

    def sensor(self, name: str) -> SensorView:
        return next(s for s in self.sensors if s.name == name)

    @property
    def warn_only(self) -> tuple[str, ...]:
        """The protective failsafes configured only to warn."""
        return self.config.warn_only()


@dataclass(frozen=True)
class SensorLight:
    """A registered auxiliary sensor's light (``backend.sensors``) while its failsafe is not
    active: what its entry's ``light`` made of its latest reading."""

    label: str
    failsafe: str  # its failsafe's name ("" none)
    state: str  # ok, warn, bad; off on a robot without it
    why: str


def sensor_lights(sensors: Any, now: float, rule: Any) -> tuple[SensorLight, ...]:
    """Each registered sensor's light from the poller ``sensors`` (a broken light function
    is said on the light, never takes the snapshot down)."""
    out = []
    for entry, status in sensors.statuses(now, rule):
        if status is None:
            state, why = "off", entry.absent
        else:
            try:
                state, why = entry.light(status)
            except Exception as e:  # noqa: BLE001: a registered entry's own code
                state, why = "warn", f"its light failed: {type(e).__name__}: {e}"
            if state not in ("ok", "warn", "bad"):
                state, why = "warn", f"its light gave {state!r} (not ok, warn or bad): {why}"
        fs = entry.failsafe
        out.append(SensorLight(entry.label, fs.name if fs is not None else "", state, str(why)))
    return tuple(out)


def camera_lights(camera: Any, now: float) -> tuple[SensorLight, ...]:
    """The camera's light (none without a camera): never a failsafe's."""
    if camera is None:
        return ()
    state, why = camera.light(now)
    return (SensorLight("Camera", "", state, why),)


@dataclass(frozen=True)
class ManoeuvreView:
    """The identification manoeuvre last started."""

    session: str
    finished: bool
    progress: float  # share done, 0-1

    @property
    def running(self) -> bool:
        return not self.finished


@dataclass(frozen=True)
class ScriptView:
    """The scripted manoeuvre last started."""

    name: str
    finished: bool
    progress: float  # share done, 0-1
    segment: int  # the segment running, from 0
    segments: int  # how many it has
    reason: str  # why it ended ("" while it runs)
    lines: tuple[str, ...]  # each measured segment: its label and figures

    @property
    def running(self) -> bool:
        return not self.finished


@dataclass(frozen=True)
class SeekView:
    """The seek of efficiency last started (docs/seek.md)."""

    finished: bool
    reason: str  # why it ended ("" while it runs)
    phase: str  # settle, measure, recover, watch, done
    candidates: int  # measured so far
    max_candidates: int  # measures of one search: its candidates and their second measures
    searches: int  # searches begun (the first and each re-seek)
    best: tuple[tuple[str, float], ...]  # the best accepted candidate's values (empty: none yet)
    best_energy: tuple[float, float, float] | None  # its energy per metre and interval (J/m)
    time_left: float  # s of loop time until the present search ends (0: watching or ended)
    lines: tuple[str, ...]  # the latest candidates, each in a line

    @property
    def running(self) -> bool:
        return not self.finished


def seek_view(run: Any) -> SeekView | None:
    """The snapshot of a :class:`~.seek_run.SeekRun` (None: none)."""
    if run is None:
        return None
    best = run.best
    e = None if best is None or best.energy is None else (best.energy.value, best.energy.lo, best.energy.hi)
    lines = tuple(f"#{c.index}: {c.verdict} ({', '.join(f'{k} {v:.4g}' for k, v in c.values)}"
                  + (f", #{c.confirms} again" if c.confirms is not None else "") + ")"
                  + (f": {c.energy.value:.1f} J/m" if c.energy is not None else "") for c in run.candidates[-8:])
    return SeekView(run.finished, run.reason, run.phase, len(run.candidates),
                    run.cfg.max_candidates + run.cfg.confirm,
                    run.searches, () if best is None else best.values, e, run.time_left(), lines)


@dataclass(frozen=True)
class Limits:
    """The limits the page shows beside its inputs."""

    max_velocity: float  # m/s
    max_depth: float  # m
    max_yaw_rate: float  # rad/s
    handover_timeout: float  # s a request for control waits for the pilot

    def envelope(self) -> dict[str, tuple[float, float]]:
        """Each setpoint's allowed range."""
        return {"velocity": (-self.max_velocity, self.max_velocity),
                "yaw_rate": (-self.max_yaw_rate, self.max_yaw_rate), "depth": (0.0, self.max_depth)}


@dataclass(frozen=True)
class ConsoleState:
    """The console at loop time ``t``, as the page shows it (module docstring)."""

    t: float
    robot: str  # the robot's name (``AppConfig.robot``)
    armed: bool
    mode: str  # the commanded mode
    formulation: str  # the MPC's cost formulation in force (``mpc.formulation``)
    setpoints: BodySetpoints  # the commanded setpoints
    fault: str  # why the closed loop stopped ("" while it runs)
    late_plans: int
    plan_overruns: int
    has_drives: bool  # the fins are moved by motor drives
    has_rig: bool  # the robot is the simulated rig (faults may be injected)
    start_depth: float  # where the simulated robot starts (m, positive down)
    access: AccessView
    recording: RecordingView
    safety: SafetyView
    manoeuvre: ManoeuvreView | None  # None: none started yet
    script: ScriptView | None  # None: no scripted manoeuvre started yet
    seek: SeekView | None  # None: no seek started yet
    limits: Limits
    effects: tuple[Effect, ...]  # the latest changes and their figures, newest first
    sensor_lights: tuple[SensorLight, ...]  # the registered auxiliary sensors', in registration order

    @property
    def failsafes(self) -> tuple[str, ...]:
        """The failsafes active."""
        return self.safety.active


def safety_view(safety: Any, now: float) -> SafetyView:
    """What the safety monitor ``safety`` holds at loop time ``now``, as values."""
    depth, altitude = safety.envelope()
    volts, used = safety.battery()
    innovation, estimate_t = safety.estimate()
    cut, off = safety.control()
    return SafetyView(
        config=safety.cfg, failsafes=tuple(safety.states()),
        sensors=tuple(SensorView(s, *safety.sensor_silence(s, now)) for s in SENSORS),
        motor_faults=tuple(safety.motor_faults()), recent_late_plans=safety.recent_late_plans(),
        depth=depth, altitude=altitude, volts=volts, energy_used=used, innovation=innovation,
        estimate_t=estimate_t, slow_fins=tuple(safety.slow_fins()),
        fin_scale=safety.fin_scale(),
        cut=tuple(cut), off_track=tuple(off),
    )


def build_state(sup: Any) -> ConsoleState:
    """The snapshot of supervisor ``sup`` now (the one place that reads its parts for the
    page; ``Any``: this module is the supervisor's, which imports it)."""
    cfg = sup.cfg
    now = sup.loop.time
    safety = sup.safety
    access = sup.access
    pilot = access.pilot
    run = sup.manoeuvre
    script = sup.script_run
    return ConsoleState(
        t=now, robot=cfg.robot, armed=sup.gate.armed, mode=sup.loop.mode,
        formulation=str(sup.param_value("mpc.formulation")), setpoints=sup.loop.setpoints,
        fault=sup.fault, late_plans=sup.loop.late_plans, plan_overruns=sup.loop.plan_overruns,
        has_drives=sup.gate.has_drives, has_rig=sup.rig is not None,
        start_depth=sup.start_depth,
        access=AccessView(pilot=pilot, pilot_name=access.name(pilot) if isinstance(pilot, int) else "",
                          pending=access.pending, clients=len(access.clients)),
        recording=RecordingView(session_id=sup.recording.session_id, failed=sup.recording.failed),
        safety=safety_view(safety, now),
        manoeuvre=None if run is None else ManoeuvreView(run.session, run.finished, run.progress),
        script=None if script is None else ScriptView(
            script.name, script.finished, script.progress, script.segment, len(script.script.segments),
            script.reason, tuple(script.lines)),
        seek=seek_view(sup.seek_run),
        limits=Limits(cfg.loop.max_velocity, cfg.loop.max_depth, cfg.loop.max_yaw_rate,
                      cfg.access.handover_timeout),
        effects=tuple(sup.effects.entries()),
        sensor_lights=sensor_lights(sup.sensors, now, safety.rule) + camera_lights(sup.camera, now),
    )
