"""Per-page control panels: pilot token and hand-over, arming, mode, setpoints, live tuning,
recording; plus the shared read-only panels (MPC introspection, failsafes, journal, events).

Each page gets its own :class:`ControlPanel` (``client.gui`` elements, built when the page
connects). A page that is not the pilot's sees the same controls disabled, and whatever
it sends anyway is refused by the supervisor: every callback passes the page's client id
to a supervisor command, which checks who asks and the value before anything changes. A
refused command shows its reason on that page (a message line and a notification) and
the inputs return to the values in force.

Values typed into inputs are drafts until applied ("Apply setpoints", "Apply tuning"),
so a half-typed number never reaches the robot. The tuning inputs are built from the
typed configuration: :data:`~ucat_console.backend.supervisor.TUNABLE` names the fields,
and each field's ``param`` metadata gives the label's range, the unit, the hint and the step.
"""

from __future__ import annotations

import contextlib

import html
import logging
import math
import time
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Any, Callable

from ucat_console.backend.access import AccessDenied, actor_name
from ucat_console.backend.loop.config import MODES
from ucat_console.backend.safety import FailsafeState
from ucat_console.backend.supervisor import SETPOINTS, TUNABLE, CommandRefused, JournalEntry
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.messages import FinPlan
from ucat_console.typedconf import describe_range

if TYPE_CHECKING:
    from ucat_console.ui.app import ConsoleApp

log = logging.getLogger(__name__)

MODE_LABELS = {"mpc": "MPC", "mpc_sync": "MPC, rear fins synchronised", "baseline": "baseline inverse model"}
REFUSALS = (AccessDenied, CommandRefused, ValueError)


def esc(text: object) -> str:
    """Text made safe for a markdown element (no HTML, no markdown markup)."""
    s = html.escape(str(text), quote=False)  # the page decodes &lt; &gt; &amp; but shows &#x27; as is
    for c in "\\`*_{}[]()#+!|~>":
        s = s.replace(c, "\\" + c)
    return s


def step_for(value: float, is_int: bool) -> float:
    """An input step of about a tenth of the value's magnitude (1 at least for integers)."""
    if value == 0 or not math.isfinite(value):
        return 1.0 if is_int else 0.01
    step = 10.0 ** math.floor(math.log10(abs(value))) / 10.0
    return max(1.0, step) if is_int else step


@dataclass(frozen=True)
class ParamSpec:
    """One tunable parameter as an input shows it."""

    key: str  # "mpc.lam_st", "pid.depth.kp"
    label: str
    hint: str
    step: float
    is_int: bool


def param_specs(tuning: dict[str, Any]) -> dict[str, list[ParamSpec]]:
    """Block -> input specs, from the typed configuration's field metadata."""
    out: dict[str, list[ParamSpec]] = {}
    for block, names in TUNABLE.items():
        cfg = tuning[block]
        by_name = {f.name: f for f in fields(cfg)}
        specs = []
        for name in names:
            f = by_name[name]
            value = getattr(cfg, name)
            if f.metadata.get("choices") is not None:
                continue  # a choice (mpc.formulation), not a number input

            is_int = isinstance(value, int)
            prefix = block.split(".", 1)[1] + " " if block.startswith("pid.") else ""
            label = f"{prefix}{name} {describe_range(f)}"
            doc = f.metadata.get("doc", "")
            hint = f"{doc} (allowed {describe_range(f)})"
            specs.append(ParamSpec(f"{block}.{name}", label, hint, step_for(value, is_int), is_int))
        out[block] = specs
    return out


BLOCK_TITLES = {
    "mpc": "MPC weights and horizon",
    "pid.velocity": "Velocity PID",
    "pid.depth": "Depth PID",
    "pid.yaw_rate": "Yaw-rate PID",
    "baseline": "Baseline",
}


