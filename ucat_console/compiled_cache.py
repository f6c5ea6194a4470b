"""Numba's on-disk cache keyed by the sources it compiles: compiled code is never stale.

numba keys each cached kernel by the source file of the function it compiled, and by
nothing else: a kernel that inlines a ``register_jitable`` helper, or freezes a constant
(a row layout's columns), from another module is loaded from the cache after that module
changed, and runs the old code. So the package gives numba a cache directory of its own
per version of its compiled sources (numba's documented ``NUMBA_CACHE_DIR``, set here
before any kernel is defined):

* the compiled sources (:func:`compiled_sources`) are every module of the package that
  imports numba, and every module of the package those import, transitively: every module
  whose code or constants a kernel can compile in (a superset of the compiled call graph);
* the directory is ``<base>/ucat-numba-<place>-<sources>``: ``<sources>`` a hash of those
  files' contents, ``<place>`` one of the package's path (two copies of the package never
  share a directory); ``<base>`` (:func:`cache_base`) the ``NUMBA_CACHE_DIR`` the user set,
  else the folder ``UCAT_CONSOLE_CACHE_DIR`` names, else the user's cache folder
  (platformdirs' ``user_cache_dir("ucat-console")``: ``~/.cache/ucat-console`` on Linux,
  ``$XDG_CACHE_HOME/ucat-console`` when that is set); where the one chosen is not writable,
  a folder of the user's in the temporary directory, with a warning (numba would otherwise
  fall back to the package's ``__pycache__``). Nothing is written inside the installed
  package: a package under site-packages (a Debian package, a read-only image) stays as
  installed.

An edit to any compiled source, or a pull of a new version, gives a new directory: the next
run compiles afresh (``ucat-console prepare`` does it ahead and removes the directories of
older sources, and those an older version kept in the package's ``__pycache__``: :func:`prune`). An edit anywhere else (the page, the CLI) keeps the cache.
numba's own check (the defining file's contents) still applies inside a directory.

Every numba user in the process shares the one directory (numba has one cache setting).
"""

from __future__ import annotations

import hashlib
import logging
import os
import re
import shutil
import sys
import tempfile
from pathlib import Path

import platformdirs

log = logging.getLogger(__name__)

PACKAGE = Path(__file__).resolve().parent
_NAME = PACKAGE.name
_PREFIX = "ucat-numba-"
_USES_NUMBA = re.compile(r"^[ \t]*(?:import[ \t]+numba|from[ \t]+numba[ \t.])", re.M)
_FROM = re.compile(rf"^[ \t]*from[ \t]+({_NAME}(?:\.\w+)*)\s+import\s+(\([^)]*\)|[^\n]+)", re.M)
_IMPORT = re.compile(rf"^[ \t]*import[ \t]+({_NAME}(?:\.\w+)*)", re.M)


def _modules(root: Path) -> dict[str, Path]:
    """Each module of the package at ``root`` by its dotted name."""
    out = {}
    for f in root.rglob("*.py"):
        if "__pycache__" in f.parts:
            continue
        parts = f.relative_to(root).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join((_NAME, *parts))] = f
    return out


def _imports(modules: dict[str, Path], text: str) -> set[Path]:
    """The package modules ``text`` imports (``from a import b``: ``a``, and ``a.b`` when
    it is a module)."""
    out = {modules[m.group(1)] for m in _IMPORT.finditer(text) if m.group(1) in modules}
    for m in _FROM.finditer(text):
        names = [m.group(1)] + [f"{m.group(1)}.{n}" for n in re.findall(r"\w+", re.sub(r"#[^\n]*", "", m.group(2)))]
        out.update(modules[n] for n in names if n in modules)
    return out


def compiled_sources(root: Path = PACKAGE) -> list[Path]:
    """The package's modules a kernel can compile code or constants from: each module that
    imports numba and every package module it imports, transitively; sorted."""
    modules = _modules(root)
    texts = {f: f.read_text(encoding="utf-8") for f in modules.values()}
    todo = [f for f, text in texts.items() if "numba" in text and _USES_NUMBA.search(text)]
    seen: set[Path] = set(todo)
    while todo:
        for g in _imports(modules, texts[todo.pop()]):
            if g not in seen:
                seen.add(g)
                todo.append(g)
    return sorted(seen)


def sources_hash(root: Path = PACKAGE) -> str:
    """A hash of the compiled sources' paths (relative to ``root``) and contents."""
    h = hashlib.sha256()
    for f in compiled_sources(root):
        h.update(f.relative_to(root).as_posix().encode() + b"\0")
        h.update(f.read_bytes() + b"\0")
    return h.hexdigest()[:16]


