"""The console's run path imports none of what only the experiments, sweeps, benchmarks and
the reference solver use (matplotlib, dask, tqdm, scipy's modules): they are the
``experiments`` extra, and scipy is imported by the scipy solver alone."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from support import sim_config

ROOT = Path(__file__).resolve().parents[1]
#: what numba itself loads of scipy when scipy is installed: the package (its version check),
#: scipy.linalg (the BLAS its compiled code calls) and scipy's private support modules, whose
#: names change between scipy versions; the console imports no scipy module
NUMBA_SCIPY = {"scipy", "scipy.__config__", "scipy.linalg", "scipy.version"}


def scipy_loaded(modules: set[str] | list[str]) -> set[str]:
    """The scipy package and its public subpackages among ``modules`` (scipy's private
    ``scipy._*`` modules left out)."""
    names = {".".join(m.split(".")[:2]) for m in modules if m.split(".")[0] == "scipy"}
    return {n for n in names if not n.partition(".")[2].startswith("_")}


HEAVY = ("matplotlib", "dask", "distributed", "tqdm", "pandas")

CHILD = """
import json, sys
from ucat_console.cli import main
code = main(sys.argv[1:])
print(json.dumps({"code": code, "modules": sorted(sys.modules)}))
"""


@pytest.mark.slow
def test_a_headless_run_with_the_foxglove_server_loads_no_experiment_library(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-c", CHILD, "run", "--config", str(sim_config(tmp_path)),
         "--headless", "--fast", "--duration", "1", "--mode", "mpc", "--foxglove-port", "0"],
        cwd=tmp_path, env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True,
        text=True, timeout=600,
    )
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert result["code"] == 0
    modules = set(result["modules"])
    assert "ucat_console.backend.foxglove_live" in modules  # the run path was taken
    assert not {m for m in modules if m.split(".")[0] in HEAVY}
    assert scipy_loaded(modules) <= NUMBA_SCIPY


def test_the_command_line_and_the_console_modules_import_no_experiment_library():
    code = ("import sys; from ucat_console.cli import build_parser; build_parser(); "
            "import ucat_console.backend.supervisor, ucat_console.ui.app, "
            "ucat_console.backend.foxglove_live; print(' '.join(sorted(sys.modules)))")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                         check=True, timeout=300).stdout.split()
    assert not {m for m in out if m.split(".")[0] in HEAVY}
    assert scipy_loaded(out) <= NUMBA_SCIPY


def test_the_scipy_reference_solver_still_loads_scipy_when_asked():
    code = ("import sys; from ucat_console.control import FinMpc, MpcConfig; "
            "FinMpc(MpcConfig(solver='scipy', n_samples=50), seed=0)"
            ".plan((-0.5, 0.5), 0.3, 0.0, (0.5, -0.5, 2.0, 2.0)); "
            "print('scipy.optimize' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                         check=True, timeout=300).stdout.split()
    assert out == ["True"]