class ControlPanel:
    """One page's controls; ``gui`` is that page's ``client.gui``."""

    def __init__(self, app: ConsoleApp, client_id: int, gui: Any, client: Any = None,
                 containers: dict[str, Any] | None = None,
                 allow: Callable[..., None] | None = None) -> None:
        """``allow(handle, pilot_only, max_len)`` tells the page guard which inputs this page
        may set (the page's own, pilot-only ones only while it is the pilot's)."""
        self.app = app
        self._allow = allow or (lambda handle, pilot_only, max_len=200: None)
        self.sup = app.sup
        self.cid = client_id
        self.gui = gui
        self.client = client
        self._pushed: dict[str, Any] = {}
        self._arm_nonce: str | None = None
        self.messages: list[str] = []
        c = containers or {}
        sup = self.sup
        env = sup.cfg.loop

        with within(c.get("pilot")):
            with gui.add_folder("Pilot", order=1.0):
                self.role = gui.add_markdown("")
                self.token = gui.add_text("Pilot token", "", hint="printed on the console's terminal at start-up")
                self.take = gui.add_button("Take control", icon=None)
                self.release = gui.add_button("Release control")
                self.handover = gui.add_button("Hand over", color="orange", visible=False)
                self.decline = gui.add_button("Decline", visible=False)
                self.arm = gui.add_button("Arm motors", color="green")
                self.disarm = gui.add_button("DISARM", color="red")
                self.mode = gui.add_dropdown("Mode", MODES, initial_value=sup.mode,
                                             hint=", ".join(f"{k}: {v}" for k, v in MODE_LABELS.items()))
                sp = sup.setpoints
                self.sp_inputs = {
                    "velocity": gui.add_number(f"Velocity m/s [-{env.max_velocity:g}, {env.max_velocity:g}]",
                                               float(sp.velocity), step=0.01, hint="forward velocity setpoint"),
                    "depth": gui.add_number(f"Depth m [0, {env.max_depth:g}]", float(sp.depth), step=0.05,
                                            hint="depth setpoint, positive down"),
                    "yaw_rate": gui.add_number(f"Yaw rate rad/s [-{env.max_yaw_rate:g}, {env.max_yaw_rate:g}]",
                                               float(sp.yaw_rate), step=0.01, hint="yaw rate setpoint"),
                }
                self.apply_sp = gui.add_button("Apply setpoints")
                self.message = gui.add_markdown("")

        self.params: dict[str, Any] = {}
        with within(c.get("tuning")):
            with gui.add_folder("Live tuning", order=10.0):
                self.apply_tuning = gui.add_button("Apply tuning", color="blue")
                self.revert = gui.add_button("Revert to saved")
                self.save = gui.add_button("Save as baseline")
                self.tuning_message = gui.add_markdown("")
                tuning = sup.tuning()
                for block, specs in param_specs(tuning).items():
                    with gui.add_folder(BLOCK_TITLES.get(block, block), expand_by_default=block == "mpc"):
                        for s in specs:
                            value = float(getattr(tuning[block], s.key.rpartition(".")[2]))
                            self.params[s.key] = gui.add_number(s.label, value, step=s.step, hint=s.hint)

        with within(c.get("session")):
            with gui.add_folder("View and recording", order=20.0):
                cfg = sup.cfg.console
                self.history = gui.add_number(f"Plot history s [5, {cfg.max_history:g}]", float(app.history),
                                              step=5.0, hint="the time window the plots show")
                self.rec_status = gui.add_markdown("")
                self.rec_start = gui.add_button("Start recording")
                self.rec_stop = gui.add_button("Stop recording")
                self.note = gui.add_text("Marker note", "")
                self.marker = gui.add_button("Add marker", hint="or press M")
        self.reset_drives = self.zero_depth = None
        if sup.has_drives:  # the robot's devices (or the rig's emulated ones)
            with within(c.get("safety")):
                with gui.add_folder("Devices", order=40.0):
                    self.reset_drives = gui.add_button(
                        "Reset drive faults", color="orange",
                        hint="after a drive fault (EMCY): reset it; the drive stays off until the next arming")
                    self.zero_depth = gui.add_button(
                        "Zero depth at the surface",
                        hint="with the robot floating at the surface, disarmed: its pressure becomes depth 0")
        self.faults: RigFaultInputs | None = None
        if sup.rig is not None:
            with within(c.get("safety")):
                self.faults = RigFaultInputs(gui)

        # the one-key marker (the note typed above goes with it)
        self.marker_key = gui.add_command("Add marker", description="a marker with the note typed in 'Marker note'",
                                          hotkey="M")

        self._wire()
        self._register_inputs()
        self.refresh(force=True)

    def _register_inputs(self) -> None:
        allow = self._allow
        for h in (self.token, self.take):
            allow(h, False)
        pilot = [self.release, self.handover, self.decline, self.arm, self.disarm, self.mode,
                 *self.sp_inputs.values(), self.apply_sp, self.apply_tuning, self.revert, self.save,
                 *self.params.values(), self.history, self.rec_start, self.rec_stop, self.marker,
                 self.reset_drives, self.zero_depth]
        if self.faults is not None:
            f = self.faults
            pilot += [f.device, f.fault, f.fin, f.code, f.duration, f.inject, f.clear]
        for h in pilot:
            allow(h, True)
        allow(self.note, True, 500)
        guard = getattr(self.app, "guard", None)
        if guard is not None and self.client is not None:
            guard.allow_command(self.marker_key, self.cid, pilot_only=True, name="Add marker (M)")

    # ------------------------------------------------------------------ callbacks
    def _wire(self) -> None:
        sup, cid = self.sup, self.cid
        self.take.on_click(self._guard(lambda: self._take_control()))
        self.release.on_click(self._guard(lambda: sup.release(cid)))
        self.handover.on_click(self._guard(lambda: sup.hand_over(cid, sup.access.pending)))  # type: ignore[arg-type]
        self.decline.on_click(self._guard(lambda: sup.decline(cid)))
        self.arm.on_click(self._guard(self._request_arm))
        self.disarm.on_click(self._guard(lambda: sup.disarm(cid, "operator")))
        self.mode.on_update(self._guard(lambda: sup.set_mode(cid, self.mode.value)))
        self.apply_sp.on_click(self._guard(self._apply_setpoints))
        self.apply_tuning.on_click(self._guard(self._apply_tuning, tuning=True))
        self.revert.on_click(self._guard(lambda: sup.revert_tuning(cid), tuning=True))
        self.save.on_click(self._guard(lambda: sup.save_baseline(cid), tuning=True))
        self.history.on_update(self._guard(self._set_history))
        self.rec_start.on_click(self._guard(lambda: sup.start_recording(cid)))
        self.rec_stop.on_click(self._guard(lambda: sup.stop_recording(cid)))
        self.marker.on_click(self._guard(self._add_marker))
        self.marker_key.on_trigger(self._guard(self._add_marker))
        if self.reset_drives is not None:
            self.reset_drives.on_click(self._guard(self._reset_drive_faults))
            self.zero_depth.on_click(self._guard(self._zero_depth))
        if self.faults is not None:
            f = self.faults
            f.device.on_update(lambda _: f.show_faults_of_device())
            f.inject.on_click(self._guard(self._inject_fault))
            f.clear.on_click(self._guard(self._clear_faults))

    def _guard(self, fn: Callable[[], Any], tuning: bool = False) -> Callable[[Any], None]:
        """A viser callback: page events only (not values set from code), refusals shown."""

        def cb(event: Any) -> None:
            if getattr(event, "client_id", None) is None and getattr(event, "client", None) is None:
                return  # a value set from code
            self.act(fn, tuning)

        return cb

    def act(self, fn: Callable[[], Any], tuning: bool = False) -> bool:
        """Run one command for this page; a refusal is shown and the inputs reverted."""
        try:
            fn()
        except REFUSALS as e:
            self.show(str(e), error=True, tuning=tuning)
            self.refresh(force=True)
            return False
        except Exception as e:  # a bug must not kill the page's callbacks silently
            log.exception("command from client %s failed", self.cid)
            self.show(f"internal error: {e}", error=True, tuning=tuning)
            return False
        self.app.request_refresh()
        return True

    def show(self, text: str, error: bool = False, tuning: bool = False) -> None:
        self.messages.append(text)
        stamp = time.strftime("%H:%M:%S")
        shown = f"{stamp} " + ("**Refused:** " if error else "") + esc(text)
        (self.tuning_message if tuning else self.message).content = shown
        if tuning:
            self.message.content = shown
        if error and self.client is not None:
            try:
                self.client.add_notification("Refused", text, color="red", auto_close_seconds=8.0)
            except Exception:
                log.debug("notification failed", exc_info=True)

    def _take_control(self) -> None:
        granted = self.sup.take_control(self.cid, self.token.value)
        self.token.value = ""
        self._pushed.pop("token", None)
        if granted:
            self.show("control taken")
        else:
            self.show(f"waiting for {actor_name(self.sup.access.pilot)} to hand over")  # type: ignore[arg-type]

    def _request_arm(self) -> None:
        nonce = self.sup.request_arm(self.cid)
        gui = self.gui
        modal = gui.add_modal("Arm the motors?")
        with modal:
            gui.add_markdown("The fins will move. Check that the water around the robot is clear.")
            confirm = gui.add_button("Confirm arm", color="green")
            cancel = gui.add_button("Cancel")
        self._allow(confirm, True)
        self._allow(cancel, True)

        def on_confirm(event: Any) -> None:
            modal.close()
            if self.act(lambda: self.sup.confirm_arm(self.cid, nonce)):
                self.show("armed")

        def on_cancel(event: Any) -> None:
            modal.close()
            self.sup.cancel_arm(self.cid)

        confirm.on_click(on_confirm)
        cancel.on_click(on_cancel)
        self._arm_nonce = nonce

    def _apply_setpoints(self) -> None:
        cur = self.sup.setpoints
        values = {k: self.sp_inputs[k].value for k in SETPOINTS}
        changed = {k: v for k, v in values.items() if v != getattr(cur, k)}
        if not changed:
            self.show("setpoints unchanged")
            return
        self.sup.set_setpoints(self.cid, **changed)
        self.show("setpoints applied: " + ", ".join(f"{k} {v:g}" for k, v in changed.items()))

    def _apply_tuning(self) -> None:
        changes = {}
        for key, handle in self.params.items():
            if handle.value != self.sup.param_value(key):
                changes[key] = handle.value
        if not changes:
            self.show("tuning unchanged", tuning=True)
            return
        self.sup.set_params(self.cid, changes)
        self.show("applied: " + ", ".join(f"{k} = {v:g}" for k, v in changes.items()), tuning=True)

    def _set_history(self) -> None:
        self.app.set_history(self.cid, self.history.value)

    def _add_marker(self) -> None:
        self.sup.add_marker(self.cid, self.note.value)
        self.note.value = ""
        self.show("marker added")

    def _reset_drive_faults(self) -> None:
        self.sup.reset_drive_faults(self.cid)
        self.show("drive faults reset: the drives stay off until armed")

    def _zero_depth(self) -> None:
        p = self.sup.zero_depth(self.cid)
        self.show(f"depth zeroed: surface pressure {p:.1f} Pa")

    def _inject_fault(self) -> None:
        f = self.faults
        assert f is not None
        event = self.sup.inject_fault(self.cid, f.device.value, f.fault.value, **f.arguments())
        self.show(event.message)

    def _clear_faults(self) -> None:
        f = self.faults
        assert f is not None
        self.sup.clear_fault(self.cid, f.device.value)
        self.show(f"{f.device.value}: faults cleared")

    # ------------------------------------------------------------------ state -> page
    def _push(self, key: str, handle: Any, value: Any, force: bool) -> None:
        if force or self._pushed.get(key, _UNSET) != value:
            handle.value = value
            self._pushed[key] = value

    def refresh(self, force: bool = False) -> None:
        """Show the supervisor's state: values in force, which controls this page may use."""
        sup, cid = self.sup, self.cid
        pilot = sup.access.is_pilot(cid)
        pending = sup.access.pending
        p = sup.access.pilot
        if pilot:
            role = "You are **the pilot**."
            if pending is not None:
                role += f" Client {pending} asks for control."
        else:
            role = f"Read-only (client {cid}). Pilot: {'client ' + str(p) if p is not None else 'none'}."
            if pending == cid:
                role += " Waiting for the pilot's hand-over."
        self.role.content = role
        for h in (self.token, self.take):
            h.disabled = pilot
        self.release.disabled = not pilot
        self.handover.visible = pilot and pending is not None
        self.decline.visible = pilot and pending is not None
        if pending is not None:
            self.handover.label = f"Hand over to client {pending}"
        self.arm.disabled = not pilot or sup.armed
        self.disarm.disabled = not pilot
        self.mode.disabled = not pilot
        self._push("mode", self.mode, sup.mode, force)
        sp = sup.setpoints
        for k in SETPOINTS:
            self.sp_inputs[k].disabled = not pilot
            self._push(f"sp.{k}", self.sp_inputs[k], float(getattr(sp, k)), force)
        self.apply_sp.disabled = not pilot
        for key, handle in self.params.items():
            handle.disabled = not pilot
            self._push(key, handle, float(sup.param_value(key)), force)
        for h in (self.apply_tuning, self.revert, self.save, self.history, self.rec_start,
                  self.rec_stop, self.note, self.marker, self.marker_key):
            h.disabled = not pilot
        self._push("history", self.history, float(self.app.history), force)
        rec = sup.recorder
        self.rec_status.content = (f"Recording **{esc(rec.session_id)}**" if rec.recording else "Not recording")
        if self.reset_drives is not None:
            self.reset_drives.disabled = self.zero_depth.disabled = not pilot or sup.armed
        if self.faults is not None:
            self.faults.enable(pilot)


