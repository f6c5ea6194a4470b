# Over 600 lines: one page's controls (setpoints, arming, tuning, recording, events, theme) share that page's handles and its pilot state.
"""Per-page control panels: pilot token and hand-over, arming, mode, setpoints, live tuning,
recording; plus the shared read-only panels (MPC introspection, failsafes, journal, events).

Each page gets its own :class:`ControlPanel` (``client.gui`` elements, built when the page
connects). A page that is not the pilot's sees the same controls disabled, and whatever
it sends anyway is refused by the supervisor: every callback passes the page's client id
to a supervisor command, which checks who asks and the value before anything changes. A
refused command shows its reason on that page (a message line and a notification) and
the inputs return to the values in force.

The pilot's safety commands (DISARM, the Esc key, the Space key's stop) are registered with
the page guard as *urgent*: they run on the guard's own thread, never behind other pages'
callbacks. Listing the sessions (for the identification) is a job of the console's
:class:`~ucat_console.ui.page_jobs.PageJobs`. A page that closes while one of its callbacks
runs is not an error: what the callback would still show goes nowhere, quietly.

Values typed into inputs are drafts until applied ("Apply setpoints", "Apply tuning"),
so a half-typed number never reaches the robot. The tuning inputs are built from the
typed configuration: the loop's registered blocks (``backend.loop.blocks``) name the
fields and their folders' titles, and each field's ``param`` metadata gives the label's
range, the unit, the hint and the step.
"""

from __future__ import annotations


import logging
import time
from typing import Any, Callable, Protocol

from ucat_console.backend.access import MAX_NAME, AccessDenied, actor_name
from ucat_console.backend.loop.blocks import block as tuning_block
from ucat_console.backend.loop.modes import MODES
from ucat_console.backend.supervisor import SETPOINTS, CommandRefused, ConsoleState, Supervisor
from ucat_console.telemetry.events import Event
from ucat_console.ui.driving import KEY_MAP, KEYS, Driving
from ucat_console.ui.markdown import _set, esc, events_markdown, within
from ucat_console.ui.identify_inputs import IdentifyInputs
from ucat_console.ui.manoeuvre_inputs import ManoeuvreInputs
from ucat_console.ui.seek_inputs import SeekInputs
from ucat_console.ui.rig_faults import RigFaultInputs
from ucat_console.ui.tuning_inputs import param_specs

log = logging.getLogger(__name__)

REFUSALS = (AccessDenied, CommandRefused, ValueError)
#: the events list's filters: name -> the levels shown
SEVERITY_FILTERS = {
    "all": frozenset({"debug", "info", "warning", "error", "fatal"}),
    "warnings and errors": frozenset({"warning", "error", "fatal"}),
    "errors": frozenset({"error", "fatal"}),
}


class PanelHost(Protocol):
    """What a page's controls use of the console app (``ui.app.ConsoleApp``); the app may
    also offer ``session_list``, ``sessions_dir``, ``guard``, ``page_present`` and
    ``submit_job``, which the panel uses when present."""

    sup: Supervisor
    history: float
    events_seen: int

    def recent_events(self) -> list[Event]: ...
    def request_refresh(self) -> None: ...
    def frame_robot(self, cid: int) -> None: ...
    def set_history(self, who: Any, seconds: object) -> None: ...
    def toggle_theme(self, cid: int) -> None: ...


