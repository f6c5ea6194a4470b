"""The layers hold: ``lint-imports`` passes on the project's contracts (pyproject.toml), and a
contract broken on purpose makes it fail."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LINT_IMPORTS = Path(sys.executable).with_name("lint-imports")


def lint_imports(cwd: Path) -> subprocess.CompletedProcess:
    """``lint-imports`` with the pyproject.toml in ``cwd``, on the package found there."""
    return subprocess.run([str(LINT_IMPORTS), "--no-cache"], cwd=cwd, capture_output=True,
                          text=True, timeout=300)


def test_the_contracts_hold() -> None:
    run = lint_imports(ROOT)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "0 broken" in run.stdout


def _copy_package(tmp_path: Path) -> None:
    """The package and its contracts in ``tmp_path``, for a test to add a leak to."""
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    shutil.copytree(ROOT / "ucat_console", tmp_path / "ucat_console",
                    ignore=shutil.ignore_patterns("__pycache__", "*.npz", "*.eds"))


def test_a_broken_contract_fails(tmp_path: Path) -> None:
    _copy_package(tmp_path)
    # the robot's description reaching into the core, and the page into a driver
    (tmp_path / "ucat_console" / "robot" / "leak.py").write_text(
        "from ucat_console.control.params import MpcConfig\n")
    (tmp_path / "ucat_console" / "ui" / "leak.py").write_text(
        "import ucat_console.backend.devices.pressure\n")
    run = lint_imports(tmp_path)
    assert run.returncode != 0
    assert "robot imports nothing of the package BROKEN" in run.stdout
    assert "ucat_console.robot.leak -> ucat_console.control.params" in run.stdout
    assert "ucat_console.ui.leak -> ucat_console.backend.devices.pressure" in run.stdout
    assert "2 broken" in run.stdout


def test_the_backend_reaching_into_the_page_fails(tmp_path: Path) -> None:
    """What compiles the page's code is named above the backend (``ucat_console.compiled``),
    never imported by it."""
    _copy_package(tmp_path)
    (tmp_path / "ucat_console" / "backend" / "leak.py").write_text("from ucat_console.ui import plots\n")
    run = lint_imports(tmp_path)
    assert run.returncode != 0
    assert "ucat_console.backend.leak -> ucat_console.ui.plots" in run.stdout
    assert "the tool packages in layers" in run.stdout and "2 broken" in run.stdout


def test_a_benchmark_reaching_into_the_command_line_fails(tmp_path: Path) -> None:
    """The tool packages are layers: a benchmark (below the command line and the
    experiments) importing the command line, even inside a function, breaks them."""
    _copy_package(tmp_path)
    (tmp_path / "ucat_console" / "bench" / "leak.py").write_text(
        "def prepare():\n    from ucat_console.cli import run\n")
    run = lint_imports(tmp_path)
    assert run.returncode != 0
    assert "ucat_console.bench is not allowed to import ucat_console.cli" in run.stdout
    assert "ucat_console.bench.leak -> ucat_console.cli.run" in run.stdout
    assert "1 broken" in run.stdout