class RigFaultInputs:
    """Fault injection on the simulated rig's device emulators (Safety tab): rehearsing what
    the console and the failsafes do when a drive faults or a sensor goes silent, garbled,
    invalid or slow. Only built when the robot is the simulated rig; only the pilot injects."""

    def __init__(self, gui: Any) -> None:
        from ucat_console.backend.sim_rig import DEFAULT_EMCY, EMULATOR_FAULTS

        self.faults_of = EMULATOR_FAULTS
        device = next(iter(EMULATOR_FAULTS))
        with gui.add_folder("Rig faults (simulated devices)", order=50.0):
            self.device = gui.add_dropdown("Device", tuple(EMULATOR_FAULTS), initial_value=device)
            self.fault = gui.add_dropdown("Fault", EMULATOR_FAULTS[device])
            self.fin = gui.add_number("Fin [0, 3]", 0, min=0, max=3, step=1, hint="EPOS2 faults: the fin's drive")
            self.code = gui.add_text("EMCY code", f"0x{DEFAULT_EMCY:04X}",
                                     hint="EPOS2 emcy: the error code the drive reports (0x2310: overcurrent)")
            self.duration = gui.add_number("Duration s (0: until cleared)", 0.0, min=0.0, max=3600.0, step=1.0,
                                           hint="the fault ends by itself after this long (not for emcy: "
                                                "a drive fault stays until reset)")
            self.inject = gui.add_button("Inject fault", color="orange")
            self.clear = gui.add_button("Clear the device's faults")

    def show_faults_of_device(self) -> None:
        faults = self.faults_of.get(self.device.value, ())
        self.fault.options = faults
        if faults and self.fault.value not in faults:
            self.fault.value = faults[0]

    def arguments(self) -> dict[str, Any]:
        """The typed arguments of the chosen fault; CommandRefused naming a bad entry."""
        kw: dict[str, Any] = {}
        epos2, emcy = self.device.value == "epos2", self.fault.value == "emcy"
        if epos2:
            fin = self.fin.value
            if not (isinstance(fin, (int, float)) and math.isfinite(fin) and fin == int(fin)):
                raise CommandRefused(f"fin: expected a fin index 0..3, got {fin!r}")
            kw["fin"] = int(fin)
        if epos2 and emcy:
            text = str(self.code.value).strip()
            try:
                kw["code"] = int(text, 0)
            except ValueError:
                raise CommandRefused(f"EMCY code: {text!r} is not a number; write it as e.g. 0x2310") from None
        elif self.duration.value:
            kw["duration"] = float(self.duration.value)
        return kw

    def enable(self, pilot: bool) -> None:
        for h in (self.device, self.fault, self.fin, self.code, self.duration, self.inject, self.clear):
            h.disabled = not pilot