class ControlPanel:
    """One page's controls; ``gui`` is that page's ``client.gui``."""

    def __init__(self, app: PanelHost, client_id: int, gui: Any, client: Any = None,
                 containers: dict[str, Any] | None = None,
                 allow: Callable[..., None] | None = None) -> None:
        """``allow(handle, pilot_only, max_len, urgent)`` tells the page guard which inputs this
        page may set (the page's own, pilot-only ones only while it is the pilot's; ``urgent``:
        a safety command's action, run by the guard)."""
        self.app = app
        self._allow = allow or (lambda handle, pilot_only, max_len=200, urgent=None: None)
        self.sup = app.sup
        self.cid = client_id
        self.gui = gui
        self.client = client
        self._pushed: dict[str, Any] = {}
        #: what this page applied last (input key -> value) while its feedback line says so
        self._applied: dict[str, Any] = {}
        self._labels: dict[str, str] = {}  # each input's own label (a draft mark is added to it)
        self._arm_nonce: str | None = None
        self.messages: list[str] = []
        c = containers or {}
        sup = self.sup
        st = sup.state()
        env = st.limits

        with within(c.get("pilot")):
            with gui.add_folder("Pilot", order=1.0):
                self.role = gui.add_markdown("")
                self.token = gui.add_text("Pilot token", "", hint="printed on the console's terminal at start-up")
                self.take = gui.add_button("Take control", icon=None)
                self.release = gui.add_button("Release control")
                self.handover = gui.add_button("Hand over", color="orange", visible=False)
                self.decline = gui.add_button("Decline", visible=False)
                self.arm = gui.add_button("Arm motors", color="green")
                # the status bar's DISARM button (and Esc) press this one; it is not drawn here
                self.disarm = gui.add_button("DISARM", color="red", visible=False)
                self.mode = gui.add_dropdown("Mode", tuple(MODES), initial_value=st.mode,
                                             hint=", ".join(f"{m.name}: {m.label}" for m in MODES.values()))
                sp = st.setpoints
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
                self.key_map = gui.add_markdown(KEY_MAP)
                self.name = gui.add_text("Your name", "", hint="shown to the other pages when you fly "
                                         f"(at most {MAX_NAME} characters)")
                # the page's script sends the gamepad's sticks and the theme switch here
                self.drive_input = gui.add_text("gamepad", "", visible=False)
                self.theme_button = gui.add_button("theme", visible=False)
            self.manoeuvres = ManoeuvreInputs(gui, sup, client_id, lambda fn: self.act(fn), self._allow, self.show)
            self.seek = SeekInputs(gui, sup, client_id, self.show)

        self.params: dict[str, Any] = {}
        with within(c.get("tuning")):
            with gui.add_folder("Live tuning", order=10.0):
                self.apply_tuning = gui.add_button("Apply tuning", color="blue")
                self.revert = gui.add_button("Revert to saved")
                self.undo = gui.add_button("Undo last change")
                self.save = gui.add_button("Save as baseline")
                self.tuning_message = gui.add_markdown("")
                tuning = sup.tuning()
                for block, specs in param_specs(tuning).items():
                    with gui.add_folder(tuning_block(block).title, expand_by_default=block == "mpc"):
                        for s in specs:
                            value = getattr(tuning[block], s.key.rpartition(".")[2])
                            if s.choices is not None:
                                self.params[s.key] = gui.add_dropdown(s.label, s.choices, initial_value=value,
                                                                      hint=s.hint)
                            else:
                                self.params[s.key] = gui.add_number(s.label, float(value), step=s.step,
                                                                    hint=s.hint)

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
                self.follow = gui.add_checkbox("Follow the robot", True, hint="the 3-D view keeps the robot in view")
                self.frame = gui.add_button("Frame the robot", hint="this page's 3-D view looks at the robot "
                                            "(the live one, or the one this page reviews) from behind and above")
            listing = getattr(app, "session_list", None)
            self.identify = IdentifyInputs(gui, sup, client_id, getattr(app, "sessions_dir", None) or
                                           sup.sessions_dir, self.show,
                                           getattr(app, "request_refresh", lambda: None),
                                           sessions=(lambda: listing.sessions()) if listing is not None else None)
            with gui.add_folder("Events", order=30.0):
                self.severity = gui.add_dropdown("Show", tuple(SEVERITY_FILTERS), initial_value="warnings and errors",
                                                 hint="which events the list shows")
                self.events = gui.add_markdown("No events yet.")
        self.reset_drives = self.zero_depth = None
        if st.has_drives:  # the robot's devices (or the rig's emulated ones)
            with within(c.get("safety")):
                with gui.add_folder("Devices", order=40.0):
                    self.reset_drives = gui.add_button(
                        "Reset drive faults", color="orange",
                        hint="after a drive fault (EMCY): reset it; the drive stays off until the next arming")
                    self.zero_depth = gui.add_button(
                        "Zero depth at the surface",
                        hint="with the robot floating at the surface, disarmed: its pressure becomes depth 0")
        self.faults: RigFaultInputs | None = None
        if st.has_rig:
            with within(c.get("safety")):
                self.faults = RigFaultInputs(gui, sup.fault_tables())

        # the one-key marker (the note typed above goes with it)
        self.marker_key = gui.add_command("Add marker", description="a marker with the note typed in 'Marker note'",
                                          hotkey="M")
        # manual driving and DISARM from the keyboard
        self.driving = Driving(sup, self.cid, lambda fn: self.act(fn))
        self.key_commands = {key: gui.add_command(f"Drive: {label}", description=f"key {key}", hotkey=key)
                             for key, (_, _, label) in KEYS.items()}
        self.stop_key = gui.add_command("Drive: stop", description="velocity and yaw rate to 0", hotkey="space")
        self.disarm_key = gui.add_command("DISARM", description="motors off now", hotkey="escape")
        self._events_shown = ""
        self._events_seen: tuple[int, str] | None = None
        self._listed: tuple[bool, bool, int] | None = None
        #: the page's other lists of the sessions (its Review tab's, its comparison's runs):
        #: listed again, with the identification's, whenever a recording ends
        self.session_lists: list[Callable[[], Any]] = []

        self._wire()
        self._register_inputs()
        self.refresh(force=True)

    def _register_inputs(self) -> None:
        allow = self._allow
        for h in (self.token, self.take):
            allow(h, False)
        allow(self.disarm, True, urgent=self._disarm_now)
        pilot = [self.release, self.handover, self.decline, self.arm, self.mode,
                 *self.sp_inputs.values(), self.apply_sp, self.apply_tuning, self.revert, self.undo, self.save,
                 *self.params.values(), self.history, self.rec_start, self.rec_stop, self.marker,
                 self.reset_drives, self.zero_depth, *self.identify.handles(), *self.manoeuvres.handles(),
                 *self.seek.handles()]
        if self.faults is not None:
            f = self.faults
            pilot += [f.device, f.fault, f.fin, f.code, f.duration, f.inject, f.clear]
        for h in pilot:
            allow(h, True)
        allow(self.note, True, 500)
        allow(self.drive_input, True, 200)
        for h in (self.name, self.follow, self.frame, self.severity, self.theme_button):
            allow(h, False, MAX_NAME if h is self.name else 200)
        guard = getattr(self.app, "guard", None)
        if guard is not None and self.client is not None:
            for cmd in (self.marker_key, *self.key_commands.values()):
                guard.allow_command(cmd, self.cid, pilot_only=True)
            guard.allow_command(self.disarm_key, self.cid, pilot_only=True, urgent=self._disarm_now)
            guard.allow_command(self.stop_key, self.cid, pilot_only=True, urgent=self._stop_now)

    def _disarm_now(self) -> None:
        """DISARM from this page (the page guard's safety thread, or viser's callback)."""
        self.act(lambda: self.sup.disarm(self.cid, "operator"))

    def _stop_now(self) -> None:
        """The Space key: velocity and yaw rate 0 (as the page guard's safety command)."""
        self.act(self.driving.stop)

    # ------------------------------------------------------------------ callbacks
    def _wire(self) -> None:
        sup, cid = self.sup, self.cid
        self.take.on_click(self._guard(lambda: self._take_control()))
        self.release.on_click(self._guard(lambda: sup.release(cid)))
        self.handover.on_click(self._guard(lambda: sup.hand_over(cid, sup.state().access.pending)))  # type: ignore[arg-type]
        self.decline.on_click(self._guard(lambda: sup.decline(cid)))
        self.arm.on_click(self._guard(self._request_arm))
        self.disarm.on_click(self._guard(self._disarm_now, direct=True))
        self.mode.on_update(self._guard(lambda: sup.set_mode(cid, self.mode.value)))
        self.apply_sp.on_click(self._guard(self._apply_setpoints))
        self.apply_tuning.on_click(self._guard(self._apply_tuning, tuning=True))
        self.revert.on_click(self._guard(self._request_revert, tuning=True))
        self.undo.on_click(self._guard(lambda: sup.undo_tuning(cid), tuning=True))
        self.save.on_click(self._guard(lambda: sup.save_baseline(cid), tuning=True))
        self.history.on_update(self._guard(self._set_history))
        self.rec_start.on_click(self._guard(lambda: sup.start_recording(cid)))
        self.rec_stop.on_click(self._guard(lambda: sup.stop_recording(cid)))
        self.marker.on_click(self._guard(self._add_marker))
        self.marker_key.on_trigger(self._guard(self._add_marker))
        for key, cmd in self.key_commands.items():
            cmd.on_trigger(self._guard(lambda k=key: self.driving.step(k)))
        self.stop_key.on_trigger(self._guard(self._stop_now, direct=True))
        self.disarm_key.on_trigger(self._guard(self._disarm_now, direct=True))
        self.drive_input.on_update(self._guard(lambda: self.driving.gamepad(self.drive_input.value)))
        self.name.on_update(self._guard(lambda: sup.set_name(cid, self.name.value)))
        self.severity.on_update(self._quiet(lambda _: self.show_events(force=True)))
        self.theme_button.on_click(self._guard(self._toggle_theme))
        self.frame.on_click(self._guard(lambda: self.app.frame_robot(cid)))
        if self.reset_drives is not None:
            self.reset_drives.on_click(self._guard(self._reset_drive_faults))
            self.zero_depth.on_click(self._guard(self._zero_depth))
        self.manoeuvres.start.on_click(self._guard(self.manoeuvres.request_start))
        self.manoeuvres.stop.on_click(self._guard(self.manoeuvres.stop_run))
        self.seek.start.on_click(self._guard(self.seek.start_seek))
        self.seek.keep.on_click(self._guard(lambda: self.seek.stop(True)))
        self.seek.revert.on_click(self._guard(lambda: self.seek.stop(False)))
        ident = self.identify
        ident.run.on_click(self._guard(ident.start))
        ident.stop.on_click(self._guard(ident.stop_run))
        ident.fit.on_click(self._guard(ident.start_fit))
        ident.use.on_click(self._guard(ident.use_fit, tuning=True))
        if self.faults is not None:
            f = self.faults
            f.device.on_update(self._quiet(lambda _: f.show_faults_of_device()))
            f.inject.on_click(self._guard(self._inject_fault))
            f.clear.on_click(self._guard(self._clear_faults))

    def _guard(self, fn: Callable[[], Any], tuning: bool = False, direct: bool = False) -> Callable[[Any], None]:
        """A viser callback: page events only (not values set from code), refusals shown;
        ``direct``: ``fn`` runs the command itself (through :meth:`act`)."""

        def cb(event: Any) -> None:
            if getattr(event, "client_id", None) is None and getattr(event, "client", None) is None:
                return  # a value set from code
            if direct:
                fn()
            else:
                self.act(fn, tuning)

        return cb

    def present(self) -> bool:
        """Whether this page is still connected (viser forgets a page before it removes the
        page's elements, so a page whose element was removed under a callback is gone here)."""
        present = getattr(self.app, "page_present", None)
        return present is None or present(self.cid)

    def _quiet(self, cb: Callable[[Any], None]) -> Callable[[Any], None]:
        """A viser callback that, when its page closed under it, ends without an error."""

        def run(event: Any) -> None:
            try:
                cb(event)
            except Exception:
                if self.present():
                    raise
                log.debug("client %s left during a callback", self.cid, exc_info=True)

        return run

    def act(self, fn: Callable[[], Any], tuning: bool = False) -> bool:
        """Run one command for this page; a refusal is shown and the inputs reverted."""
        try:
            try:
                fn()
            except REFUSALS as e:
                self.show(str(e), error=True, tuning=tuning)
                self.refresh(force=True)
                return False
            except Exception as e:  # a bug must not kill the page's callbacks silently
                if not self.present():
                    raise
                log.exception("command from client %s failed", self.cid)
                self.show(f"internal error: {e}", error=True, tuning=tuning)
                return False
        except Exception:
            if self.present():
                raise
            log.debug("client %s left during a command", self.cid, exc_info=True)
            return False
        self.app.request_refresh()
        return True

    def show(self, text: str, error: bool = False, tuning: bool = False) -> None:
        self.messages.append(text)
        stamp = time.strftime("%H:%M:%S")
        shown = f"{stamp} " + ("**Refused:** " if error else "") + esc(text)
        try:
            (self.tuning_message if tuning else self.message).content = shown
            if tuning:
                self.message.content = shown
        except RuntimeError:  # the page has gone, and its elements with it
            if self.present():
                raise
            return
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
            st = self.sup.state()
            pilot = actor_name(st.access.pilot)  # type: ignore[arg-type]
            self.show(f"{pilot} flies: asked it to hand over control; the request lapses after "
                      f"{st.limits.handover_timeout:g} s. Once the pilot's page is gone, the token "
                      "takes control at once")

    def _request_arm(self) -> None:
        nonce = self.sup.request_arm(self.cid)
        gui = self.gui
        sp = self.sup.setpoints
        modal = gui.add_modal("Arm the motors?")
        with modal:
            gui.add_markdown("The fins will move. Check that the water around the robot is clear.\n\n"
                             f"The robot goes at once to **velocity {sp.velocity:g} m/s, depth {sp.depth:g} m, "
                             f"yaw rate {sp.yaw_rate:g} rad/s**.")
            confirm = gui.add_button("Confirm arm", color="green")
            zero = gui.add_button("Zero velocity and yaw rate, then arm",
                                  visible=bool(sp.velocity or sp.yaw_rate))
            cancel = gui.add_button("Cancel")
        for h in (confirm, zero, cancel):
            self._allow(h, True)

        def on_zero(event: Any) -> None:
            if self.act(lambda: self.sup.set_setpoints(self.cid, velocity=0.0, yaw_rate=0.0)):
                on_confirm(event)

        zero.on_click(on_zero)

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
        # the line follows every setpoint from here on (a key, the gamepad, a failsafe)
        sp = self.sup.setpoints
        self._applied = {f"sp.{k}": self._in_force(f"sp.{k}", sp) for k in SETPOINTS}

    def _apply_tuning(self) -> None:
        changes = {}
        for key, handle in self.params.items():
            if handle.value != self.sup.param_value(key):
                changes[key] = handle.value
        if not changes:
            self.show("tuning unchanged", tuning=True)
            return
        self.sup.set_params(self.cid, changes)
        self.show("applied: " + ", ".join(f"{k} = {v:g}" if not isinstance(v, str) else f"{k} = {v}"
                                          for k, v in changes.items()), tuning=True)
        self._applied = dict(changes)

    def _unsaved(self) -> dict[str, tuple[Any, Any]]:
        """Each tuning value in force that is not the saved baseline's: key -> (in force, saved)."""
        saved = self.sup.saved_tuning()
        out = {}
        for key in self.params:
            block, _, name = key.rpartition(".")
            now, was = self.sup.param_value(key), getattr(saved[block], name)
            if not self._same(now, was):
                out[key] = (now, was)
        return out

    def _request_revert(self) -> None:
        """*Revert to saved*: at once while disarmed; while armed (the controller in force
        changes under the swimming robot) only once the pilot confirms what it changes.
        The page says what it did, or that nothing differed."""
        unsaved = self._unsaved()
        if not unsaved:
            self.show("revert: the tuning in force is the saved baseline; nothing changed", tuning=True)
            return
        if not self.sup.armed:
            self._revert()
            return
        gui = self.gui
        modal = gui.add_modal("Revert the tuning while armed?")
        with modal:
            gui.add_markdown("The robot is armed: its controller changes at once to the saved baseline:\n\n"
                             + "\n".join(f"- {esc(k)}: {_value(now)} → {_value(was)}"
                                         for k, (now, was) in unsaved.items()))
            confirm = gui.add_button("Revert now", color="orange")
            cancel = gui.add_button("Cancel")
        for h in (confirm, cancel):
            self._allow(h, True)

        def on_confirm(event: Any) -> None:
            modal.close()
            self.act(self._revert, tuning=True)

        def on_cancel(event: Any) -> None:
            modal.close()
            self.show("revert cancelled: the tuning in force is unchanged", tuning=True)

        confirm.on_click(on_confirm)
        cancel.on_click(on_cancel)

    def _revert(self) -> None:
        unsaved = self._unsaved()
        self.sup.revert_tuning(self.cid)
        self.show("reverted to the saved baseline: " + (", ".join(
            f"{k} {_value(now)} → {_value(was)}" for k, (now, was) in unsaved.items()) or "nothing differed"),
            tuning=True)
        sp = self.sup.setpoints
        self._applied = {k: self._in_force(k, sp) for k in unsaved}

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

    def _in_force(self, key: str, sp: Any) -> Any:
        """The value in force of input ``key`` (``sp.<setpoint>``: of setpoints ``sp``, or a tuning key)."""
        if key.startswith("sp."):
            return round(float(getattr(sp, key[3:])), 4)
        v = self.sup.param_value(key)
        return v if isinstance(v, str) else float(v)

    @staticmethod
    def _same(a: Any, b: Any) -> bool:
        if isinstance(a, str) or isinstance(b, str):
            return a == b
        return abs(float(a) - float(b)) <= 1e-9 * max(1.0, abs(float(b)))

    def _mark_draft(self, key: str, handle: Any, sp: Any) -> None:
        """An input whose value is not the one in force says so in its label."""
        base = self._labels.setdefault(key, handle.label)
        drafted = not self._same(handle.value, self._in_force(key, sp))
        self._set_prop(handle, "label", base + (DRAFT_MARK if drafted else ""))

    def _follow_applied(self, sp: Any) -> None:
        """The feedback line of the last apply is replaced whenever what it says is no longer
        in force (reverted, undone, a key or the gamepad, a failsafe or another pilot), and
        follows those values from then on."""
        if not self._applied:
            return
        now = {k: self._in_force(k, sp) for k in self._applied}
        if all(self._same(v, now[k]) for k, v in self._applied.items()):
            return
        tuning = not any(k.startswith("sp.") for k in self._applied)
        self._applied = now
        self.show("now in force: " + ", ".join(f"{k.removeprefix('sp.')} = {v:g}" if not isinstance(v, str)
                                              else f"{k} = {v}" for k, v in now.items()), tuning=tuning)

    def refresh(self, force: bool = False, state: ConsoleState | None = None) -> None:
        """Show the console's state (``state``, else the supervisor's snapshot now): values in
        force, which controls this page may use."""
        sup, cid = self.sup, self.cid
        st = state if state is not None else sup.state()
        pilot = st.access.is_pilot(cid)
        pending = st.access.pending
        p = st.access.pilot
        if pilot:
            role = "You are **the pilot**."
            if pending is not None:
                role += f" Client {pending} asks for control."
        else:
            who = "none" if p is None else (f"{esc(st.access.pilot_name)} (client {p})" if st.access.pilot_name
                                            else f"client {p}")
            role = f"Read-only (client {cid}). Pilot: {who}."
            if pending == cid:
                role += " Waiting for the pilot's hand-over."
        _set(self.role, role)
        self._set_prop(self.token, "visible", not pilot)
        self._set_prop(self.take, "visible", not pilot)
        self._set_prop(self.release, "visible", pilot)
        self._set_prop(self.handover, "visible", pilot and pending is not None)
        self._set_prop(self.decline, "visible", pilot and pending is not None)
        if pending is not None:
            self._set_prop(self.handover, "label", f"Hand over to client {pending}")
        armed, recording = st.armed, st.recording.recording
        self._set_prop(self.arm, "disabled", not pilot or armed)
        self._set_prop(self.disarm, "disabled", not pilot or not armed)
        self._set_prop(self.mode, "disabled", not pilot)
        self._push("mode", self.mode, st.mode, force)
        sp = st.setpoints
        for k in SETPOINTS:
            self._set_prop(self.sp_inputs[k], "disabled", not pilot)
            self._push(f"sp.{k}", self.sp_inputs[k], round(float(getattr(sp, k)), 4), force)
            self._mark_draft(f"sp.{k}", self.sp_inputs[k], sp)
        for key, handle in self.params.items():
            self._set_prop(handle, "disabled", not pilot)
            v = sup.param_value(key)
            self._push(key, handle, v if isinstance(v, str) else float(v), force)
            self._mark_draft(key, handle, sp)
        self._follow_applied(sp)
        for h in (self.apply_sp, self.apply_tuning, self.revert, self.undo, self.save, self.history, self.note, self.marker,
                  self.marker_key, self.stop_key, self.disarm_key, *self.key_commands.values()):
            self._set_prop(h, "disabled", not pilot)
        failed = st.recording.failed
        self._set_prop(self.rec_start, "disabled", not pilot or recording)
        self._set_prop(self.rec_stop, "disabled", not pilot or not (recording or failed))
        self._push("history", self.history, float(self.app.history), force)
        _set(self.rec_status, f"**Recording FAILED:** {esc(failed)}. Start recording again once there is space "
                              "(a new session), or Stop recording to acknowledge." if failed
             else f"Recording **{esc(st.recording.session_id)}**" if recording else "Not recording")
        if self.reset_drives is not None:
            self._set_prop(self.reset_drives, "disabled", not pilot or armed)
            self._set_prop(self.zero_depth, "disabled", not pilot or armed)
        if self.faults is not None:
            self.faults.enable(pilot)
        run = st.manoeuvre
        listed = (recording, run is not None and run.finished, sup.runs_version)
        # a recording ended (it may be fitted, reviewed, compared), or a page wrote a run's tags or notes
        if force or listed != self._listed:
            others = self._listed is not None and listed != self._listed
            self._listed = listed
            submit = getattr(self.app, "submit_job", None)
            if submit is None:
                self._list_sessions(others)
            else:  # (listed by the page jobs)
                submit(self.cid, "list sessions", lambda: self._list_sessions(others), coalesce=True)
        self.identify.refresh(pilot, st)
        self.manoeuvres.refresh(pilot, st)
        self.seek.refresh(pilot, st)

    def _list_sessions(self, others: bool = False) -> None:
        """The identification's list of sessions, and with ``others`` the page's other lists."""
        self._quiet(lambda _: self.identify.list_sessions())(None)
        for relist in self.session_lists if others else ():
            self._quiet(lambda _, f=relist: f())(None)

    @staticmethod
    def _set_prop(handle: Any, name: str, value: Any) -> None:
        """Set a property only when it changes (a refresh sends nothing for what stayed)."""
        if getattr(handle, name) != value:
            setattr(handle, name, value)

    def show_events(self, force: bool = False) -> None:
        """The events list, filtered by this page's choice of severity."""
        seen = (self.app.events_seen, self.severity.value)
        if not force and seen == self._events_seen:
            return  # no new event and the same filter: the same list
        self._events_seen = seen
        levels = SEVERITY_FILTERS.get(self.severity.value, SEVERITY_FILTERS["all"])
        text = events_markdown([e for e in self.app.recent_events() if e.level in levels][-_EVENTS_SHOWN:])
        if force or text != self._events_shown:
            self._events_shown = text
            self.events.content = text

    def _toggle_theme(self) -> None:
        self.app.toggle_theme(self.cid)


_EVENTS_SHOWN = 12


def _value(v: Any) -> str:
    """A tuning value as the page says it."""
    return v if isinstance(v, str) else f"{float(v):g}"


#: added to the label of an input whose value is not the one in force
DRAFT_MARK = " (not applied)"
_UNSET = object()