def _place(root: Path) -> str:
    return hashlib.sha256(str(root).encode()).hexdigest()[:8]


def _writable(d: Path) -> bool:
    try:
        d.mkdir(parents=True, exist_ok=True)
        probe = d / f".probe-{os.getpid()}"
        probe.touch()
        probe.unlink()
        return True
    except OSError:
        return False


#: environment: the directory this package set (a child process inherits it with
#: NUMBA_CACHE_DIR) and the base the user had set, if any
_SET, _USER_BASE = "UCAT_CONSOLE_NUMBA_CACHE", "UCAT_CONSOLE_NUMBA_BASE"


def _user_base() -> str:
    """The NUMBA_CACHE_DIR the user set ("" if none): the inherited one when this package set it."""
    user = os.environ.get("NUMBA_CACHE_DIR", "")
    if user and user == os.environ.get(_SET):
        return os.environ.get(_USER_BASE, "")
    return user


#: the environment variable naming the base folder of the package's compiled cache
CACHE_ENV = "UCAT_CONSOLE_CACHE_DIR"


def default_cache_base() -> Path:
    """The user's cache folder for the package (platformdirs), where nothing else is set."""
    return Path(platformdirs.user_cache_dir("ucat-console", appauthor=False))


def base_and_reason() -> tuple[Path, str]:
    """:func:`cache_base` and what chose it (for ``ucat-console paths``)."""
    user = _user_base()
    named = os.environ.get(CACHE_ENV, "")
    if user:
        base, why = Path(user), "$NUMBA_CACHE_DIR"
    elif named:
        base, why = Path(named).expanduser().absolute(), f"${CACHE_ENV}"
    else:
        base, why = default_cache_base(), f"the user's cache folder; ${CACHE_ENV} chooses another"
    if _writable(base):
        return base, why
    # numba itself would fall back to the package's own __pycache__ (a write into the
    # installed package, and a cache not keyed by the compiled sources): a folder of the
    # user's in the temporary directory instead
    uid = os.getuid() if hasattr(os, "getuid") else "user"
    fallback = Path(tempfile.gettempdir()) / f"ucat-console-{uid}"
    log.warning("the compiled-code cache folder %s (%s) is not writable: using %s", base, why.split(";")[0], fallback)
    return fallback, f"{base} ({why.split(';')[0]}) is not writable"


def cache_base(root: Path = PACKAGE) -> Path:
    """Where the per-sources directories live: the user's ``NUMBA_CACHE_DIR``, else
    ``UCAT_CONSOLE_CACHE_DIR``, else the user's cache folder; ``<tmp>/ucat-console-<uid>`` when
    the one chosen is not writable (a read-only home, an image run as another user). ``root``
    is unused: never inside a package."""
    return base_and_reason()[0]


def cache_dir(root: Path = PACKAGE) -> Path:
    """numba's cache directory for the present compiled sources of the package at ``root``."""
    return cache_base(root) / f"{_PREFIX}{_place(root)}-{sources_hash(root)}"


def use_source_keyed_cache(root: Path = PACKAGE) -> Path:
    """Point numba's cache at :func:`cache_dir` (before any kernel is defined); the directory."""
    user = _user_base()
    d = cache_dir(root)
    os.environ.update({"NUMBA_CACHE_DIR": str(d), _SET: str(d), _USER_BASE: user})
    numba = sys.modules.get("numba")
    if numba is not None:  # imported before the package: numba read its setting already
        numba.config.CACHE_DIR = str(d)
    return d


def prune(root: Path = PACKAGE) -> list[Path]:
    """Remove this package copy's cache directories of older sources, those an older version
    kept inside the package (``__pycache__/ucat-numba-*``), and the cache files numba kept next
    to the sources before (``__pycache__/*.nbi``, ``*.nbc``); what was removed."""
    current = cache_dir(root)
    removed: list[Path] = []
    base = current.parent
    if base.is_dir():
        for d in base.glob(f"{_PREFIX}{_place(root)}-*"):
            if d != current and d.is_dir():
                shutil.rmtree(d, ignore_errors=True)
                removed.append(d)
    # where an older version of the package kept them: its own __pycache__
    inside = root / "__pycache__"
    if inside.is_dir() and inside != base:
        for d in inside.glob(f"{_PREFIX}*"):
            if d.is_dir():
                shutil.rmtree(d, ignore_errors=True)
                removed.append(d)
    for pattern in ("*.nbi", "*.nbc"):
        for f in root.rglob(f"__pycache__/{pattern}"):
            if current not in f.parents:
                try:
                    f.unlink()
                    removed.append(f)
                except OSError:
                    pass
    if removed:
        log.info("removed %d stale compiled-cache entries", len(removed))
    return removed
