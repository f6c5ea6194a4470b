"""Scripted manoeuvres from the Drive tab: pick a shipped one, Start (a confirmation that
lists its plan), Stop (docs/manoeuvres.md).

Every control here is the pilot's, and the server checks it again: the manoeuvre a page
names must be one of the shipped ones (a page never names a file), and
:meth:`~ucat_console.backend.supervisor.Supervisor.start_script` refuses anyone but the
pilot. DISARM and Esc stop a running manoeuvre (the supervisor stops it at the disarm).
"""

from __future__ import annotations

from typing import Any, Callable

from ucat_console import shipped
from ucat_console.backend.manoeuvre_files import load_script
from ucat_console.backend.supervisor.console_state import ConsoleState
from ucat_console.control.scripted import Script, plan
from ucat_console.ui.markdown import esc


class ManoeuvreInputs:
    """One page's Manoeuvre folder (module docstring)."""

    def __init__(self, gui: Any, sup: Any, cid: int, act: Callable[[Callable[[], Any]], bool],
                 allow: Callable[..., None], show: Callable[[str], None]) -> None:
        self.gui = gui
        self.sup = sup
        self.cid = cid
        self._act = act
        self._allow = allow
        self._show = show
        #: the manoeuvre the open confirmation lists (None: none open)
        self.pending: Script | None = None
        names = tuple(shipped.manoeuvre_names())
        with gui.add_folder("Manoeuvre", order=2.0, expand_by_default=False):
            self.choice = gui.add_dropdown("Manoeuvre", names or ("(none shipped)",),
                                           hint="a shipped scripted manoeuvre (docs/manoeuvres.md)")
            self.start = gui.add_button("Start manoeuvre", color="orange",
                                        hint="armed, pilot only: its segments one after another, recorded; "
                                             "DISARM or Esc stops it")
            self.stop = gui.add_button("Stop manoeuvre", visible=False)
            self.progress = gui.add_progress_bar(0.0, visible=False)
            self.status = gui.add_markdown("")

    def handles(self) -> list[Any]:
        return [self.choice, self.start, self.stop]

    def script(self) -> Script:
        """The chosen manoeuvre, checked for this console; only a shipped one's name."""
        name = self.choice.value
        if not isinstance(name, str) or name not in shipped.manoeuvre_names():
            raise ValueError(f"manoeuvre: {name!r} is not a shipped manoeuvre")
        return load_script(name, self.sup.cfg.loop)

    def request_start(self) -> None:
        """A confirmation listing what the manoeuvre will do; it starts once confirmed."""
        self.sup.require_pilot(self.cid, "manoeuvre")
        if not self.sup.state().armed:
            raise ValueError("manoeuvre: arm the motors first")
        script = self.pending = self.script()
        gui = self.gui
        modal = gui.add_modal(f"Start manoeuvre {script.name}?")
        with modal:
            gui.add_markdown("The robot will be driven through these segments, recorded; DISARM or Esc "
                             "stops it and puts back the setpoints and mode in force now.\n\n```\n"
                             f"{plan(script)}\n```")
            confirm = gui.add_button("Start", color="orange")
            cancel = gui.add_button("Cancel")
        for h in (confirm, cancel):
            self._allow(h, True)

        def on_confirm(event: Any) -> None:
            modal.close()
            self._act(self.confirm_start)

        def on_cancel(event: Any) -> None:
            modal.close()
            self.pending = None

        confirm.on_click(on_confirm)
        cancel.on_click(on_cancel)

    def confirm_start(self) -> None:
        """Start the manoeuvre the confirmation listed (the supervisor checks the pilot)."""
        script, self.pending = self.pending, None
        if script is None:
            raise ValueError("manoeuvre: nothing to start (press Start manoeuvre first)")
        self.sup.start_script(self.cid, script)
        self._show(f"manoeuvre {script.name} started")

    def stop_run(self) -> None:
        self.sup.stop_script(self.cid)
        self._show("manoeuvre stopped")

    def refresh(self, pilot: bool, st: ConsoleState) -> None:
        """Show the running or last manoeuvre; a property is set only when it changes."""
        run = st.script
        running = run is not None and run.running
        _prop(self.choice, "disabled", not pilot or running)
        _prop(self.start, "disabled", not pilot or running or not st.armed)
        _prop(self.stop, "visible", running and pilot)
        _prop(self.progress, "visible", running)
        text = ""
        if run is not None:
            if running:
                _prop(self.progress, "value", round(100.0 * run.progress, 1))
                text = f"**{esc(run.name)}**: segment {min(run.segment + 1, run.segments)} of {run.segments}"
            else:
                text = f"**{esc(run.name)}** ended: {esc(run.reason)}"
            lines = [f"- {esc(line)}" for line in run.lines]
            text += ("\n\n" + "\n".join(lines)) if lines else ""
        _prop(self.status, "content", text)


def _prop(handle: Any, name: str, value: Any) -> None:
    if getattr(handle, name) != value:
        setattr(handle, name, value)
