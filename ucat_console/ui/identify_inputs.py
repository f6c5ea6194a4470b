"""Fin-model identification from the Session tab: run the manoeuvre, fit a recording, use it.

The pilot runs the identification manoeuvre (the supervisor's
:meth:`~ucat_console.backend.supervisor.Supervisor.start_manoeuvre`: mode "identify",
recorded, ended by itself), picks a recorded session (the manoeuvre's is chosen when it
ends) and fits the fin coefficients to it
(:func:`~ucat_console.backend.identification.identify_sessions`, in a thread of its own: a
fit of a two-minute recording takes about a second). The fit is shown with its 95 %
intervals, and *Use in the MPC* applies its C_D and C_L as a journalled tuning change.
Every control here is the pilot's.
"""

from __future__ import annotations

import threading
from typing import Any, Callable, Mapping, Protocol

from ucat_console.backend.identification import IdentifyReport, identify_sessions
from ucat_console.backend.sessions import index
from ucat_console.backend.sessions.shared import SharedReaders
from ucat_console.backend.supervisor import ConsoleState
from ucat_console.backend.supervisor.manoeuvre import ManoeuvreRun
from ucat_console.ui.markdown import esc

NO_SESSION = "(no recorded session)"


class IdentifyHost(Protocol):
    """What the identification folder uses of the supervisor: its configuration and session
    readers, its snapshot, and its commands."""

    cfg: Any  # the AppConfig the console started with
    readers: SharedReaders

    def state(self) -> ConsoleState: ...
    def current_config(self) -> Any: ...
    def require_pilot(self, who: Any, action: str) -> None: ...
    def start_manoeuvre(self, who: Any) -> ManoeuvreRun: ...
    def stop_manoeuvre(self, who: Any) -> Any: ...
    def set_params(self, who: Any, changes: Mapping[str, object]) -> None: ...


class IdentifyInputs:
    """The Session tab's identification folder of one page (module docstring)."""

    def __init__(self, gui: Any, sup: IdentifyHost, cid: int, directory: Any,
                 show: Callable[..., None], changed: Callable[[], None],
                 sessions: Callable[[], list[index.SessionInfo]] | None = None) -> None:
        """``sessions()``: the sessions folder's listing (default: read it each time)."""
        self.sup = sup
        self.cid = cid
        self.directory = directory
        self._sessions = sessions or (lambda: index.list_sessions(self.directory))
        self._show = show  # a message on the page
        self._changed = changed  # ask the page to refresh
        self.report: IdentifyReport | None = None
        self.error = ""
        self._fitting: threading.Thread | None = None
        duration = sup.cfg.loop.manoeuvre.duration
        with gui.add_folder("Fin model identification", order=25.0, expand_by_default=False):
            gui.add_markdown(f"The manoeuvre beats the fins at fixed strokes and rates for about "
                             f"{duration:.0f} s, recorded; keep the depth for it (the hull heaves). "
                             "Then fit the fin coefficients to the recording.")
            self.run = gui.add_button("Run the identification manoeuvre", color="orange",
                                      hint="armed, pilot only: mode identify, recorded, ends by itself")
            self.stop = gui.add_button("Stop the manoeuvre", visible=False)
            self.progress = gui.add_progress_bar(0.0, visible=False)
            self.session = gui.add_dropdown("Session to fit", (NO_SESSION,), hint="a recorded session")
            self.fit = gui.add_button("Fit the fin model")
            self.result = gui.add_markdown("")
            self.use = gui.add_button("Use C_D and C_L in the MPC", color="blue", visible=False,
                                      hint="a tuning change, journalled like any other")

    def handles(self) -> list[Any]:
        return [self.run, self.stop, self.session, self.fit, self.use]

    # ------------------------------------------------------------------ commands
    def start(self) -> None:
        run = self.sup.start_manoeuvre(self.cid)
        self._show(f"identification manoeuvre started, recording {run.session}")

    def stop_run(self) -> None:
        self.sup.stop_manoeuvre(self.cid)
        self._show("identification manoeuvre stopped")

    def list_sessions(self) -> None:
        names = tuple(s.session_id for s in self._sessions() if not s.truncated)
        current = self.session.value
        self.session.options = names or (NO_SESSION,)
        run = self.sup.state().manoeuvre
        if run is not None and run.finished and run.session in names:
            self.session.value = run.session
        elif current in names:
            self.session.value = current
        elif names:
            self.session.value = names[-1]

    def start_fit(self) -> threading.Thread:
        """Fit the chosen session in a thread (the pilot's; one fit at a time per page)."""
        self.sup.require_pilot(self.cid, "identification")
        name = self.session.value
        if name == NO_SESSION or not isinstance(name, str) or not name:
            raise ValueError("identification: no recorded session to fit")
        if self._fitting is not None and self._fitting.is_alive():
            raise ValueError("identification: a fit is running")
        self.report, self.error = None, ""
        self.result.content = f"Fitting {esc(name)} ..."
        self._fitting = threading.Thread(target=self._fit, args=(name,), name="identify", daemon=True)
        self._fitting.start()
        return self._fitting

    def _fit(self, name: str) -> None:
        try:
            self.report = identify_sessions([name], self.directory, config=self.sup.current_config(),
                                            budget=self.sup.readers.budget)
        except Exception as e:  # a recording the fit refuses: the reason on the page
            self.error = str(e)
        self._changed()

    def use_fit(self) -> None:
        rep = self.report
        if rep is None:
            raise ValueError("identification: no fit to use yet")
        r = rep.result
        self.sup.set_params(self.cid, {"mpc.c_d": round(r.c_d, 6), "mpc.c_l": round(r.c_l, 6)})
        self._show(f"MPC fin model: C_D {r.c_d:.4g}, C_L {r.c_l:.4g}")

    # ------------------------------------------------------------------ state -> page
    def refresh(self, pilot: bool, st: ConsoleState) -> None:
        """Show the run and the fit as of snapshot ``st``; a property is set only when it
        changes (a refresh of an unchanged page sends nothing)."""
        run = st.manoeuvre
        running = run is not None and not run.finished
        _prop(self.fit, "disabled", not pilot)
        _prop(self.session, "disabled", not pilot)
        _prop(self.run, "disabled", not pilot or running or not st.armed)
        _prop(self.stop, "visible", running and pilot)
        _prop(self.progress, "visible", running)
        if run is not None and running:
            _prop(self.progress, "value", round(100.0 * run.progress, 1))
        text = self.result.content
        if self.error:
            text = f"**Fit refused**: {esc(self.error)}"
        elif self.report is not None:
            r = self.report.result
            text = (f"**{esc(', '.join(self.report.sessions))}**: C_D **{r.c_d:.4g}** +- {r.c_d_ci:.2g}, "
                    f"C_L **{r.c_l:.4g}** +- {r.c_l_ci:.2g} (95 %); {r.steady_windows} steady of "
                    f"{len(r.windows)} windows, rms residual {r.rms_residual:.3g} N; hull from "
                    f"{esc(self.report.config_source)}")
        _prop(self.result, "content", text)
        _prop(self.use, "visible", self.report is not None and pilot)


def _prop(handle: Any, name: str, value: Any) -> None:
    if getattr(handle, name) != value:
        setattr(handle, name, value)