_UNSET = object()


def within(container: Any) -> Any:
    """``with within(container):`` enters the container when one is given."""
    return contextlib.nullcontext() if container is None else container


# ---------------------------------------------------------------------- shared panels
def introspection_markdown(plans: list[FinPlan | None], late_plans: int, overruns: int, mode: str) -> str:
    """Each fin's last plan: strokes and rates, cost split, solve time, late flag."""
    lines = [
        f"Mode **{esc(mode)}** · late plans **{late_plans}** · hand-over overruns **{overruns}**",
        "",
        "| fin | St | d1, d2 (rad) | w1, w2 (rad/s) | cost F / St / A / D = total | solve ms | late |",
        "|---|---|---|---|---|---|---|",
    ]
    baseline = []
    for i, p in enumerate(plans):
        if p is None:
            lines.append(f"| {i} | - | - | - | - | - | - |")
            continue
        d1, d2, w1, w2 = p.u
        lines.append(
            f"| {i} | {p.st:.3f} | {d1:+.2f}, {d2:+.2f} | {w1:.2f}, {w2:.2f} | "
            f"{p.cost_force:.3g} / {p.cost_strouhal:.3g} / {p.cost_amplitude:.3g} / {p.cost_smoothness:.3g}"
            f" = {p.cost_total:.3g} | {p.solve_time * 1e3:.1f} | {'yes' if p.late else 'no'} |"
        )
        if p.mode == "baseline":
            baseline.append(f"fin {i}: amplitude {p.amplitude:.2f} rad, centre {p.centre:+.2f} rad")
    if baseline:
        lines += ["", "Baseline: " + "; ".join(baseline)]
    return "\n".join(lines)


