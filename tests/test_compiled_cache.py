"""numba's cache is keyed by the compiled sources: an edit to a jitted helper in another
module recompiles the kernels that inline it; an unchanged package loads them."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

import ucat_console
from ucat_console import compiled_cache

PACKAGE = Path(ucat_console.__file__).resolve().parent

#: a kernel in its own module inlining a helper of another module (control.filters)
PROBE = '''
import numba
from ucat_console.control.filters import median_size


@numba.njit(cache=True)
def probe(window):
    return median_size(window)
'''

RUN = '''
import json
import ucat_console
from ucat_console.control.cache_probe import probe
value = probe(5)
s = probe.stats
print(json.dumps({"value": int(value), "hits": sum(s.cache_hits.values()),
                  "misses": sum(s.cache_misses.values()), "package": ucat_console.__file__}))
'''


def _copy(tmp: Path) -> Path:
    root = tmp / "ucat_console"
    shutil.copytree(PACKAGE, root, ignore=shutil.ignore_patterns("__pycache__"))
    (root / "control" / "cache_probe.py").write_text(PROBE)
    return root


def _run(root: Path) -> dict:
    env = dict(os.environ)  # this process set NUMBA_CACHE_DIR: the copy must not take it for its own
    env["PYTHONPATH"] = str(root.parent)
    env[compiled_cache.CACHE_ENV] = str(root.parent / "numba-cache")  # removed with tmp_path
    out = subprocess.run([sys.executable, "-c", RUN], env=env, cwd=root.parent, capture_output=True,
                         text=True, timeout=240, check=True)
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert Path(got["package"]).resolve().parent == root  # the copy ran, not the installed package
    return got


def _edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new))


def test_an_edited_helper_in_another_module_recompiles(tmp_path: Path) -> None:
    root = _copy(tmp_path)
    first = _run(root)
    assert first["misses"] == 1 and first["value"] == _median_size(5)
    again = _run(root)  # unchanged: loaded from the cache
    assert again == {**first, "hits": 1, "misses": 0}
    _edit(root / "control" / "filters.py", "return MED_RING + 2 * window", "return MED_RING + 3 * window")
    edited = _run(root)  # the helper changed, the kernel's own module did not
    assert edited["misses"] == 1 and edited["hits"] == 0
    assert edited["value"] == first["value"] + 5
    assert _run(root)["hits"] == 1


def test_an_edit_outside_the_compiled_sources_keeps_the_cache(tmp_path: Path) -> None:
    root = _copy(tmp_path)
    before = compiled_cache.cache_dir(root)
    assert _run(root)["misses"] == 1
    _edit(root / "cli" / "run.py", '"""', '"""An edit. ')
    assert compiled_cache.cache_dir(root) == before
    assert _run(root)["hits"] == 1


def test_the_compiled_sources_follow_the_imports_of_the_kernels() -> None:
    names = {f.relative_to(PACKAGE).as_posix() for f in compiled_cache.compiled_sources()}
    # kernels, the helpers they inline, and the layouts whose constants they freeze
    assert {"control/loop_core.py", "control/filters.py", "control/pid.py", "robot/reading_rows.py",
            "control/mpc_kernels.py", "backend/sim/plant.py"} <= names
    assert not any(n.startswith(("cli/", "bench/tracking")) for n in names)


def test_each_copy_and_each_version_of_the_sources_has_its_own_directory(tmp_path: Path) -> None:
    root = _copy(tmp_path)
    d = compiled_cache.cache_dir(root)
    assert d != compiled_cache.cache_dir(PACKAGE)
    _edit(root / "robot" / "reading_rows.py", '"""', '"""An edit. ')
    assert compiled_cache.cache_dir(root) != d
    os.makedirs(d)
    (root / "control" / "__pycache__").mkdir(exist_ok=True)
    old_file = root / "control" / "__pycache__" / "loop_core.core_step-1.py311.nbi"
    old_file.write_bytes(b"")
    removed = compiled_cache.prune(root)
    assert d in removed and old_file in removed and not d.exists() and not old_file.exists()


def _median_size(window: int) -> int:
    from ucat_console.control.filters import MED_RING

    return MED_RING + 2 * window


def test_a_cache_directory_the_user_sets_is_the_base(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "user"))
    d = compiled_cache.cache_dir()
    assert d.parent == tmp_path / "user" and d.name.startswith("ucat-numba-")


def _clean_env(**extra: str) -> dict[str, str]:
    """This environment without the cache settings this process (or the user) made."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("NUMBA_CACHE_DIR", compiled_cache.CACHE_ENV, "XDG_CACHE_HOME")
           and not k.startswith("UCAT_CONSOLE_NUMBA_")}
    env.update(extra)
    return env


