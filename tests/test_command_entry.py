"""The command's entry points: ``ucat-console --version`` and ``python -m ucat_console`` print
the installed distribution's version, and argcomplete completes sub-commands and options."""

from __future__ import annotations

import os
import subprocess
import sys
import tomllib
from importlib import metadata
from pathlib import Path

import pytest

import ucat_console

ROOT = Path(__file__).resolve().parents[1]
WORKTREE = Path(ucat_console.__file__).resolve().parents[1]


def _env(**extra: str) -> dict[str, str]:
    env = dict(os.environ, PYTHONPATH=str(WORKTREE))
    env.update(extra)
    return env


def _pyproject_version() -> str:
    with open(ROOT / "pyproject.toml", "rb") as fh:
        return tomllib.load(fh)["project"]["version"]


def test_the_version_is_the_distributions() -> None:
    assert ucat_console.__version__ == metadata.version("ucat-console") == _pyproject_version()


def test_python_dash_m_runs_the_command_and_prints_the_version(tmp_path: Path) -> None:
    proc = subprocess.run([sys.executable, "-m", "ucat_console", "--version"], cwd=tmp_path, env=_env(),
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["ucat-console", _pyproject_version()]
    # the same parser as the installed script: its name, and every sub-command
    proc = subprocess.run([sys.executable, "-m", "ucat_console", "--help"], cwd=tmp_path, env=_env(),
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and proc.stdout.startswith("usage: ucat-console ")
    assert "prepare" in proc.stdout and "paths" in proc.stdout


def test_a_source_tree_never_installed_reads_its_pyproject(tmp_path: Path, monkeypatch) -> None:
    def missing(name: str) -> str:
        raise metadata.PackageNotFoundError(name)

    monkeypatch.setattr(metadata, "version", missing)
    assert ucat_console._version() == _pyproject_version()


def _complete(line: str, tmp_path: Path) -> list[str]:
    """What argcomplete offers for ``line`` (the cursor at its end), as bash's hook asks it."""
    out = tmp_path / "completions"
    env = _env(_ARGCOMPLETE="1", _ARGCOMPLETE_SHELL="bash", _ARGCOMPLETE_IFS="\n", COMP_LINE=line,
               COMP_POINT=str(len(line)), COMP_TYPE="9", _ARGCOMPLETE_STDOUT_FILENAME=str(out))
    proc = subprocess.run([sys.executable, "-m", "ucat_console"], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return out.read_text().split("\n")


def test_the_shell_completes_sub_commands_and_their_options(tmp_path: Path) -> None:
    pytest.importorskip("argcomplete")
    assert sorted(c.strip() for c in _complete("ucat-console pr", tmp_path)) == ["prepare"]
    options = {c.strip() for c in _complete("ucat-console prepare --", tmp_path)}
    assert {"--config", "--workers", "--help"} <= options


def test_the_command_module_carries_argcompletes_marker() -> None:
    # register-python-argcomplete's hook completes only a script whose entry point's module
    # says so in its first 1024 bytes
    head = (WORKTREE / "ucat_console" / "cli" / "__init__.py").read_bytes()[:1024]
    assert b"PYTHON_ARGCOMPLETE_OK" in head