def failsafe_markdown(states: list[FailsafeState], now: float) -> str:
    lines = ["| failsafe | action | after | state | cause |", "|---|---|---|---|---|"]
    for s in states:
        state = f"**ACTIVE** {now - s.since:.0f} s" if s.active and s.since is not None else "ok"
        lines.append(f"| {s.name} | {s.action} | {s.timeout:g} s | {state} | {esc(s.cause) if s.active else ''} |")
    return "\n".join(lines)


def journal_markdown(entries: list[JournalEntry]) -> str:
    if not entries:
        return "Journal: no changes yet."
    return "Journal (newest first):\n\n" + "\n".join(f"- {esc(e.text())}" for e in reversed(entries))


def events_markdown(events: list[Event]) -> str:
    if not events:
        return "No events yet."
    out = []
    for e in reversed(events):
        mark = "**" if e.level in ("error", "fatal") else ""
        out.append(f"- {e.t:7.1f} s {mark}{esc(e.source)} {esc(e.code)}{mark}: {esc(e.message)}")
    return "\n".join(out)


def status_markdown(*, armed: bool, mode: str, pilot: int | None, t: float, depth: float | None,
                    velocity: float | None, failsafes: tuple[str, ...], recording: str, fault: str) -> str:
    parts = ["**ARMED**" if armed else "disarmed", f"mode **{esc(mode)}**",
             f"pilot: {'client ' + str(pilot) if pilot is not None else 'none'}", f"t {t:.1f} s"]
    if depth is not None and math.isfinite(depth):
        parts.append(f"depth {depth:.2f} m")
    if velocity is not None and math.isfinite(velocity):
        parts.append(f"u {velocity:+.2f} m/s")
    parts.append(f"recording {esc(recording)}" if recording else "not recording")
    text = " · ".join(parts)
    if failsafes:
        text += "\n\n**FAILSAFE: " + ", ".join(esc(f) for f in failsafes) + "**"
    if fault:
        text += f"\n\n**LOOP STOPPED: {esc(fault)}**"
    return text
