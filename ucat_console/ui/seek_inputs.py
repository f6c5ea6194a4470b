"""Seek efficiency from the Drive tab (beside the Manoeuvre folder): the parameters to vary (of the configuration's
``[[seek.params]]``), Start seek, Stop & keep best, Stop & revert (docs/seek.md).

Every control here is the pilot's, and the server checks it again:
:meth:`~ucat_console.backend.supervisor.Supervisor.start_seek` and ``stop_seek`` refuse
anyone but the pilot, and the parameters a page names must be the configuration's (with
their configured bounds: a page never sets a bound). The progress is read from the console's
snapshot (``ConsoleState.seek``). DISARM and Esc stop a running seek.
"""

from __future__ import annotations

import math
from typing import Any, Callable

from ucat_console.backend.supervisor.console_state import ConsoleState
from ucat_console.ui.markdown import esc


class SeekInputs:
    """One page's Seek efficiency folder (module docstring)."""

    def __init__(self, gui: Any, sup: Any, cid: int, show: Callable[[str], None]) -> None:
        self.sup = sup
        self.cid = cid
        self._show = show
        seek = sup.cfg.seek
        with gui.add_folder("Seek efficiency", order=3.0, expand_by_default=False):
            self.params = {p.name: gui.add_checkbox(p.name, True, hint=f"vary {p.name} within [{p.lo:g}, {p.hi:g}] "
                                                                         "(the configuration's [[seek.params]])")
                           for p in seek.params}
            self.start = gui.add_button("Start seek", color="orange",
                                        hint=f"armed, pilot only: up to {seek.max_candidates} candidates of "
                                             f"{seek.settle_s:g} s settle and {seek.window_s:g} s measure, judged on "
                                             f"electrical energy per metre, then the best {seek.confirm} measured "
                                             "again; DISARM or Esc stops it")
            self.keep = gui.add_button("Stop & keep best", visible=False)
            self.revert = gui.add_button("Stop & revert", visible=False)
            self.progress = gui.add_progress_bar(0.0, visible=False)
            self.status = gui.add_markdown("")

    def handles(self) -> list[Any]:
        return [*self.params.values(), self.start, self.keep, self.revert]

    def chosen(self) -> tuple[str, ...]:
        names = tuple(name for name, box in self.params.items() if box.value is True)
        if not names:
            raise ValueError("seek: tick at least one parameter")
        return names

    def start_seek(self) -> None:
        run = self.sup.start_seek(self.cid, self.chosen())
        self._show(f"seek started over {', '.join(p.name for p in run.params)}")

    def stop(self, keep: bool) -> None:
        self.sup.stop_seek(self.cid, keep)
        self._show("seek stopped: " + ("the best kept" if keep else "the values it found put back"))

    def refresh(self, pilot: bool, st: ConsoleState) -> None:
        """Show the running or last seek; a property is set only when it changes."""
        view = st.seek
        running = view is not None and view.running
        for box in self.params.values():
            _prop(box, "disabled", not pilot or running)
        _prop(self.start, "disabled", not pilot or running or not st.armed)
        _prop(self.keep, "visible", running and pilot)
        _prop(self.revert, "visible", running and pilot)
        _prop(self.progress, "visible", running and view.phase != "watch")
        text = ""
        if view is not None:
            if running:
                done = min(view.candidates, view.max_candidates)
                _prop(self.progress, "value", round(100.0 * done / view.max_candidates, 1))
                if view.phase == "watch":
                    text = "**Seek**: watching the best for a drift"
                else:
                    text = (f"**Seek** {view.phase}: {view.candidates} measured, search {view.searches}; "
                            f"about {view.time_left:.0f} s left")
            else:
                text = f"**Seek** ended: {esc(view.reason)}"
            if view.best_energy is not None:
                v, lo, hi = view.best_energy
                interval = f" [{lo:.1f}, {hi:.1f}]" if math.isfinite(lo) and math.isfinite(hi) else ""
                best = ", ".join(f"{k} {x:.4g}" for k, x in view.best)
                text += f"\n\nBest: {esc(best)}: **{v:.1f} J/m**{interval}"
            lines = [f"- {esc(line)}" for line in view.lines]
            text += ("\n\n" + "\n".join(lines)) if lines else ""
        _prop(self.status, "content", text)


def _prop(handle: Any, name: str, value: Any) -> None:
    if getattr(handle, name) != value:
        setattr(handle, name, value)