def test_the_default_base_is_the_users_cache_folder_never_the_package(tmp_path: Path, monkeypatch) -> None:
    for name in ("NUMBA_CACHE_DIR", compiled_cache.CACHE_ENV):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    d = compiled_cache.cache_dir()
    assert d.parent == tmp_path / "xdg" / "ucat-console"
    assert PACKAGE not in d.parents


def test_the_cache_folder_setting_is_honoured_and_numbas_own_wins(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setenv(compiled_cache.CACHE_ENV, str(tmp_path / "ours"))
    assert compiled_cache.cache_dir().parent == tmp_path / "ours"
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba"))
    assert compiled_cache.cache_dir().parent == tmp_path / "numba"


@pytest.mark.parametrize("setting", ["XDG_CACHE_HOME", compiled_cache.CACHE_ENV, "NUMBA_CACHE_DIR"])
def test_an_unwritable_cache_folder_falls_back_to_the_temporary_directory(setting: str, tmp_path: Path,
                                                                          monkeypatch) -> None:
    """Never numba's own fallback, the package's __pycache__."""
    for name in ("NUMBA_CACHE_DIR", compiled_cache.CACHE_ENV):
        monkeypatch.delenv(name, raising=False)
    blocker = tmp_path / "a-file"
    blocker.write_text("")  # a folder cannot be made under a file, even as root
    monkeypatch.setenv(setting, str(blocker / "cache"))
    base, why = compiled_cache.base_and_reason()
    assert blocker not in base.parents and PACKAGE not in base.parents
    assert base.parent == Path(tempfile.gettempdir()) and "not writable" in why


def test_importing_compiling_and_pruning_write_nothing_inside_the_package(tmp_path: Path) -> None:
    """A copy of the package, as installed: a kernel compiled and the cache pruned (what
    ``prepare`` does) leave its files as they were; the compiled code is in the user's cache."""
    root = _copy(tmp_path)
    before = {f.relative_to(root): f.stat().st_mtime_ns for f in root.rglob("*")}
    xdg = tmp_path / "xdg"
    env = _clean_env(PYTHONPATH=str(root.parent), XDG_CACHE_HOME=str(xdg), PYTHONDONTWRITEBYTECODE="1")
    code = RUN + "\nfrom ucat_console import compiled_cache\ncompiled_cache.prune()\nprint(compiled_cache.cache_dir())"
    out = subprocess.run([sys.executable, "-c", code], env=env, cwd=tmp_path, capture_output=True,
                         text=True, timeout=240, check=True).stdout.strip().splitlines()
    got = json.loads(out[-2])
    assert got["misses"] == 1 and Path(got["package"]).resolve().parent == root
    assert {f.relative_to(root): f.stat().st_mtime_ns for f in root.rglob("*")} == before
    cache = Path(out[-1])
    assert cache.parent == xdg / "ucat-console"
    assert list(cache.rglob("*.nbi")) and list(cache.rglob("*.nbc"))


def test_paths_shows_the_compiled_cache_and_what_chose_it(tmp_path: Path, monkeypatch, capsys) -> None:
    from ucat_console.cli import main

    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setenv(compiled_cache.CACHE_ENV, str(tmp_path / "ours"))
    assert main(["paths"]) == 0
    line = next(s for s in capsys.readouterr().out.splitlines() if s.startswith("compiled code"))
    assert line.split()[2] == str(compiled_cache.cache_dir()) and f"${compiled_cache.CACHE_ENV}" in line
    assert compiled_cache.cache_dir().parent == tmp_path / "ours"
