"""A fresh virtual environment installs the console from constraints.txt: every package at
its pinned version, consistent (pip check), the command runs, and none of the experiments'
libraries comes along (they are the ``experiments`` extra)."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _pins() -> dict[str, set[str]]:
    """Package name -> the versions constraints.txt allows (one per environment marker)."""
    pins: dict[str, set[str]] = {}
    for line in (ROOT / "constraints.txt").read_text().splitlines():
        m = re.match(r"^([A-Za-z0-9_.-]+)==([^ ;]+)", line)
        if m:
            pins.setdefault(_norm(m[1]), set()).add(m[2])
    return pins


def _norm(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_a_fresh_venv_installs_the_pinned_console(tmp_path):
    src = tmp_path / "src"  # a copy: building writes into the source tree
    src.mkdir()
    for name in ("pyproject.toml", "README.md", "constraints.txt"):
        shutil.copy(ROOT / name, src / name)
    shutil.copytree(ROOT / "ucat_console", src / "ucat_console",
                    ignore=shutil.ignore_patterns("__pycache__"))
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=120)
    py = venv / "bin" / "python"
    subprocess.run([py, "-m", "pip", "install", "-q", "-c", "constraints.txt", "."], cwd=src,
                   check=True, timeout=840)
    subprocess.run([py, "-m", "pip", "check"], check=True, timeout=60, capture_output=True)
    listed = subprocess.run([py, "-m", "pip", "list", "--format=freeze"], check=True,
                            capture_output=True, text=True, timeout=60).stdout.split()
    installed = {_norm(n): v for n, v in (x.split("==") for x in listed)}
    pins = _pins()
    for name, version in installed.items():
        if name in ("pip", "setuptools", "ucat-console"):  # the venv's own, and the project
            continue
        assert name in pins, f"{name} {version}: installed but not pinned in constraints.txt"
        assert version in pins[name], f"{name}: {version} installed, {pins[name]} pinned"
    assert not {"matplotlib", "dask", "distributed", "foxglove-sdk"} & set(installed)
    out = subprocess.run([venv / "bin" / "ucat-console", "run", "--help"], check=True,
                         capture_output=True, text=True, timeout=120, cwd=tmp_path).stdout
    assert "--foxglove-port" in out
    # the experiments say what to install rather than failing on an import
    proc = subprocess.run([venv / "bin" / "ucat-console", "experiment", "E1", "--quick", "--out",
                           str(tmp_path / "out")], capture_output=True, text=True, timeout=120,
                          cwd=tmp_path)
    assert proc.returncode == 2
    assert "pip install 'ucat-console[experiments]'" in proc.stderr
