"""No import circles through the closed loop and the functional core (the loop's parts talk
to narrow collaborators, not back to the loop)."""

from __future__ import annotations

import grimp

AREAS = ("ucat_console.backend.loop", "ucat_console.control", "ucat_console.robot", "ucat_console.compiled_cache")


def test_no_module_of_the_loop_or_the_core_imports_itself_back() -> None:
    g = grimp.build_graph("ucat_console")
    circles = [(m, imp) for m in g.modules if m.startswith(AREAS)
               for imp in g.find_modules_directly_imported_by(m) if g.chain_exists(importer=imp, imported=m)]
    assert circles == []
