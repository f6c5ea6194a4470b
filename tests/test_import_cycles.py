"""No import circle anywhere in the package: every import counts, at a module's top, inside a
function or only for type checking (a module's parts talk to narrow collaborators, not back)."""

from __future__ import annotations

import grimp


def circles(g: grimp.ImportGraph) -> list[tuple[str, str]]:
    """Each import ``(m, imp)`` through which ``imp`` leads back to ``m``."""
    return sorted((m, imp) for m in g.modules for imp in g.find_modules_directly_imported_by(m)
                  if g.chain_exists(importer=imp, imported=m))


def test_no_module_imports_itself_back() -> None:
    assert circles(grimp.build_graph("ucat_console")) == []


def test_a_circle_is_found() -> None:
    g = grimp.ImportGraph()
    for m in ("p", "p.a", "p.b", "p.c"):
        g.add_module(m)
    g.add_import(importer="p.a", imported="p.b")
    g.add_import(importer="p.b", imported="p.a")
    g.add_import(importer="p.c", imported="p.a")
    assert circles(g) == [("p.a", "p.b"), ("p.b", "p.a")]
