"""The page reads the console through its snapshot (``Supervisor.state()``) and commands it
through the supervisor's methods: no module of ``ui/`` reaches into a part of the supervisor
(its access control, failsafes, recorder, loop, journal...) or writes one.

Allowed: a method of the supervisor (``sup.set_mode(...)``, ``sup.state()``), a value it
holds (``sup.armed``; ``sup.setpoints``, frozen, read into), and three handles the page is given on purpose:
``cfg`` (the configuration the console started with, a frozen value), ``stream`` (the public
telemetry the page plots) and ``readers`` (the shared session readers the review uses)."""

from __future__ import annotations

import ast
from pathlib import Path

import ucat_console.ui

UI = Path(ucat_console.ui.__file__).parent
#: the names a module of ui/ gives the supervisor
SUPERVISOR_NAMES = {"sup", "_sup", "supervisor"}
#: what the page may hold of the supervisor beyond its methods and values (module docstring)
HANDLES = {"cfg", "stream", "readers", "setpoints"}
#: the supervisor's parts: the page names none of them
PARTS = {"access", "safety", "recording", "recorder", "loop", "gate", "tuning_state", "journal_log",
         "rig_control", "rig", "effects", "manoeuvre", "manoeuvre_host", "leak", "leak_emulator",
         "arm_requests", "watchdog", "clock", "bursts"}


def _is_supervisor(node: ast.AST) -> bool:
    """``sup``, ``supervisor``, ``self.sup``, ``self._sup``, ``app.sup``, ``self.app.sup``."""
    if isinstance(node, ast.Name):
        return node.id in SUPERVISOR_NAMES
    return isinstance(node, ast.Attribute) and node.attr in SUPERVISOR_NAMES


def reaches_into(source: str) -> list[str]:
    """Each place in ``source`` that reads or writes a part of the supervisor."""
    tree = ast.parse(source)
    parent = {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}
    found = []
    for node in ast.walk(tree):
        if not (isinstance(node, ast.Attribute) and _is_supervisor(node.value)):
            continue
        where = f"line {node.lineno}: {ast.unparse(node)}"
        up = parent.get(node)
        if isinstance(node.ctx, (ast.Store, ast.Del)):
            found.append(where + " (written)")
        elif node.attr in PARTS:
            found.append(where)
        elif node.attr not in HANDLES and isinstance(up, ast.Attribute) and up.value is node:
            found.append(f"line {node.lineno}: {ast.unparse(up)}")
    return found


def test_no_module_of_the_page_reaches_into_the_supervisors_parts() -> None:
    modules = sorted(UI.glob("*.py"))
    assert len(modules) > 10
    found = {p.name: hits for p in modules if (hits := reaches_into(p.read_text()))}
    assert not found, f"the page reads parts of the supervisor (render its state() instead): {found}"


def test_the_check_finds_what_it_forbids_and_allows_the_rest() -> None:
    bad = ("sup.access.pilot", "self.sup.safety.states()", "supervisor.recorder.directory", "self.app.sup.loop.time",
           "x = sup.manoeuvre", "self.sup.journal_log.add(1, 2, 3, 4)", "sup.armed = True", "sup.foo.bar")
    for line in bad:
        assert reaches_into(line), line
    good = ("sup.state().access.pilot", "sup.set_mode(1, 'mpc')", "sup.armed", "sup.setpoints.depth",
            "sup.cfg.console.max_history", "sup.stream.subscribe(f, [])", "sup.readers.budget",
            "self.sup.param_value('mpc.lam_st')", "st.access.pilot")
    for line in good:
        assert not reaches_into(line), line
